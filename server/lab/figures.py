"""The report's figures as PNG files, drawn with matplotlib's Agg canvas (no display, no pyplot global state).

The paper's kinds of plots: box plots per method of tracking error, uncertainty, in-frame fraction and
distance from the image centre ("Statistics of Simulation Experiment" a-d), and tracking error against the
number of MAVs, the link loss and the obstacle count. Each box holds one value per run (the run's mean over
time).
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from server.lab.report import CENTER, ERROR, IN_FRAME, UNCERTAINTY, FamilySummary

FIGURE_SIZE_IN = (6.4, 4.2)
DPI = 120
FIGURES_DIR = "figures"
LABEL_WIDTH_CHARS = 14  # tick labels wrap beyond this, so four method names fit side by side

# (metric, file stem, axis label) of the methods box plots.
METHOD_PANELS: tuple[tuple[str, str, str], ...] = (
    (ERROR, "methods_tracking_error", "mean 3-D tracking error (m)"),
    (UNCERTAINTY, "methods_uncertainty", "mean trace of fused covariance (m$^2$)"),
    (IN_FRAME, "methods_in_frame", "person fully in frame (fraction of frames)"),
    (CENTER, "methods_center_distance", "mean distance from image centre (px)"),
)
# family -> (file stem, x-axis label) of the error-versus-sweep plots.
SWEEP_PANELS: dict[str, tuple[str, str]] = {
    "scalability": ("scalability_error", "number of MAVs"),
    "commloss": ("commloss_error", "link loss (%)"),
    "obstacles": ("obstacles_error", "number of obstacles"),
}


def _finite(values: Sequence[float]) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    return arr[np.isfinite(arr)]


def _save(fig: Figure, path: Path) -> Path:
    FigureCanvasAgg(fig)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    # No "Software" text chunk: the same data gives the same bytes whatever matplotlib build drew it.
    fig.savefig(path, format="png", dpi=DPI, metadata={"Software": None})
    return path


def box_plot(
    *,
    groups: Sequence[Sequence[float]],
    labels: Sequence[str],
    ylabel: str,
    title: str,
    path: Path,
    positions: Sequence[float] | None = None,
    xlabel: str = "",
) -> Path:
    """Box plot of one metric per group (whiskers 1.5 IQR, every run drawn as a dot), saved to `path`.

    groups: one sequence of per-run values per box (non-finite values are left out; an empty group: no box).
    positions: x of each box (default 1..n); with numeric positions the groups' means are joined by a line.
    """
    if len(groups) != len(labels):
        raise ValueError(f"{len(groups)} groups but {len(labels)} labels")
    fig = Figure(figsize=FIGURE_SIZE_IN)
    ax = fig.add_subplot(1, 1, 1)
    xs = (
        np.arange(1, len(groups) + 1, dtype=float)
        if positions is None
        else np.asarray(positions, dtype=float)
    )
    width = 0.5
    if positions is not None and len(xs) > 1:
        width = min(0.6 * float(np.min(np.diff(np.sort(xs)))), 0.12 * float(np.ptp(xs)))
    data = [_finite(g) for g in groups]
    drawn = [i for i, d in enumerate(data) if d.size]
    if drawn:
        ax.boxplot(
            [data[i] for i in drawn],
            positions=xs[drawn],
            widths=width,
            showfliers=False,
            tick_labels=[textwrap.fill(labels[i], LABEL_WIDTH_CHARS) for i in drawn],
            medianprops={"color": "tab:orange"},
        )
        for i in drawn:
            jitter = np.linspace(-0.15, 0.15, data[i].size) * width if data[i].size > 1 else np.zeros(1)
            ax.plot(xs[i] + jitter, data[i], "o", color="tab:blue", alpha=0.5, markersize=3)
        if positions is not None and len(drawn) > 1:
            ax.plot(
                xs[drawn],
                [float(data[i].mean()) for i in drawn],
                "-",
                color="tab:gray",
                linewidth=1,
                label="mean",
            )
            ax.legend(loc="best")
    else:
        ax.text(0.5, 0.5, "no finished runs", ha="center", va="center", transform=ax.transAxes)
    ax.set_ylabel(ylabel)
    ax.set_xlabel(xlabel)
    ax.set_title(title)
    ax.grid(True, axis="y", alpha=0.3)
    return _save(fig, path)


def methods_figures(summary: FamilySummary, out_dir: Path) -> list[Path]:
    """Four box plots, one per metric of the paper's comparison of methods, with a box per method."""
    names = [c.condition.name for c in summary.conditions]
    paths = []
    for metric, stem, ylabel in METHOD_PANELS:
        groups = [c.values.get(metric, ()) for c in summary.conditions]
        paths.append(
            box_plot(
                groups=groups,
                labels=names,
                ylabel=ylabel,
                title=f"{metric} per method",
                path=out_dir / f"{stem}.png",
            )
        )
    return paths


def sweep_figure(summary: FamilySummary, out_dir: Path) -> Path:
    """Tracking error against the family's swept quantity (MAV count, link loss, obstacle count)."""
    stem, xlabel = SWEEP_PANELS[summary.family]
    conds = summary.conditions
    return box_plot(
        groups=[c.values.get(ERROR, ()) for c in conds],
        labels=[f"{c.condition.x:g}" for c in conds],
        positions=[c.condition.x for c in conds],
        ylabel="mean 3-D tracking error (m)",
        xlabel=xlabel,
        title=f"{ERROR} vs {xlabel}",
        path=out_dir / f"{stem}.png",
    )


def draw_all(summaries: Sequence[FamilySummary], out_dir: Path) -> dict[str, list[str]]:
    """Every figure of `summaries` under `out_dir/figures`; returns family -> paths relative to `out_dir`."""
    fig_dir = out_dir / FIGURES_DIR
    drawn: dict[str, list[Path]] = {}
    for s in summaries:
        drawn[s.family] = methods_figures(s, fig_dir) if s.family == "methods" else [sweep_figure(s, fig_dir)]
    return {family: [p.relative_to(out_dir).as_posix() for p in paths] for family, paths in drawn.items()}


def cdf_figure(
    *,
    panels: Sequence[tuple[Sequence[float], str, float | None]],
    title: str,
    path: Path,
) -> Path:
    """Empirical CDFs side by side, one panel per (values, x-axis label, threshold or None), the threshold a
    red dashed line with how many values fall below it; saved to `path`. The safety sweep draws its runs'
    minima this way: the lower tail is what matters."""
    cols = 2
    rows = max(1, (len(panels) + cols - 1) // cols)
    fig = Figure(figsize=(FIGURE_SIZE_IN[0] * 1.5, FIGURE_SIZE_IN[1] * rows * 0.85))
    for k, (values, xlabel, threshold) in enumerate(panels):
        ax = fig.add_subplot(rows, cols, k + 1)
        data = np.sort(_finite(values))
        if data.size:
            ax.step(data, np.arange(1, data.size + 1) / data.size, where="post", color="tab:blue")
        else:
            ax.text(0.5, 0.5, "no values", ha="center", va="center", transform=ax.transAxes)
        if threshold is not None:
            below = int(np.sum(data < threshold))
            ax.axvline(threshold, color="tab:red", linestyle="--", label=f"{threshold:g} m: {below} below")
            ax.legend(loc="lower right")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("fraction of runs")
        ax.set_ylim(0.0, 1.02)
        ax.grid(True, alpha=0.3)
    fig.suptitle(title)
    return _save(fig, path)
