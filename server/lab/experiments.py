"""The paper's simulation experiments as data: families, their conditions, per-run seeds, and a process pool.

A *family* is one of the paper's studies (Sec. V-B): `methods` (SE1-SE4), `scalability` (3..16 MAVs),
`commloss` (link loss) and `obstacles` (obstacle count). Each family is a list of *conditions* (one cell of
the sweep: a set of `SimConfig` fields) run `runs` times. Every run is an independent worker process whose
seed is derived from (base seed, family, run index) with numpy's `SeedSequence`, so the same command gives the
same runs in any order and with any number of workers, and run i of every condition of a family flies the
same world (a paired comparison; see `derive_seed`).

Runs go to a local process pool by default, or, for sweeps that outgrow one machine, to an existing Dask
distributed cluster (`run_all(..., cluster="tcp://host:8786")`): its workers run the same `run_one`, so a
run's report is the same wherever it ran on the same numeric platform (numeric_platform.py; each run records
its own, and tests/server/lab/test_experiments_cluster.py checks the equality on a local cluster). Dask
rather than Ray: it is pure Python from PyPI (a few MB, no native runtime to match between machines), a
cluster is one `dask scheduler` plus `dask worker ADDRESS --nthreads 1` per core anywhere the project is
installed, and a client needs nothing but the address; the runs are independent, CPU-bound and return small
JSON, so a plain task queue is all the sweep needs (docs/fast-core.md, "Sweeps on a cluster").
"""

from __future__ import annotations

import importlib
import json
import multiprocessing
import re
import signal
import time
import traceback
import zlib
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from server.lab.numeric_platform import NumericPlatform, numeric_platform

FAMILIES: tuple[str, ...] = ("methods", "scalability", "commloss", "obstacles")

# The module that runs one simulation: `SimConfig(**fields)` and `run_simulation(config) -> report` with
# `report.to_json()`. Imported inside each worker process, never in the parent.
SIMULATION_MODULE = "server.lab.simulation"


@dataclass(frozen=True)
class Condition:
    """One cell of a family's sweep.

    name: label in tables and figures (e.g. "SE3 active", "8 MAVs", "25 % loss"); x: the swept quantity for
    plots (SE number, MAV count, loss in percent, obstacle count); settings: `SimConfig` fields as
    (name, value) pairs, applied on top of the simulator's defaults.
    """

    name: str
    x: float
    settings: tuple[tuple[str, Any], ...]

    @property
    def slug(self) -> str:
        """File-system name of the condition: lower case, runs of other characters as one '-'."""
        return re.sub(r"[^a-z0-9]+", "-", self.name.lower()).strip("-")


@dataclass(frozen=True)
class Protocol:
    """How one family is run: its conditions, each run's duration (one entry per run index, seconds) and the
    control rate of every run (Hz; the paper's protocol runs at the paper's PAPER_RATE_HZ)."""

    family: str
    conditions: tuple[Condition, ...]
    durations_s: tuple[float, ...]
    rate_hz: float = 100.0

    @property
    def runs(self) -> int:
        return len(self.durations_s)


@dataclass(frozen=True)
class RunSpec:
    """One simulation to run: where it belongs, how long, and its derived seed."""

    family: str
    condition: Condition
    run_index: int
    duration_s: float
    seed: int
    rate_hz: float = 100.0

    def config_fields(self) -> dict[str, Any]:
        """Keyword arguments for `SimConfig`: the condition's settings and this run's duration, seed, rate."""
        return {
            **dict(self.condition.settings),
            "duration_s": self.duration_s,
            "seed": self.seed,
            "rate_hz": self.rate_hz,
        }

    def relative_path(self) -> Path:
        """Where this run's JSON report lives under the output directory."""
        return Path(self.family) / self.condition.slug / f"run-{self.run_index:03d}.json"


@dataclass(frozen=True)
class RunResult:
    """The outcome of one run: the simulator's JSON report (`{"config", "metrics"}`) or the reason it failed.

    wall_s: the worker's wall time for the run (a timing: not part of the reproducible results).
    platform: the numeric platform the run was computed on (numeric_platform.py: the same seed gives the same
    bits only on the same one); None where no worker reported it (a worker that died, an older run file).
    """

    spec: RunSpec
    report: dict[str, Any] | None
    error: str | None = None
    wall_s: float = 0.0
    platform: NumericPlatform | None = None

    @property
    def ok(self) -> bool:
        return self.report is not None


@dataclass(frozen=True)
class ProfileOverrides:
    """What the user changed on the command line; None keeps the profile's value."""

    runs: int | None = None
    duration_s: float | None = None
    rate_hz: float | None = None


