"""Statistics over runs, the paper's claims checked against them, and `report.md`.

Everything here is a pure function of the runs' JSON reports, so the same runs give the same report to the
last character. Timings (the simulator's tick_ms and realtime_factor, the runs' wall time) differ from one
machine and moment to the next: they are kept out of the tables and claims, in a last section of their own.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy import stats as scipy_stats

from server.lab.experiments import Condition, Protocol, RunResult, platforms

# Per-run summary metrics the claims and figures use (names of the simulator's JSON report, flattened).
ERROR = "tracking_error_m.mean"
UNCERTAINTY = "cov_trace_m2.mean"
IN_FRAME = "in_frame_fraction"
CENTER = "center_offset_px.mean"
SPACING = "spacing_error_deg"

# Table order; any other metric the simulator reports follows alphabetically.
METRIC_ORDER: tuple[str, ...] = (
    "tracking_error_m.mean",
    "tracking_error_m.median",
    "tracking_error_m.p90",
    "cov_trace_m2.mean",
    "cov_trace_m2.median",
    "in_frame_fraction",
    "center_offset_px.mean",
    "center_offset_px.median",
    "spacing_error_deg",
    "distance_error_m",
    "height_error_m",
    "min_separation_m",
    "min_believed_separation_m",
    "min_obstacle_clearance_m",
    "min_person_distance_m",
)
TIMING_PREFIXES: tuple[str, ...] = ("tick_ms", "realtime_factor")
# Bookkeeping (how many frames, samples, messages, rejections): summed per condition, not tabulated.
COUNT_PREFIXES: tuple[str, ...] = ("counters", "frames", "samples", "flight_ticks")
# When and between whom a safety minimum happened (min_separation_t_s, min_person_distance_vehicle, ...):
# kept in each run's JSON to reproduce it, meaningless as a mean over runs.
EVENT_SUFFIXES: tuple[str, ...] = ("_t_s", "_vehicle")

# Tolerances of the paper's qualitative claims, stated in the report next to each verdict.
IN_FRAME_MIN = 0.90  # paper: "almost 94 %" of frames with the person fully in the image (SE3)
LOSS_TOLERANCE = 0.20  # "accurate up to 25 % loss": error within 20 % of the loss-free error
OBSTACLE_TOLERANCE = 0.20  # "only slightly deteriorates": error within 20 % of the obstacle-free error
LOSS_ACCURATE_PERCENT = 25.0
# The controllers' teammate d_min (docs/method.md#avoidance-guarantee): a closer true approach, anywhere in
# the flight (take-off and spreading out included), is reported under each family's table.
SEPARATION_MIN_M = 1.5
SEPARATION = "min_separation_m"
BELIEVED_SEPARATION = "min_believed_separation_m"


def flatten(metrics: Mapping[str, Any], prefix: str = "") -> dict[str, float]:
    """`{"a": {"b": 1}}` -> `{"a.b": 1.0}`; numbers only (None and non-numbers are dropped)."""
    flat: dict[str, float] = {}
    for key, value in metrics.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(flatten(value, prefix=f"{name}."))
        elif isinstance(value, bool):
            flat[name] = float(value)
        elif isinstance(value, int | float):
            flat[name] = float(value)
    return flat


def metric_kind(metric: str) -> str:
    """The kind of a metric: "timing" if measured with a clock (it varies between otherwise identical runs),
    "count" for bookkeeping counters, "event" for when and where a safety minimum happened, "result" for
    everything else."""
    head = metric.split(".")[0]
    if head in TIMING_PREFIXES:
        return "timing"
    if head in COUNT_PREFIXES:
        return "count"
    return "event" if head.endswith(EVENT_SUFFIXES) else "result"


def is_timing(metric: str) -> bool:
    """True for metrics measured with a clock."""
    return metric_kind(metric) == "timing"


@dataclass(frozen=True)
class Stat:
    """Spread of one metric over runs: n finite values, mean, median, quartiles (q25, q75), std, min, max."""

    n: int
    mean: float
    median: float
    q25: float
    q75: float
    std: float
    min: float
    max: float

    @property
    def iqr(self) -> float:
        return self.q75 - self.q25


def describe(values: Sequence[float | None]) -> Stat | None:
    """The `Stat` of the finite values in `values`, or None if there are none."""
    arr = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if arr.size == 0:
        return None
    q25, median, q75 = np.percentile(arr, [25.0, 50.0, 75.0])
    return Stat(
        n=int(arr.size),
        mean=float(arr.mean()),
        median=float(median),
        q25=float(q25),
        q75=float(q75),
        std=float(arr.std(ddof=1)) if arr.size > 1 else 0.0,
        min=float(arr.min()),
        max=float(arr.max()),
    )


@dataclass(frozen=True)
class ConditionSummary:
    """One condition's runs: per-run values of every metric (run order), and how many runs failed."""

    condition: Condition
    values: Mapping[str, tuple[float, ...]]
    runs_ok: int
    runs_failed: int

    def stat(self, metric: str) -> Stat | None:
        return describe(self.values.get(metric, ()))

    def mean(self, metric: str) -> float | None:
        s = self.stat(metric)
        return None if s is None else s.mean


