"""`skyring experiment`: rerun the paper's simulation experiments, or the safety sweep; write report.md with
tables and figures."""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from enum import StrEnum
from pathlib import Path
from typing import Annotated, TextIO

import typer
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from server.lab import experiments as exp
from server.lab import figures, safety_report
from server.lab import report as rep
from server.lab import safety_sweep as sweep


class Experiment(StrEnum):
    """What `skyring experiment` can run: one of the paper's studies, all of them, or the safety sweep."""

    METHODS = "methods"
    SCALABILITY = "scalability"
    COMMLOSS = "commloss"
    OBSTACLES = "obstacles"
    ALL = "all"
    SAFETY = "safety"


class RunProgress:
    """Progress of the runs on a stream: a rich progress bar on a terminal (done/total, failed, elapsed, time
    left, the last run), one plain line per finished run otherwise (a log file, CI)."""

    def __init__(self, *, total: int, stream: TextIO) -> None:
        self.total = total
        self.failed = 0
        self.stream = stream
        self.start = time.monotonic()
        self._console = Console(file=stream)
        self._bar: Progress | None = None
        self._task: TaskID | None = None
        if self._console.is_terminal:
            self._bar = Progress(
                TextColumn("runs"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("{task.fields[failed]} failed"),
                TimeElapsedColumn(),
                TextColumn("~"),
                TimeRemainingColumn(),
                TextColumn("{task.fields[last]}"),
                console=self._console,
            )
            self._task = self._bar.add_task("runs", total=total, failed=0, last="")

    def __enter__(self) -> RunProgress:
        if self._bar is not None:
            self._bar.start()
        return self

    def __exit__(self, *_exc: object) -> None:
        if self._bar is not None:
            self._bar.stop()

    def __call__(self, done: int, total: int, result: exp.RunResult) -> None:
        self.failed += 0 if result.ok else 1
        spec = result.spec
        last = (
            f"{spec.family} / {spec.condition.name} / run {spec.run_index} {'ok' if result.ok else 'FAILED'}"
        )
        if self._bar is not None and self._task is not None:
            self._bar.update(self._task, completed=done, failed=self.failed, last=last)
            return
        elapsed = time.monotonic() - self.start
        eta = elapsed / done * (total - done) if done else 0.0
        self.stream.write(
            f"{done}/{total} runs, {self.failed} failed, {_clock(elapsed)} elapsed, ~{_clock(eta)} left "
            f"| {last}\n"
        )
        self.stream.flush()


def _clock(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


def _command_text(
    family: str, *, quick: bool, runs: int | None, duration: float | None, rate: float | None, seed: int
) -> str:
    """The command as far as it decides the results (not --jobs, --out or --resume)."""
    parts = ["skyring experiment", family]
    if quick:
        parts.append("--quick")
    if runs is not None:
        parts.append(f"--runs {runs}")
    if duration is not None:
        parts.append(f"--duration {duration:g}")
    if rate is not None:
        parts.append(f"--rate {rate:g}")
    parts.append(f"--seed {seed}")
    return " ".join(parts)


def experiment(
    family: Annotated[Experiment, typer.Argument(help="which study to run", show_default=False)],
    runs: Annotated[
        int | None,
        typer.Option(min=1, help="runs per condition (default: the paper's protocol); safety: runs (1000)"),
    ] = None,
    duration: Annotated[
        float | None, typer.Option(min=0.1, help="seconds per run (default: the paper's; safety: 90)")
    ] = None,
    rate: Annotated[
        float | None,
        typer.Option(
            min=1.0,
            max=1000.0,
            help="control rate, Hz (default: the paper's 100; --quick and safety: 10, about 6x cheaper)",
        ),
    ] = None,
    seed: Annotated[int, typer.Option(min=0, help="base seed; each run's seed is derived from it")] = 0,
    jobs: Annotated[
        int | None, typer.Option(min=1, help="parallel worker processes (default: CPU count)")
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            help="output directory: runs' JSON, figures/, report.md (default experiments; safety: "
            "experiments/safety, with safety.json)"
        ),
    ] = None,
    quick: Annotated[
        bool, typer.Option("--quick", help="small CI profile: sweep end points, few short runs at 10 Hz")
    ] = False,
    resume: Annotated[bool, typer.Option("--resume", help="reuse finished runs already in --out")] = False,
    cluster: Annotated[
        str | None,
        typer.Option(
            help="run on an existing Dask cluster: its scheduler's address, e.g. tcp://10.0.0.5:8786 "
            "(workers: `dask worker ADDRESS --nthreads 1` where skyring is installed); "
            "default: local processes"
        ),
    ] = None,
    methods: Annotated[
        str | None,
        typer.Option(help="safety only: comma-separated methods to cycle through (active, dqmpc, price)"),
    ] = None,
    first: Annotated[
        int | None, typer.Option(min=0, help="safety only: index of the first run (fly a slice of the sweep)")
    ] = None,
) -> None:
    """Rerun the paper's simulation experiments (SE1-SE4, 3..16 MAVs, link loss, obstacles), write a report;
    or, with `safety`, the safety sweep.

    Each run is its own process with a seed derived from --seed; its JSON goes under --out/<family>/.
    `safety` flies seeded runs (default 1000 of 90 s at 10 Hz) over team size 3-16, trees, link loss,
    person and method, half of them from clustered starts, and writes safety.json and report.md with the
    distribution of each run's closest true pair, closest believed pair, trunk clearance and closest
    approach to the person over the whole flight. Violations (believed pair < 1.5 m, true pair < 1.0 m,
    trunk contact) are counted and listed with the `skyring sim` command that reproduces each, but do not
    change the exit status: like every experiment, it exits 1 only if a run failed.
    """
    if family == Experiment.SAFETY:
        if quick:
            raise typer.BadParameter("--quick is for the paper's families", param_hint="--quick")
        safety(
            runs=runs,
            duration=duration,
            rate=rate,
            seed=seed,
            jobs=jobs,
            out=out or Path("experiments") / "safety",
            resume=resume,
            cluster=cluster,
            methods=methods,
            first=first,
        )
        return
    for name, value in (("--methods", methods), ("--first", first)):
        if value is not None:
            raise typer.BadParameter("only for the safety sweep", param_hint=name)
    out = out or Path("experiments")
    try:
        families = exp.select_families(family.value)
        overrides = exp.ProfileOverrides(runs=runs, duration_s=duration, rate_hz=rate)
        protocols = [
            exp.with_overrides(exp.quick_protocol(f) if quick else exp.paper_protocol(f), overrides)
            for f in families
        ]
        specs = exp.plan_runs(protocols, base_seed=seed)
        exp.check_configs(specs)
    except ValueError as err:
        raise typer.BadParameter(str(err)) from err
    jobs = jobs or os.cpu_count() or 1
    out.mkdir(parents=True, exist_ok=True)
    where = f"the Dask cluster at {cluster}" if cluster else f"{jobs} processes"
    typer.echo(
        f"{len(specs)} runs ({sum(s.duration_s for s in specs):.0f} simulated seconds) on {where} -> {out}",
        err=True,
    )

    start = time.monotonic()
    results = _run_specs(specs, jobs=jobs, out=out, resume=resume, cluster=cluster)
    wall = time.monotonic() - start

    summaries = [rep.summarize(p, results) for p in protocols]
    drawn = figures.draw_all(summaries, out)
    context = rep.ReportContext(
        command=_command_text(family.value, quick=quick, runs=runs, duration=duration, rate=rate, seed=seed),
        base_seed=seed,
        profile="quick (CI)"
        if quick
        else "the paper's protocol" + (" with overrides" if runs or duration or rate else ""),
    )
    text = rep.render_report(
        context=context, summaries=summaries, results=results, figures=drawn, wall_time_s=wall
    )
    report_path = out / "report.md"
    report_path.write_text(text)

    claims = [c for s in summaries for c in rep.check_claims(s)]
    agreed = sum(1 for c in claims if c.agrees)
    failed = sum(1 for r in results if not r.ok)
    typer.echo(
        f"{report_path}: {len(results) - failed}/{len(results)} runs ok, {agreed}/{len(claims)} of the "
        f"paper's claims agree, wall time {wall:.1f} s"
    )
    if failed:
        typer.echo(f"error: {failed} run(s) failed; see the list in {report_path}", err=True)
        raise typer.Exit(code=1)


class _Terminated(Exception):
    """SIGTERM arrived: stop the runs as on Ctrl-C."""


@contextmanager
def _sigterm_stops_the_runs() -> Iterator[None]:
    """Turn SIGTERM into `_Terminated` while the runs go, so that the runner stops its worker processes (as
    on Ctrl-C) instead of the process dying and leaving them to finish their runs unwatched."""
    if threading.current_thread() is not threading.main_thread():  # signals reach the main thread only
        yield
        return

    def terminate(_signum: int, _frame: object) -> None:
        raise _Terminated

    previous = signal.signal(signal.SIGTERM, terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _run_specs(
    specs: list[exp.RunSpec], *, jobs: int, out: Path, resume: bool, cluster: str | None
) -> list[exp.RunResult]:
    """The runs through the experiments' runner with progress; exit 2 on an unreachable cluster, 130 on
    Ctrl-C, 143 on SIGTERM (the worker processes stopped in both)."""
    try:
        with _sigterm_stops_the_runs(), RunProgress(total=len(specs), stream=sys.stderr) as progress:
            results = exp.run_all(
                specs, jobs=jobs, out_dir=out, resume=resume, progress=progress, cluster=cluster
            )
    except ValueError as err:  # e.g. no scheduler at the cluster address
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(code=2) from None
    except (KeyboardInterrupt, _Terminated) as stop:
        how = "terminated" if isinstance(stop, _Terminated) else "interrupted"
        typer.echo(f"\n{how}: the finished runs are kept under {out}; add --resume to continue", err=True)
        raise typer.Exit(code=143 if isinstance(stop, _Terminated) else 130) from None
    if len(exp.platforms(results)) > 1:  # a cluster of unlike machines, or runs resumed from another's
        typer.echo(f"warning: {rep.MIXED_PLATFORMS}", err=True)
    return results


def _safety_command(
    *, runs: int, first: int, duration: float, rate: float, seed: int, methods: tuple[str, ...]
) -> str:
    """The sweep's command as far as it decides the results."""
    return (
        f"skyring experiment safety --runs {runs} --first {first} --duration {duration:g} --rate {rate:g} "
        f"--seed {seed} --methods {','.join(methods)}"
    )


def safety(
    *,
    runs: int | None,
    duration: float | None,
    rate: float | None,
    seed: int,
    jobs: int | None,
    out: Path,
    resume: bool,
    cluster: str | None,
    methods: str | None,
    first: int | None,
) -> None:
    """`skyring experiment safety`: plan the sweep, fly it, write safety.json, report.md and the figure."""
    chosen = tuple(m.strip().lower() for m in (methods or "active").split(",") if m.strip())
    n, start = runs or sweep.DEFAULT_RUNS, first or 0
    length, hz = duration or sweep.DEFAULT_DURATION_S, rate or sweep.DEFAULT_RATE_HZ
    try:
        plan = sweep.plan_sweep(
            base_seed=seed, runs=n, first=start, methods=chosen, duration_s=length, rate_hz=hz
        )
        specs = [r.spec() for r in plan]
        exp.check_configs(specs)
    except ValueError as err:
        raise typer.BadParameter(str(err)) from err
    jobs = jobs or os.cpu_count() or 1
    out.mkdir(parents=True, exist_ok=True)
    where = f"the Dask cluster at {cluster}" if cluster else f"{jobs} processes"
    typer.echo(f"{n} safety runs ({n * length:.0f} simulated seconds) on {where} -> {out}", err=True)
    began = time.monotonic()
    results = _run_specs(specs, jobs=jobs, out=out, resume=resume, cluster=cluster)
    wall = time.monotonic() - began

    outcomes = [sweep.outcome(r, res) for r, res in zip(plan, results, strict=True)]
    thresholds = sweep.Thresholds()
    command = _safety_command(runs=n, first=start, duration=length, rate=hz, seed=seed, methods=chosen)
    panels = [
        (
            [m.distance_m for o in outcomes if (m := getattr(o, attr)).distance_m is not None],
            label,
            getattr(thresholds, limit) if limit else None,
        )
        for attr, label, limit in safety_report.ROWS
    ]
    figure = figures.cdf_figure(
        panels=panels,
        title=f"safety minima over the whole flight, {n} runs",
        path=out / figures.FIGURES_DIR / "safety_minima.png",
    )
    doc = safety_report.sweep_json(outcomes, command=command, thresholds=thresholds, wall_s=wall)
    (out / "safety.json").write_text(json.dumps(doc, indent=2) + "\n")
    text = safety_report.render_report(
        outcomes,
        command=command,
        thresholds=thresholds,
        figure=figure.relative_to(out).as_posix(),
        wall_s=wall,
    )
    report_path = out / "report.md"
    report_path.write_text(text)
    failed = sum(1 for o in outcomes if o.error is not None)
    counts = ", ".join(
        f"{k} {sum(k in o.violations(thresholds) for o in outcomes)}" for k in safety_report.VIOLATION_TEXT
    )
    typer.echo(f"{report_path}: {n - failed}/{n} runs ok; violations: {counts}; wall time {wall:.1f} s")
    if failed:
        typer.echo(f"error: {failed} run(s) failed; see the list in {report_path}", err=True)
        raise typer.Exit(code=1)
