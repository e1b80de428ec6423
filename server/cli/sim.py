"""`skyring sim`: run the embedded simulation headless, print a short table and write the JSON report.

Options are typed with their ranges (server/cli/options.py); the run's settings are checked once more as a
whole by `SimConfig` (a warm-up shorter than the run, a re-planning rate below the control rate). Any bad
value ends the command with exit status 2 and one line naming the option (server/cli/__init__.py).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from controller.params import Method, ParameterError
from server.cli.options import (
    OPTION_OF_FIELD,
    MethodOption,
    Person,
    PersonMode,
    Rate,
    Seed,
    StartLayout,
    Trees,
    Vehicles,
    positive,
)


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


HEADLESS = typer.Option("--headless", help="run as fast as possible, without the live view")
DURATION = positive("simulated seconds, warm-up included", "S")
COMM_LOSS = typer.Option(
    min=0.0, max=1.0, metavar="P", help="probability that a message between MAVs is lost"
)
WARMUP = typer.Option(
    min=0.0,
    metavar="S",
    help="tracking and formation metrics start after S seconds (the safety minima cover the whole flight)",
)
REPLAN = typer.Option(
    min=0.0,
    metavar="HZ",
    help="solve the MPC at most this often, following the plan in between (0: every tick, as the paper)",
)
START = typer.Option(case_sensitive=False, help="MAVs start at their roster slots or side by side")
D_DES = positive("desired horizontal distance to the person", "M")
H_DES = positive("desired height above the person", "M")
REPORT = typer.Option(metavar="PATH", help="write the JSON report here", dir_okay=False)
GPS_OFFSET = typer.Option(
    "--gps-offset/--no-gps-offset",
    help="each MAV learns its GPS offset relative to the team from its detections and places teammates by it",
)


def sim(
    headless: Annotated[bool, HEADLESS] = False,
    vehicles: Vehicles = 3,
    duration: Annotated[float, DURATION] = 60.0,
    seed: Seed = 0,
    method: MethodOption = Method.ACTIVE,
    trees: Trees = "paper",
    comm_loss: Annotated[float, COMM_LOSS] = 0.0,
    person: Person = PersonMode.paper,
    warmup: Annotated[float, WARMUP] = 20.0,
    rate: Rate = 100.0,
    replan_rate: Annotated[float, REPLAN] = 0.0,
    start: Annotated[StartLayout, START] = StartLayout.ring,
    d_des: Annotated[float, D_DES] = 8.0,
    h_des: Annotated[float, H_DES] = 8.0,
    gps_offset: Annotated[bool, GPS_OFFSET] = True,
    report: Annotated[Path | None, REPORT] = None,
) -> None:
    """Run the embedded simulation of the paper's world and report its metrics."""
    if not headless:
        typer.echo(
            "Error: the live 3-D view runs in `skyring serve`; add --headless to simulate and get a report",
            err=True,
        )
        raise typer.Exit(code=2)
    if report is not None and not report.parent.exists():
        raise typer.BadParameter(f"directory {str(report.parent)!r} does not exist", param_hint="--report")
    from server.lab.simulation import SimConfig, run_simulation  # the runner loads once the options are good

    try:
        config = SimConfig(
            vehicles=vehicles,
            duration_s=duration,
            seed=seed,
            method=method,
            trees=trees,
            comm_loss=comm_loss,
            person=person.value,
            warmup_s=warmup,
            rate_hz=rate,
            replan_hz=replan_rate,
            start=start.value,
            d_des_m=d_des,
            h_des_m=h_des,
            gps_offset=gps_offset,
        )
    except ParameterError as exc:
        raise typer.BadParameter(exc.reason, param_hint=OPTION_OF_FIELD.get(exc.field, exc.field)) from None
    typer.echo(
        f"simulating {config.vehicles} MAVs, {config.method.value}, trees {config.trees}, person "
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