@dataclass(frozen=True)
class FamilySummary:
    """A family's protocol and the summary of each of its conditions (protocol order)."""

    protocol: Protocol
    conditions: tuple[ConditionSummary, ...]

    @property
    def family(self) -> str:
        return self.protocol.family

    def metrics(self, kind: str) -> list[str]:
        """Names of the metrics of `kind` (see `metric_kind`) present in any run, in table order."""
        names = {m for c in self.conditions for m in c.values if metric_kind(m) == kind}
        ordered = [m for m in METRIC_ORDER if m in names]
        return ordered + sorted(names - set(ordered))

    def find(self, **settings: Any) -> ConditionSummary | None:
        """The first condition whose settings include all of `settings`."""
        for c in self.conditions:
            have = dict(c.condition.settings)
            if all(have.get(k) == v for k, v in settings.items()):
                return c
        return None


def summarize(protocol: Protocol, results: Sequence[RunResult]) -> FamilySummary:
    """Group `results` of `protocol`'s family by condition. Each metric's values are in run-index order with
    NaN for a failed run, so position i is run i of every condition (the pairs of the paired design)."""
    out = []
    for cond in protocol.conditions:
        by_index = {
            r.spec.run_index: r
            for r in results
            if r.spec.family == protocol.family and r.spec.condition == cond
        }
        flats = [
            flatten(r.report.get("metrics", {})) if r is not None and r.report is not None else {}
            for r in (by_index.get(i) for i in range(protocol.runs))
        ]
        names = sorted({m for f in flats for m in f})
        values = {m: tuple(f.get(m, math.nan) for f in flats) for m in names}
        ok = sum(1 for r in by_index.values() if r.ok)
        out.append(
            ConditionSummary(condition=cond, values=values, runs_ok=ok, runs_failed=len(by_index) - ok)
        )
    return FamilySummary(protocol=protocol, conditions=tuple(out))


# ---- the paper's claims ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ClaimCheck:
    """One of the paper's claims for a family, our evidence, and the verdict (None: too little data)."""

    family: str
    claim: str
    evidence: str
    agrees: bool | None

    @property
    def verdict(self) -> str:
        return {True: "agrees", False: "does not agree", None: "not judged"}[self.agrees]


def _fmt(v: float | None) -> str:
    if v is None or not math.isfinite(v):
        return "n/a"
    if v == 0:
        return "0"
    if abs(v) >= 1000 or abs(v) < 0.001:
        return f"{v:.3g}"
    return f"{v:.{max(0, 2 - int(math.floor(math.log10(abs(v)))))}f}"


