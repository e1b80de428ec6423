"""`skyring sim`: run the embedded simulation headless, print a short table and write the JSON report.

Every option value is parsed here, not by typer, so that any bad value ends the command with exit status 2
and exactly one line on stderr that names the option (typer's own error panels take several lines).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Annotated, Any, NoReturn

import typer

from controller.params import Method
from vehicles.sim.person import PERSON_MODES
from vehicles.sim.trees import TreeSpec

START_LAYOUTS = ("ring", "cluster")  # vehicles.sim.scenario.START_LAYOUTS, kept here so errors print fast


class _BadOption(Exception):
    def __init__(self, option: str, message: str) -> None:
        super().__init__(f"invalid value for {option}: {message}")


def _fail(message: str) -> NoReturn:
    typer.echo(f"Error: {message}", err=True)
    raise typer.Exit(code=2)


def _int(option: str, text: str, *, minimum: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise _BadOption(option, f"expected a whole number, got {text!r}") from None
    if value < minimum:
        raise _BadOption(option, f"must be at least {minimum}, got {value}")
    return value


def _float(option: str, text: str, *, low: float, high: float = math.inf, low_open: bool = False) -> float:
    try:
        value = float(text)
    except ValueError:
        raise _BadOption(option, f"expected a number, got {text!r}") from None
    too_low = value <= low if low_open else value < low
    if not math.isfinite(value) or too_low or value > high:
        lo = f"above {low:g}" if low_open else f"at least {low:g}"
        rng = f"{lo}" if math.isinf(high) else f"{lo} and at most {high:g}"
        raise _BadOption(option, f"must be {rng}, got {text}")
    return value


def _choice(option: str, text: str, choices: tuple[str, ...]) -> str:
    value = text.strip().lower()
    if value not in choices:
        raise _BadOption(option, f"choose one of {', '.join(choices)}, got {text!r}")
    return value


def parse_options(
    *,
    vehicles: str,
    duration: str,
    seed: str,
    method: str,
    trees: str,
    comm_loss: str,
    person: str,
    warmup: str,
    rate: str,
    start: str,
    d_des: str,
    h_des: str,
    replan_rate: str = "0",
) -> dict[str, Any]:
    """SimConfig keyword arguments from the command line's text; raises _BadOption naming the option."""
    out: dict[str, Any] = {
        "vehicles": _int("--vehicles", vehicles, minimum=1),
        "duration_s": _float("--duration", duration, low=0.0, low_open=True),
        "seed": _int("--seed", seed, minimum=0),
        "method": _choice("--method", method, tuple(m.value for m in Method)),
        "comm_loss": _float("--comm-loss", comm_loss, low=0.0, high=1.0),
        "person": _choice("--person", person, PERSON_MODES),
        "rate_hz": _float("--rate", rate, low=1.0, high=1000.0),
        "start": _choice("--start", start, START_LAYOUTS),
        "d_des_m": _float("--d-des", d_des, low=0.0, low_open=True),
        "h_des_m": _float("--h-des", h_des, low=0.0, low_open=True),
    }
    try:
        out["trees"] = str(TreeSpec.parse(trees))
    except ValueError as exc:
        raise _BadOption("--trees", str(exc)) from None
    out["warmup_s"] = _float("--warmup", warmup, low=0.0)
    if out["warmup_s"] >= out["duration_s"]:
        raise _BadOption("--warmup", f"must be below --duration ({out['duration_s']:g} s), got {warmup}")
    out["replan_hz"] = _float("--replan-rate", replan_rate, low=0.0, high=out["rate_hz"])
    if out["vehicles"] > 64:
        raise _BadOption("--vehicles", f"at most 64 vehicles, got {out['vehicles']}")
    return out


def _fmt(value: Any, unit: str = "") -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.3f}{unit}"
    return f"{value}{unit}"


