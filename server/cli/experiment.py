"""`skyring experiment`: rerun the paper's simulation experiments; write report.md with tables and figures."""

from __future__ import annotations

import os
import sys
import time
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
from server.lab import figures
from server.lab import report as rep


class Experiment(StrEnum):
    """What `skyring experiment` can run: one of the paper's studies, or all of them."""

    METHODS = "methods"
    SCALABILITY = "scalability"
    COMMLOSS = "commloss"
    OBSTACLES = "obstacles"
    ALL = "all"


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
        int | None, typer.Option(min=1, help="runs per condition (default: the paper's protocol)")
    ] = None,
    duration: Annotated[
        float | None, typer.Option(min=0.1, help="seconds per run (default: the paper's)")
    ] = None,
    rate: Annotated[
        float | None,
        typer.Option(
            min=1.0,
            max=1000.0,
            help="control rate, Hz (default 10, the MPC's step; the paper's 100: ~7x slower)",
        ),
    ] = None,
    seed: Annotated[int, typer.Option(min=0, help="base seed; each run's seed is derived from it")] = 0,
    jobs: Annotated[
        int | None, typer.Option(min=1, help="parallel worker processes (default: CPU count)")
    ] = None,
    out: Annotated[Path, typer.Option(help="output directory: runs' JSON, figures/, report.md")] = Path(
        "experiments"
    ),
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
) -> None:
    """Rerun the paper's simulation experiments (SE1-SE4, 3..16 MAVs, link loss, obstacles), write a report.

    Each run is its own process with a seed derived from --seed; its JSON goes under --out/<family>/.
    """
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
    try:
        with RunProgress(total=len(specs), stream=sys.stderr) as progress:
            results = exp.run_all(
                specs, jobs=jobs, out_dir=out, resume=resume, progress=progress, cluster=cluster
            )
    except ValueError as err:  # e.g. no scheduler at the cluster address
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(code=2) from None
    except KeyboardInterrupt:
        typer.echo(
            f"\ninterrupted: the finished runs are kept under {out}; add --resume to continue", err=True
        )
        raise typer.Exit(code=130) from None
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