# ---- the paper's protocol (docs/method.md#experiments) ----------------------------------------------------

PAPER_METHODS: tuple[tuple[str, str, str], ...] = (
    # (label, method, virtual obstacles): SE4 avoids the paper's 13 tree positions as virtual obstacles
    # (avoided, not seen by the cameras); no trunks anywhere in this family.
    ("SE1 price", "price", "none"),
    ("SE2 dqmpc", "dqmpc", "none"),
    ("SE3 active", "active", "none"),
    ("SE4 active + virtual obstacles", "active", "paper"),
)
# The methods family starts every team side by side (the simulator's "cluster" start), so each method has to
# build its own formation. From the "ring" start the baselines would be handed the evenly spaced formation
# that only the active method creates, and the comparison would not test formation control at all.
METHODS_START = "cluster"
PAPER_VEHICLES_METHODS = 5
PAPER_VEHICLE_COUNTS: tuple[int, ...] = tuple(range(3, 17))
PAPER_LOSS_PERCENT: tuple[int, ...] = (0, 10, 25, 50, 75, 90, 100)
PAPER_VEHICLES_COMMLOSS = 8
PAPER_OBSTACLE_COUNTS: tuple[int, ...] = (0, 5, 10, 15, 20)
PAPER_VEHICLES_OBSTACLES = 5

QUICK_VEHICLE_COUNTS: tuple[int, ...] = (3, 16)
QUICK_LOSS_PERCENT: tuple[int, ...] = (0, 25, 100)
QUICK_OBSTACLE_COUNTS: tuple[int, ...] = (0, 20)
QUICK_RUNS = 2
QUICK_DURATION_S = 30.0
# The paper's protocol runs at the paper's control rate: the MPC re-solved every tick at 100 Hz. `--rate 10`
# (the MPC's own step, dt = 0.1 s: the team still re-plans every step of its horizon, only the way-point
# follower sees set-points less often) costs about a sixth as much to simulate; the method ordering is the
# same at both rates and the means differ by a few percent (SE3, 4 paired runs of 120 s: tracking error
# 0.450 vs 0.446 m, covariance trace 0.113 vs 0.109 m^2, spacing error 5.4 vs 5.2 deg, in frame 0.996 vs
# 0.999). What the whole protocol costs at either rate: `skyring bench protocol` (docs/fast-core.md). The
# quick profile, a smoke test of the pipeline, keeps the cheaper rate.
PAPER_RATE_HZ = 100.0
QUICK_RATE_HZ = 10.0


def _methods_conditions() -> tuple[Condition, ...]:
    return tuple(
        Condition(
            name=label,
            x=float(i + 1),
            settings=(
                ("vehicles", PAPER_VEHICLES_METHODS),
                ("method", method),
                ("trees", "none"),
                ("virtual_obstacles", virtual),
                ("person", "paper"),
                ("start", METHODS_START),
            ),
        )
        for i, (label, method, virtual) in enumerate(PAPER_METHODS)
    )


def _scalability_conditions(counts: Iterable[int]) -> tuple[Condition, ...]:
    return tuple(
        Condition(
            name=f"{k} MAVs",
            x=float(k),
            settings=(("vehicles", k), ("method", "active"), ("trees", "paper"), ("person", "paper")),
        )
        for k in counts
    )


def _commloss_conditions(percents: Iterable[int]) -> tuple[Condition, ...]:
    return tuple(
        Condition(
            name=f"{p} % loss",
            x=float(p),
            settings=(
                ("vehicles", PAPER_VEHICLES_COMMLOSS),
                ("method", "active"),
                ("trees", "paper"),
                ("person", "paper"),
                ("comm_loss", p / 100.0),
            ),
        )
        for p in percents
    )


def _obstacles_conditions(counts: Iterable[int]) -> tuple[Condition, ...]:
    return tuple(
        Condition(
            name=f"{n} obstacles",
            x=float(n),
            settings=(
                ("vehicles", PAPER_VEHICLES_OBSTACLES),
                ("method", "active"),
                ("trees", str(n) if n > 0 else "none"),
                ("person", "random"),
            ),
        )
        for n in counts
    )