def summary_table(metrics: dict[str, Any]) -> str:
    """A short human-readable table of a report's main metrics."""
    te, ct, co, tk = (
        metrics.get(k) or {} for k in ("tracking_error_m", "cov_trace_m2", "center_offset_px", "tick_ms")
    )
    rows = [
        (
            "tracking error",
            f"mean {_fmt(te.get('mean'), ' m')}  median {_fmt(te.get('median'), ' m')}  "
            f"p90 {_fmt(te.get('p90'), ' m')}",
        ),
        ("covariance trace", f"mean {_fmt(ct.get('mean'), ' m^2')}  median {_fmt(ct.get('median'), ' m^2')}"),
        ("person in frame", _fmt(metrics.get("in_frame_fraction"))),
        ("centre offset", f"mean {_fmt(co.get('mean'), ' px')}  median {_fmt(co.get('median'), ' px')}"),
        ("spacing error", _fmt(metrics.get("spacing_error_deg"), " deg")),
        ("distance error", _fmt(metrics.get("distance_error_m"), " m")),
        ("height error", _fmt(metrics.get("height_error_m"), " m")),
        ("min separation", _fmt(metrics.get("min_separation_m"), " m")),
        ("min obstacle clearance", _fmt(metrics.get("min_obstacle_clearance_m"), " m")),
        ("min person distance", _fmt(metrics.get("min_person_distance_m"), " m")),
        ("agent tick", f"median {_fmt(tk.get('median'), ' ms')}  p99 {_fmt(tk.get('p99'), ' ms')}"),
        ("real-time factor", _fmt(metrics.get("realtime_factor"), "x")),
    ]
    width = max(len(name) for name, _ in rows)
    return "\n".join(f"{name:<{width}}  {value}" for name, value in rows)


def _opt(name: str, metavar: str, help_text: str):
    return typer.Option(name, metavar=metavar, help=help_text)


HEADLESS = typer.Option("--headless", help="run as fast as possible, without the live view")
VEHICLES = _opt("--vehicles", "K", "number of MAVs (>= 1)")
DURATION = _opt("--duration", "S", "simulated seconds, warm-up included")
SEED = _opt("--seed", "N", "seed of every random choice")
METHOD = _opt("--method", "{active,dqmpc,price}", "formation method")
TREES = _opt("--trees", "{paper,none,N}", "the paper's 13 trees, none, or N random ones")
COMM_LOSS = _opt("--comm-loss", "P", "probability in [0, 1] that a message between MAVs is lost")
PERSON = _opt("--person", "{paper,random,still}", "how the person moves")
WARMUP = _opt("--warmup", "S", "metrics start after S seconds")
RATE = _opt("--rate", "HZ", "control rate (the paper: 100 Hz)")
REPLAN = _opt(
    "--replan-rate",
    "HZ",
    "solve the MPC at most this often, following the plan in between (0: every control tick, as the paper)",
)
START = _opt("--start", "{ring,cluster}", "MAVs start at their roster slots or side by side")
D_DES = _opt("--d-des", "M", "desired horizontal distance to the person")
H_DES = _opt("--h-des", "M", "desired height above the person")
REPORT = _opt("--report", "PATH", "write the JSON report here")


def sim(
    headless: Annotated[bool, HEADLESS] = False,
    vehicles: Annotated[str, VEHICLES] = "3",
    duration: Annotated[str, DURATION] = "60",
    seed: Annotated[str, SEED] = "0",
    method: Annotated[str, METHOD] = "active",
    trees: Annotated[str, TREES] = "paper",
    comm_loss: Annotated[str, COMM_LOSS] = "0",
    person: Annotated[str, PERSON] = "paper",
    warmup: Annotated[str, WARMUP] = "20",
    rate: Annotated[str, RATE] = "100",
    replan_rate: Annotated[str, REPLAN] = "0",
    start: Annotated[str, START] = "ring",
    d_des: Annotated[str, D_DES] = "8",
    h_des: Annotated[str, H_DES] = "8",
    report: Annotated[Path | None, REPORT] = None,
) -> None:
    """Run the embedded simulation of the paper's world and report its metrics."""
    try:
        options = parse_options(
            vehicles=vehicles,
            duration=duration,
            seed=seed,
            method=method,
            trees=trees,
            comm_loss=comm_loss,
            person=person,
            warmup=warmup,
            rate=rate,
            start=start,
            d_des=d_des,
            h_des=h_des,
            replan_rate=replan_rate,
        )
    except _BadOption as exc:
        _fail(str(exc))
    if not headless:
        _fail("the live 3-D view runs in `skyring serve`; add --headless to simulate and get a report")
    from server.lab.simulation import SimConfig, run_simulation  # heavy imports only once arguments are good

    try:
        config = SimConfig(**options)
    except ValueError as exc:
        _fail(str(exc))
    if report is not None and not report.parent.exists():
        _fail(f"invalid value for --report: directory {str(report.parent)!r} does not exist")
    typer.echo(
        f"simulating {config.vehicles} MAVs, {config.method}, trees {config.trees}, person "
        f"{config.person}, loss {config.comm_loss:g}, {config.duration_s:g} s at "
        f"{config.rate_hz:g} Hz, seed {config.seed} ...",
        err=True,
    )
    result = run_simulation(config)
    typer.echo(summary_table(dict(result.metrics)))
    if report is not None:
        report.write_text(result.dumps())
        typer.echo(f"report written to {report}", err=True)
    sys.stdout.flush()