def _paired_text(best: Sequence[float], other: Sequence[float]) -> str:
    """How many paired runs (same run index, hence the same world) have `best` below `other`; from 5 pairs on,
    also the one-sided Wilcoxon signed-rank p-value."""
    pairs = [(a, b) for a, b in zip(best, other, strict=False) if math.isfinite(a) and math.isfinite(b)]
    if not pairs:
        return ""
    text = f"lower in {sum(a < b for a, b in pairs)} of {len(pairs)} paired runs"
    diffs = [a - b for a, b in pairs]
    if len(pairs) >= 5 and any(diffs):
        test = scipy_stats.wilcoxon(diffs, alternative="less")
        p_value = float(test.pvalue)  # pyright: ignore[reportAttributeAccessIssue]  # scipy's result is untyped
        text += f", one-sided Wilcoxon p = {_fmt(p_value)}"
    return text


def _lower_than_all(
    family: str,
    claim: str,
    metric: str,
    unit: str,
    best: ConditionSummary | None,
    others: Sequence[ConditionSummary | None],
) -> ClaimCheck:
    """Claim: `best` has a lower mean `metric` than every one of `others`."""
    ours = None if best is None else best.mean(metric)
    present = [o for o in others if o is not None]
    if best is None or ours is None or len(present) < len(others):
        return ClaimCheck(family, claim, "the conditions to compare were not run", None)
    parts = []
    agrees = True
    for o in present:
        m = o.mean(metric)
        if m is None:
            return ClaimCheck(family, claim, f"{metric} missing for {o.condition.name}", None)
        agrees = agrees and ours < m
        paired = _paired_text(best.values.get(metric, ()), o.values.get(metric, ()))
        parts.append(
            f"{o.condition.name} {_fmt(m)} {unit} ({best.condition.name} {(ours - m) / m:+.1%}"
            + (f", {paired}" if paired else "")
            + ")"
        )
    evidence = f"mean {metric}: {best.condition.name} {_fmt(ours)} {unit} vs " + ", ".join(parts)
    return ClaimCheck(family, claim, evidence, agrees)


def _obstacle_cost_text(se3: ConditionSummary, se4: ConditionSummary) -> str:
    """What flying round the virtual obstacles costs SE4 against SE3 (the same method without them): the
    formation quantities that set the fused uncertainty."""
    parts = []
    for metric, unit in ((SPACING, "deg"), ("distance_error_m", "m"), (UNCERTAINTY, "m^2")):
        a, b = se4.mean(metric), se3.mean(metric)
        if a is not None and b is not None:
            parts.append(f"{metric} {_fmt(a)} vs {_fmt(b)} {unit}")
    return "what avoiding the obstacles costs SE4 against SE3: " + ", ".join(parts) if parts else ""


def _methods_claims(s: FamilySummary) -> list[ClaimCheck]:
    price = s.find(method="price")
    dqmpc = s.find(method="dqmpc")
    se3 = s.find(method="active", virtual_obstacles="none")
    se4 = s.find(method="active", virtual_obstacles="paper")
    claims = [
        _lower_than_all(
            s.family,
            "SE3 (active) has the lowest uncertainty of the person's estimate: lower mean "
            "trace of the fused covariance than SE1 (Price et al.) and SE2 (DQMPC).",
            UNCERTAINTY,
            "m^2",
            se3,
            [price, dqmpc],
        ),
        _lower_than_all(
            s.family,
            "With obstacles to avoid, the active method (SE4) still has lower uncertainty "
            "than both earlier methods.",
            UNCERTAINTY,
            "m^2",
            se4,
            [price, dqmpc],
        ),
    ]
    if se3 is not None and se4 is not None:
        claims[1] = replace(claims[1], evidence=claims[1].evidence + "; " + _obstacle_cost_text(se3, se4))
    claim = (
        f"Without obstacles, the active method keeps the person fully in the image about 94 % of the time "
        f"(we require at least {IN_FRAME_MIN:.0%})."
    )
    in_frame = None if se3 is None else se3.stat(IN_FRAME)
    if in_frame is None:
        claims.append(ClaimCheck(s.family, claim, "SE3 was not run", None))
    else:
        claims.append(
            ClaimCheck(
                s.family,
                claim,
                f"SE3 mean {IN_FRAME} = {_fmt(in_frame.mean)} (lowest run {_fmt(in_frame.min)})",
                in_frame.mean >= IN_FRAME_MIN,
            )
        )
    claims.append(
        _lower_than_all(
            s.family,
            "The active method tracks the person more accurately than Price et "
            "al. (paper, real robots: about 0.7 m against 1.2 m mean error).",
            ERROR,
            "m",
            se3,
            [price],
        )
    )
    claims.append(
        _lower_than_all(
            s.family,
            "Only the active method spreads the MAVs evenly about the person (angular gaps of 2 pi / K, the "
            "configuration that minimises the fused uncertainty): lowest spacing error.",
            SPACING,
            "deg",
            se3,
            [price, dqmpc],
        )
    )
    return claims