def paper_protocol(family: str) -> Protocol:
    """The paper's protocol for `family`: SE1-SE4 with 5 MAVs, 30 runs (10 of 120 s, 20 of 180 s);
    3..16 MAVs with trees, 10 runs; 0..100 % link loss with 8 MAVs, 3 runs; 0..20 obstacles with 5 MAVs,
    5 runs of 180 s. Control rate PAPER_RATE_HZ, the paper's 100 Hz."""
    if family == "methods":
        return Protocol(family, _methods_conditions(), (120.0,) * 10 + (180.0,) * 20, PAPER_RATE_HZ)
    if family == "scalability":
        return Protocol(family, _scalability_conditions(PAPER_VEHICLE_COUNTS), (120.0,) * 10, PAPER_RATE_HZ)
    if family == "commloss":
        return Protocol(family, _commloss_conditions(PAPER_LOSS_PERCENT), (120.0,) * 3, PAPER_RATE_HZ)
    if family == "obstacles":
        return Protocol(family, _obstacles_conditions(PAPER_OBSTACLE_COUNTS), (180.0,) * 5, PAPER_RATE_HZ)
    raise ValueError(f"unknown experiment family {family!r}; choose from {', '.join(FAMILIES)}")


def quick_protocol(family: str) -> Protocol:
    """A small profile for CI: the sweep's end points (and 25 % loss), a few short runs per condition at the
    MPC's own rate (QUICK_RATE_HZ, 10 Hz)."""
    durations = (QUICK_DURATION_S,) * QUICK_RUNS
    if family == "methods":
        return Protocol(family, _methods_conditions(), durations, QUICK_RATE_HZ)
    if family == "scalability":
        return Protocol(family, _scalability_conditions(QUICK_VEHICLE_COUNTS), durations, QUICK_RATE_HZ)
    if family == "commloss":
        return Protocol(family, _commloss_conditions(QUICK_LOSS_PERCENT), durations, QUICK_RATE_HZ)
    if family == "obstacles":
        return Protocol(family, _obstacles_conditions(QUICK_OBSTACLE_COUNTS), durations, QUICK_RATE_HZ)
    raise ValueError(f"unknown experiment family {family!r}; choose from {', '.join(FAMILIES)}")


