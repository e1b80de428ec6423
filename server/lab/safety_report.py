"""The safety sweep's results: `safety.json` (every run) and `report.md` (distributions, violations, figure).

Everything but the timing section is a pure function of the runs' outcomes, so the same sweep gives the same
report. A violation does not fail the command: the report lists every violating run with the `skyring sim`
command that flies it again.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from server.lab.report import markdown_table
from server.lab.safety_sweep import MINIMA, Minimum, RunOutcome, Thresholds

# (record attribute, what it is, threshold attribute of Thresholds or "") in the report's order.
ROWS: tuple[tuple[str, str, str], ...] = (
    ("separation", "closest true pair (m)", "true_separation_m"),
    ("believed_separation", "closest believed pair (m)", "believed_separation_m"),
    ("obstacle_clearance", "trunk / obstacle clearance (m)", "trunk_clearance_m"),
    ("person_distance", "closest approach to the person (m)", ""),
)
VIOLATION_TEXT = {
    "believed": "closest believed pair below {believed_separation_m:g} m",
    "true": "closest true pair below {true_separation_m:g} m",
    "trunk": "trunk clearance below {trunk_clearance_m:g} m (contact)",
}
TIMING_HEADING = "## Timing"


@dataclass(frozen=True)
class Distribution:
    """One minimum over the sweep's runs: how many runs measured it, min, p1, p5 and median (m), and the
    run index of the smallest."""

    n: int
    min_m: float
    p1_m: float
    p5_m: float
    median_m: float
    argmin_index: int


def distribution(outcomes: Sequence[RunOutcome], attr: str) -> Distribution | None:
    """The distribution of minimum `attr` over the runs that measured it; None if none did."""
    pairs = [(m.distance_m, o.run.index) for o in outcomes if (m := _min(o, attr)).distance_m is not None]
    if not pairs:
        return None
    values = np.array([v for v, _ in pairs], dtype=float)
    p1, p5, median = np.percentile(values, [1.0, 5.0, 50.0])
    best = int(np.argmin(values))
    return Distribution(
        n=len(pairs),
        min_m=float(values[best]),
        p1_m=float(p1),
        p5_m=float(p5),
        median_m=float(median),
        argmin_index=pairs[best][1],
    )


def _min(outcome: RunOutcome, attr: str) -> Minimum:
    value = getattr(outcome, attr)
    assert isinstance(value, Minimum)
    return value


def _fmt(v: float | None) -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{v:.3f}"


def sweep_json(
    outcomes: Sequence[RunOutcome], *, command: str, thresholds: Thresholds, wall_s: float
) -> dict[str, object]:
    """safety.json: the command, thresholds, the distributions, and every run with its minima and config."""
    return {
        "command": command,
        "thresholds": asdict(thresholds),
        "runs": len(outcomes),
        "failed": sum(1 for o in outcomes if o.error is not None),
        "violations": {k: sum(k in o.violations(thresholds) for o in outcomes) for k in VIOLATION_TEXT},
        "distributions": {
            metric: (None if (d := distribution(outcomes, attr)) is None else asdict(d))
            for attr, metric, _ in MINIMA
        },
        "wall_s": wall_s,
        "results": [o.to_json(thresholds) for o in outcomes],
    }


def _when(m: Minimum) -> str:
    between = " and ".join(str(b) for b in m.between)
    return f"{_fmt(m.distance_m)} m at t = {_fmt(m.t_s)} s ({between})" if m.distance_m is not None else "n/a"


def render_report(
    outcomes: Sequence[RunOutcome],
    *,
    command: str,
    thresholds: Thresholds,
    figure: str | None,
    wall_s: float,
) -> str:
    """The whole report.md. Everything above the timing section depends only on the outcomes."""
    failed = [o for o in outcomes if o.error is not None]
    clustered = sum(o.run.start == "cluster" for o in outcomes)
    lines = [
        "# skyring safety sweep",
        "",
        f"Command: `{command}`. {len(outcomes)} runs ({clustered} from clustered starts), failed: "
        f"{len(failed)}. Each run's configuration and seed follow from (base seed, run index), so any run "
        "can be flown alone with the command listed for it. The minima are over the whole flight, from "
        "take-off to landing (server/lab/metrics.py); every run's values are in `safety.json`.",
        "",
        "## Distribution of the minima over the runs",
        "",
    ]
    rows = []
    for attr, label, _ in ROWS:
        d = distribution(outcomes, attr)
        if d is None:
            rows.append([label, "0", "n/a", "n/a", "n/a", "n/a", "-"])
        else:
            cells = [_fmt(x) for x in (d.min_m, d.p1_m, d.p5_m, d.median_m)]
            rows.append([label, str(d.n), *cells, str(d.argmin_index)])
    lines.append(markdown_table(["minimum", "runs", "min", "p1", "p5", "median", "run of min"], rows))
    lines += [
        "",
        "Runs without a trunk below the MAVs' height have no clearance and are left out of its row.",
        "",
    ]
    if figure is not None:
        lines += [f"![minima]({figure})", ""]
    lines += _violations(outcomes, thresholds)
    for o in failed:
        lines.append(f"- failed: run {o.run.index} ({o.run.label}): {o.error}")
    lines += [
        "",
        TIMING_HEADING,
        "",
        f"Wall time of the command: {wall_s:.1f} s; the runs' own wall times add up to "
        f"{sum(o.wall_s for o in outcomes):.1f} s (mean {_mean_wall(outcomes):.1f} s per run).",
        "",
    ]
    return "\n".join(lines)


def _mean_wall(outcomes: Sequence[RunOutcome]) -> float:
    return sum(o.wall_s for o in outcomes) / len(outcomes) if outcomes else 0.0


def _violations(outcomes: Sequence[RunOutcome], thresholds: Thresholds) -> list[str]:
    """The violation counts, then every violating run with its minima and reproduction command."""
    limits = asdict(thresholds)
    rows = [
        [text.format(**limits), str(sum(k in o.violations(thresholds) for o in outcomes))]
        for k, text in VIOLATION_TEXT.items()
    ]
    bad = [o for o in outcomes if o.violations(thresholds)]
    lines = [
        "## Violations",
        "",
        markdown_table(["threshold", "runs"], rows),
        "",
        f"{len(bad)} of {len(outcomes)} runs broke at least one threshold.",
    ]
    for o in bad:
        lines += [
            "",
            f"- run {o.run.index} ({o.run.label}, seed {o.run.seed}): "
            + ", ".join(o.violations(thresholds))
            + f"; true pair {_when(o.separation)}, believed pair {_when(o.believed_separation)}, "
            f"clearance {_when(o.obstacle_clearance)}",
            f"  `{o.run.sim_command()}`",
        ]
    return lines


def reproducible_part(report_md: str) -> str:
    """The report without its timing section: what the same sweep must give again exactly."""
    return report_md.split("\n" + TIMING_HEADING + "\n", 1)[0]