def _sweep(s: FamilySummary, metric: str) -> tuple[np.ndarray, np.ndarray]:
    """(x, mean of `metric`) of the conditions that have it, in x order."""
    pts = sorted((c.condition.x, m) for c in s.conditions if (m := c.mean(metric)) is not None)
    return np.array([p[0] for p in pts]), np.array([p[1] for p in pts])


def _trend_text(x: np.ndarray, y: np.ndarray, x_unit: str) -> str:
    """The straight-line fit and rank correlation of the means over the sweep (three points or more)."""
    if len(x) < 3:
        return ""
    if np.ptp(y) == 0.0:
        return "; the means are all equal"
    slope, r_value = _line_fit(x, y)
    rho = float(scipy_stats.spearmanr(x, y).statistic)  # pyright: ignore[reportAttributeAccessIssue]  # untyped
    return f"; linear fit {_fmt(slope)} m per {x_unit}, R^2 = {_fmt(r_value**2)}, Spearman rho = {_fmt(rho)}"


def _line_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Slope and correlation coefficient r of the least-squares line through (x, y) (scipy's linregress)."""
    fit = scipy_stats.linregress(x, y)
    return float(fit.slope), float(fit.rvalue)  # pyright: ignore[reportAttributeAccessIssue]  # untyped result


def _scalability_claims(s: FamilySummary) -> list[ClaimCheck]:
    claim = (
        "Tracking error falls as MAVs are added (paper: nearly linearly from 3 to 16 MAVs); we check "
        "that the largest team's mean error is below the smallest team's and that a line fitted "
        "through the means falls."
    )
    x, y = _sweep(s, ERROR)
    if len(x) < 2:
        return [ClaimCheck(s.family, claim, "fewer than two team sizes were run", None)]
    slope = _line_fit(x, y)[0] if len(x) >= 3 else (y[-1] - y[0]) / (x[-1] - x[0])
    evidence = (
        f"mean {ERROR}: {x[0]:g} MAVs {_fmt(y[0])} m, {x[-1]:g} MAVs {_fmt(y[-1])} m"
        f"{_trend_text(x, y, 'MAV')}"
    )
    return [ClaimCheck(s.family, claim, evidence, bool(y[-1] < y[0] and slope < 0))]


def _commloss_claims(s: FamilySummary) -> list[ClaimCheck]:
    x, y = _sweep(s, ERROR)
    by_x = dict(zip(x.tolist(), y.tolist(), strict=True))
    claim = (
        f"Tracking stays accurate up to {LOSS_ACCURATE_PERCENT:g} % link loss: mean error within "
        f"{LOSS_TOLERANCE:.0%} of the error without loss."
    )
    if 0.0 in by_x and LOSS_ACCURATE_PERCENT in by_x:
        ratio = by_x[LOSS_ACCURATE_PERCENT] / by_x[0.0]
        evidence = (
            f"mean {ERROR}: 0 % loss {_fmt(by_x[0.0])} m, {LOSS_ACCURATE_PERCENT:g} % loss "
            f"{_fmt(by_x[LOSS_ACCURATE_PERCENT])} m (ratio {_fmt(ratio)})"
        )
        claims = [ClaimCheck(s.family, claim, evidence, bool(ratio <= 1.0 + LOSS_TOLERANCE))]
    else:
        missing = f"0 % and {LOSS_ACCURATE_PERCENT:g} % loss were not both run"
        claims = [ClaimCheck(s.family, claim, missing, None)]
    claim = (
        "Tracking gets worse as more messages are lost: the error at the highest loss is above the "
        "loss-free one."
    )
    if len(x) >= 2 and x[0] == 0.0:
        evidence = (
            f"mean {ERROR}: 0 % loss {_fmt(y[0])} m, {x[-1]:g} % loss {_fmt(y[-1])} m"
            f"{_trend_text(x, y, 'percent of loss')}"
        )
        claims.append(ClaimCheck(s.family, claim, evidence, bool(y[-1] > y[0])))
    else:
        claims.append(ClaimCheck(s.family, claim, "0 % loss and a higher loss were not both run", None))
    return claims


def _obstacles_claims(s: FamilySummary) -> list[ClaimCheck]:
    claim = (
        f"More obstacles only slightly worsen tracking: mean error with the most obstacles within "
        f"{OBSTACLE_TOLERANCE:.0%} of the error without obstacles."
    )
    x, y = _sweep(s, ERROR)
    if len(x) < 2 or x[0] != 0.0:
        return [ClaimCheck(s.family, claim, "0 obstacles and a higher count were not both run", None)]
    ratio = y[-1] / y[0]
    evidence = (
        f"mean {ERROR}: 0 obstacles {_fmt(y[0])} m, {x[-1]:g} obstacles {_fmt(y[-1])} m "
        f"(ratio {_fmt(ratio)}){_trend_text(x, y, 'obstacle')}"
    )
    return [ClaimCheck(s.family, claim, evidence, bool(ratio <= 1.0 + OBSTACLE_TOLERANCE))]


def separation_notes(s: FamilySummary) -> list[str]:
    """Conditions where some run brought two MAVs closer than SEPARATION_MIN_M (true positions, over the whole
    flight from take-off to landing), with the closest separation the controllers themselves saw (their
    self-localised positions) in those runs."""
    notes = []
    for c in s.conditions:
        true = np.asarray(c.values.get(SEPARATION, ()), dtype=float)
        believed = np.asarray(c.values.get(BELIEVED_SEPARATION, ()), dtype=float)
        close = true < SEPARATION_MIN_M
        if not close.any():
            continue
        seen = ""
        if believed.shape == true.shape:
            closest_believed = _fmt(float(believed[close].min()))
            seen = f"; the closest the MAVs believed themselves in those runs: {closest_believed} m"
        notes.append(
            f"{c.condition.name}: {int(close.sum())} of {len(true)} runs, closest "
            f"{_fmt(float(true.min()))} m{seen}"
        )
    return notes


CLAIMS = {
    "methods": _methods_claims,
    "scalability": _scalability_claims,
    "commloss": _commloss_claims,
    "obstacles": _obstacles_claims,
}


def check_claims(summary: FamilySummary) -> list[ClaimCheck]:
    """The paper's claims for `summary`'s family (Sec. V-B), each judged on our numbers."""
    return CLAIMS[summary.family](summary)


# ---- report.md ---------------------------------------------------------------------------------------------

# Section titles, with the paper's figure each family reproduces (by its caption; figure numbers differ
# between the arXiv and RA-L versions).
TITLES = {
    "methods": 'Comparison of methods, SE1-SE4 (paper: "Statistics of Simulation Experiment" a-d)',
    "scalability": 'Scalability with the number of MAVs (paper: "scalability and robustness" a)',
    "commloss": 'Communication loss (paper: "scalability and robustness" b)',
    "obstacles": 'Number of obstacles (paper: "Statistics of Simulation Experiment" e)',
}
TIMING_HEADING = "## Timing"
MIXED_PLATFORMS = (
    "These runs were computed on more than one numeric platform: compare them as statistics, not run by run "
    '(docs/fast-core.md, "Same seed, same result: on which machines").'
)


def _total(values: Sequence[float]) -> str:
    finite = [v for v in values if math.isfinite(v)]
    return f"{sum(finite):.0f}" if finite else "n/a"


def _cell(stat: Stat | None) -> str:
    if stat is None:
        return "n/a"
    return f"{_fmt(stat.mean)} / {_fmt(stat.median)} ({_fmt(stat.iqr)})"


def _durations_text(durations: Sequence[float]) -> str:
    groups: list[list[float]] = []
    for d in durations:
        if groups and groups[-1][0] == d:
            groups[-1].append(d)
        else:
            groups.append([d])
    return ", ".join(f"{len(g)} x {_fmt(g[0])} s" for g in groups)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A GitHub-flavoured markdown table; the first column left-aligned, the others right-aligned."""
    lines = ["| " + " | ".join(header) + " |", "|:---|" + "---:|" * (len(header) - 1)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def family_table(summary: FamilySummary) -> str:
    """The family's table: a row per metric, a column per condition; cells mean / median (IQR) over runs."""
    conds = summary.conditions
    rows = [["runs ok / failed", *(f"{c.runs_ok} / {c.runs_failed}" for c in conds)]]
    rows += [[m, *(_cell(c.stat(m)) for c in conds)] for m in summary.metrics("result")]
    return markdown_table(["metric", *(c.condition.name for c in conds)], rows)


def timing_table(summaries: Sequence[FamilySummary], results: Sequence[RunResult]) -> str:
    """Per condition: the median over runs of each timing metric and the summed wall time of its runs."""
    names = sorted({m for s in summaries for m in s.metrics("timing")})
    rows = []
    for s in summaries:
        for c in s.conditions:
            mine = [r for r in results if r.spec.family == s.family and r.spec.condition == c.condition]
            cells = [_fmt(stat.median) if (stat := c.stat(m)) is not None else "n/a" for m in names]
            rows.append([s.family, c.condition.name, *cells, f"{sum(r.wall_s for r in mine):.1f}"])
    return markdown_table(["family", "condition", *(f"{m} (median)" for m in names), "wall time (s)"], rows)


@dataclass(frozen=True)
class ReportContext:
    """What the report says about how it was made: the command (reproducible part only) and the base seed."""

    command: str
    base_seed: int
    profile: str


def render_report(
    *,
    context: ReportContext,
    summaries: Sequence[FamilySummary],
    results: Sequence[RunResult],
    figures: Mapping[str, Sequence[str]],
    wall_time_s: float,
) -> str:
    """The whole `report.md`. Everything above the timing section depends only on the runs' JSON reports."""
    lines = _overview(context, summaries, results)
    for s in summaries:
        lines += _family_section(s, figures.get(s.family, ()))
    lines += _timing_section(summaries, results, wall_time_s)
    return "\n".join(lines)


def _overview(
    context: ReportContext, summaries: Sequence[FamilySummary], results: Sequence[RunResult]
) -> list[str]:
    """Title, how the runs were made, the protocol of each family, and the failed runs."""
    failed = [r for r in results if not r.ok]
    lines = [
        "# skyring experiments: the paper's simulation study, rerun",
        "",
        f"Command: `{context.command}` (profile: {context.profile}; base seed {context.base_seed}). "
        "Every run is an independent process with a seed derived from (base seed, family, run index): run i "
        "of every condition of a family flies the same world (person, trees, GPS drift, detector noise), a "
        "paired comparison. Each run's JSON report is kept beside this file under "
        "`<family>/<condition>/run-NNN.json`. "
        "The same command gives this "
        f"report again, character for character, down to the `{TIMING_HEADING[3:]}` section.",
        "",
    ]
    rows = [
        [
            p.family,
            ", ".join(c.name for c in p.conditions),
            str(p.runs),
            _durations_text(p.durations_s),
            f"{p.rate_hz:g} Hz",
        ]
        for p in (s.protocol for s in summaries)
    ]
    lines.append(
        markdown_table(["family", "conditions", "runs per condition", "durations", "control rate"], rows)
    )
    lines += ["", f"Runs: {len(results)}, failed: {len(failed)}."]
    for r in failed:
        lines.append(
            f"- failed: {r.spec.family} / {r.spec.condition.name} / run {r.spec.run_index} "
            f"(seed {r.spec.seed}): {r.error}"
        )
    return lines


def _family_section(s: FamilySummary, figures: Sequence[str]) -> list[str]:
    """One family: its table, counters, figures, the paper's claims and any separation notes."""
    lines = [
        "",
        f"## {TITLES[s.family]}",
        "",
        "Each cell: mean / median (interquartile range) over the condition's runs of the per-run value. "
        "The min_ rows (separations, clearance, person distance) are each run's minimum over the whole "
        "flight, take-off included; the other rows start after the simulator's warm-up.",
        "",
        family_table(s),
        "",
    ]
    counts = s.metrics("count")
    if counts:
        lines += ["Counters, summed over each condition's runs:", ""]
        for c in s.conditions:
            totals = ", ".join(f"{m.removeprefix('counters.')} {_total(c.values.get(m, ()))}" for m in counts)
            lines.append(f"- {c.condition.name}: {totals}")
        lines.append("")
    lines += [f"![{s.family}]({fig})" for fig in figures]
    lines += ["", "The paper's claims against our numbers:", ""]
    lines += [f"- **{c.verdict}**: {c.claim} Ours: {c.evidence}." for c in check_claims(s)]
    notes = separation_notes(s)
    if notes:
        lines += [
            "",
            f"Safety: runs in which two MAVs came closer than {SEPARATION_MIN_M:g} m (the controllers' "
            "d_min) between their true positions at any time of the flight, from take-off to landing (the "
            "warm-up included: the team spreads out then), and in those runs the closest approach between "
            "the positions the MAVs believed they were at (self-localisation with GPS drift: what the "
            "controllers keep apart). A believed approach below d_min too means the controllers "
            "themselves let the MAVs close in; a believed approach above it means the drift did.",
            "",
            *(f"- {n}" for n in notes),
        ]
    return lines


def _timing_section(
    summaries: Sequence[FamilySummary], results: Sequence[RunResult], wall_time_s: float
) -> list[str]:
    """What was measured with a clock: the only part that differs between reruns of the same command."""
    return [
        "",
        TIMING_HEADING,
        "",
        "Measured with a clock: these numbers change from run to run and machine to machine.",
        "",
        f"Wall time of the command that wrote this report: {wall_time_s:.1f} s. The runs' own wall times add "
        f"up to {sum(r.wall_s for r in results):.1f} s (runs execute in parallel; a run reused with --resume "
        "keeps the time it took then).",
        "",
        timing_table(summaries, results),
        "",
        *platform_lines(results),
    ]


def platform_lines(results: Sequence[RunResult]) -> list[str]:
    """Which numeric platforms computed the runs (server/lab/numeric_platform.py), and a warning when there
    were several: the same seed gives the same bits only on the same one, so such runs compare as
    statistics, not one by one."""
    counts = platforms(results)
    if not counts:
        return []
    lines = ["Numeric platform of the runs (the same seed gives the same bits only on the same one):", ""]
    for platform, n in counts.items():
        simd = ", ".join(platform.numpy_simd) or "none"
        lines.append(
            f"- {n} run(s): numpy {platform.numpy_version} (SIMD {simd}), OpenBLAS kernel "
            f"{platform.blas_core or 'unknown'}, {platform.libc}, {platform.machine}"
        )
    if len(counts) > 1:
        lines += ["", f"**{MIXED_PLATFORMS}**"]
    return [*lines, ""]


def reproducible_part(report_md: str) -> str:
    """The report without its timing section: what the same command must reproduce exactly."""
    return report_md.split("\n" + TIMING_HEADING + "\n", 1)[0]