def with_overrides(protocol: Protocol, overrides: ProfileOverrides) -> Protocol:
    """`protocol` with the user's run count, duration and/or control rate. A new run count keeps the profile's
    mix of durations in proportion (the paper's methods family: the first third of the runs short, the rest
    long)."""
    durations = protocol.durations_s
    if overrides.runs is not None:
        if overrides.runs < 1:
            raise ValueError(f"runs must be at least 1, got {overrides.runs}")
        n = len(durations)
        durations = tuple(durations[min(n - 1, (i * n) // overrides.runs)] for i in range(overrides.runs))
    if overrides.duration_s is not None:
        if not (np.isfinite(overrides.duration_s) and overrides.duration_s > 0):
            raise ValueError(f"duration must be a positive number of seconds, got {overrides.duration_s}")
        durations = (float(overrides.duration_s),) * len(durations)
    rate = protocol.rate_hz
    if overrides.rate_hz is not None:
        if not (np.isfinite(overrides.rate_hz) and overrides.rate_hz > 0):
            raise ValueError(f"rate must be a positive number of hertz, got {overrides.rate_hz}")
        rate = float(overrides.rate_hz)
    return Protocol(protocol.family, protocol.conditions, durations, rate)


def select_families(name: str) -> tuple[str, ...]:
    """The families a command argument names: one family, or all of them for "all"."""
    if name == "all":
        return FAMILIES
    if name not in FAMILIES:
        raise ValueError(f"unknown experiment {name!r}; choose from {', '.join(FAMILIES)} or all")
    return (name,)


# ---- seeds and the run plan --------------------------------------------------------------------------------


def _stable_key(text: str) -> int:
    """A platform- and run-independent integer for a label (Python's hash() is salted per process)."""
    return zlib.crc32(text.encode("utf-8"))


def derive_seed(*, base_seed: int, family: str, run_index: int) -> int:
    """The seed of run `run_index` of every condition of `family`, via `np.random.SeedSequence` from
    (base seed, family, run index).

    The condition is deliberately left out: run i of each condition flies the same world (person, trees, GPS
    drift, detector noise), a paired design (common random numbers), so a difference between two conditions
    comes from the conditions and not from luck. Measured: with 8 MAVs and 60 s runs, the run-to-run spread of
    the mean tracking error (0.28-0.59 m, mostly GPS drift) hid the 0 % vs 25 % link-loss comparison, while
    paired runs differed by 8 % at most. Independent of the order of execution and of the number of workers.
    """
    if base_seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {base_seed}")
    seq = np.random.SeedSequence(entropy=base_seed, spawn_key=(_stable_key(family), run_index))
    return int(seq.generate_state(1, dtype=np.uint32)[0])


def plan_runs(protocols: Sequence[Protocol], *, base_seed: int) -> list[RunSpec]:
    """Every run of `protocols`, family by family, condition by condition, run index ascending."""
    return [
        RunSpec(
            family=p.family,
            condition=c,
            run_index=i,
            duration_s=d,
            seed=derive_seed(base_seed=base_seed, family=p.family, run_index=i),
            rate_hz=p.rate_hz,
        )
        for p in protocols
        for c in p.conditions
        for i, d in enumerate(p.durations_s)
    ]


def check_configs(specs: Sequence[RunSpec], *, simulator: str = SIMULATION_MODULE) -> None:
    """Build every run's simulator config before anything runs, so a bad setting (say, a duration shorter
    than the simulator's warm-up) is one clear error now rather than a failure in every worker.

    Raises ValueError naming the family and condition.
    """
    sim = importlib.import_module(simulator)
    for spec in specs:
        try:
            sim.SimConfig(**spec.config_fields())
        except (TypeError, ValueError) as err:
            raise ValueError(f"{spec.family} / {spec.condition.name}: {err}") from None


# ---- execution ---------------------------------------------------------------------------------------------


def run_one(spec: RunSpec, simulator: str = SIMULATION_MODULE) -> RunResult:
    """Run one simulation (in a worker process) and return its JSON report, or the error it raised."""
    start = time.perf_counter()
    try:
        sim = importlib.import_module(simulator)
        config = sim.SimConfig(**spec.config_fields())
        report = sim.run_simulation(config).to_json()
        return RunResult(
            spec=spec, report=report, wall_s=time.perf_counter() - start, platform=numeric_platform()
        )
    except Exception as exc:  # a broken run is recorded and counted; the experiment goes on
        detail = "".join(traceback.format_exception_only(type(exc), exc)).strip()
        wall_s = time.perf_counter() - start
        return RunResult(spec=spec, report=None, error=detail, wall_s=wall_s, platform=numeric_platform())


def run_document(result: RunResult) -> dict[str, Any]:
    """The JSON kept for one run: the simulator's report plus an `experiment` block placing it."""
    doc: dict[str, Any] = dict(result.report or {})
    doc["experiment"] = {
        "family": result.spec.family,
        "condition": result.spec.condition.name,
        "x": result.spec.condition.x,
        "run_index": result.spec.run_index,
        "seed": result.spec.seed,
        "duration_s": result.spec.duration_s,
        "sim_fields": result.spec.config_fields(),
        "error": result.error,
        "wall_s": result.wall_s,
        "platform": None if result.platform is None else result.platform.to_json(),
    }
    return doc


def write_run(result: RunResult, out_dir: Path) -> Path:
    """Write one run's JSON under `out_dir` (atomically: a partial file never looks like a finished run)."""
    path = out_dir / result.spec.relative_path()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(run_document(result), indent=2, sort_keys=True) + "\n")
    tmp.replace(path)
    return path


def load_run(spec: RunSpec, out_dir: Path) -> RunResult | None:
    """A finished run of `spec` under `out_dir` (same condition and simulator fields), else None."""
    path = out_dir / spec.relative_path()
    try:
        doc = json.loads(path.read_text())
        meta = doc["experiment"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    same = (
        meta.get("condition") == spec.condition.name
        and meta.get("sim_fields") == json.loads(json.dumps(spec.config_fields()))
        and meta.get("error") is None
        and "metrics" in doc
    )
    if not same:
        return None
    report = {k: v for k, v in doc.items() if k != "experiment"}
    try:
        platform = NumericPlatform.from_json(meta["platform"])
    except (KeyError, ValueError):  # written before runs recorded it
        platform = None
    return RunResult(spec=spec, report=report, wall_s=float(meta.get("wall_s", 0.0)), platform=platform)


def platforms(results: Iterable[RunResult]) -> dict[NumericPlatform, int]:
    """How many of the results were computed on each numeric platform (the ones that recorded it)."""
    return Counter(result.platform for result in results if result.platform is not None)


ProgressCallback = Callable[[int, int, RunResult], None]


def _fresh_process_pool(*, jobs: int, simulator: str) -> ProcessPoolExecutor:
    """A process pool in which every task runs in a new process (max_tasks_per_child=1): runs share nothing.

    With 'forkserver' (Linux) the simulator is imported and the controller's compiled kernels are loaded once,
    in the fork server, so each new worker starts in milliseconds instead of re-importing numpy, osqp and
    filterpy and loading the kernels again (about 0.14 s of CPU per run, measured); elsewhere 'spawn'.
    """
    method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    ctx = multiprocessing.get_context(method)
    if method == "forkserver":
        ctx.set_forkserver_preload([__name__, simulator, "server.lab.warm_kernels"])
    return ProcessPoolExecutor(
        max_workers=jobs, mp_context=ctx, max_tasks_per_child=1, initializer=_ignore_interrupts
    )


def _ignore_interrupts() -> None:
    """Workers leave Ctrl-C to the parent, which stops them (see `_stop`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _stop(executor: ProcessPoolExecutor) -> None:
    """End the running runs now and drop the queued ones (on Ctrl-C): finished runs are already on disk.

    The executor has no public way to end running tasks, so its workers are terminated first; the executor
    then sees a broken pool, fails the remaining futures and shuts down cleanly.
    """
    for process in list((getattr(executor, "_processes", None) or {}).values()):
        process.terminate()
    executor.shutdown(wait=True, cancel_futures=True)


def _run_on_cluster(
    specs: Sequence[RunSpec],
    pending: list[int],
    *,
    address: str,
    simulator: str,
    done: Callable[[int, RunResult], None],
    timeout_s: float,
) -> None:
    """Run specs[i] for every i in pending on the Dask cluster at `address`; call done(i, result) as each
    finishes. A run whose worker died comes back as a failed RunResult; Ctrl-C cancels what is left."""
    from distributed import Client, as_completed  # imported only when a cluster is asked for

    try:
        client = Client(address, timeout=f"{timeout_s}s")
    except OSError as err:
        raise ValueError(f"cannot reach the Dask scheduler at {address}: {err}") from None
    try:
        futures = {
            client.submit(run_one, specs[i], simulator, key=f"skyring-run-{i}-{specs[i].seed}", pure=False): i
            for i in pending
        }
        try:
            for fut in as_completed(list(futures)):
                i = futures[fut]
                try:
                    result = fut.result()
                except Exception as exc:  # the worker itself failed (killed, out of memory, lost)
                    result = RunResult(spec=specs[i], report=None, error=f"worker failed: {exc!r}")
                done(i, result)
        except BaseException:
            client.cancel(list(futures))
            raise
    finally:
        client.close()


def run_all(
    specs: Sequence[RunSpec],
    *,
    jobs: int,
    out_dir: Path,
    resume: bool = False,
    progress: ProgressCallback | None = None,
    simulator: str = SIMULATION_MODULE,
    cluster: str | None = None,
    cluster_timeout_s: float = 20.0,
) -> list[RunResult]:
    """Run every spec in worker processes (at most `jobs` at once), write each run's JSON under `out_dir` as
    it finishes, and return the results in the order of `specs`. With `resume`, finished runs already on disk
    with the same seed and duration are reused instead of rerun. With `cluster` (a Dask scheduler address,
    e.g. "tcp://10.0.0.5:8786") the runs go to that cluster's workers instead (`jobs` is then unused; a
    scheduler not reached within cluster_timeout_s is a ValueError); the reports are the same."""
    if jobs < 1:
        raise ValueError(f"jobs must be at least 1, got {jobs}")
    results: dict[int, RunResult] = {}
    total = len(specs)

    def finished(i: int, result: RunResult) -> None:
        results[i] = result
        if progress is not None:
            progress(len(results), total, result)

    pending: list[int] = []
    for i, spec in enumerate(specs):
        on_disk = load_run(spec, out_dir) if resume else None
        if on_disk is None:
            pending.append(i)
        else:
            finished(i, on_disk)
    if not pending:
        return [results[i] for i in range(total)]
    if cluster is not None:

        def written(i: int, result: RunResult) -> None:
            write_run(result, out_dir)
            finished(i, result)

        _run_on_cluster(
            specs, pending, address=cluster, simulator=simulator, done=written, timeout_s=cluster_timeout_s
        )
        return [results[i] for i in range(total)]
    executor = _fresh_process_pool(jobs=min(jobs, len(pending)), simulator=simulator)
    try:
        futures = {executor.submit(run_one, specs[i], simulator): i for i in pending}
        remaining = set(futures)
        while remaining:
            done, remaining = wait(remaining, return_when=FIRST_COMPLETED)
            for fut in done:
                i = futures[fut]
                try:
                    result = fut.result()
                except Exception as exc:  # the worker process itself died (e.g. killed, out of memory)
                    result = RunResult(spec=specs[i], report=None, error=f"worker failed: {exc!r}")
                write_run(result, out_dir)
                finished(i, result)
    except BaseException:
        _stop(executor)
        raise
    executor.shutdown(wait=True)
    return [results[i] for i in range(total)]
