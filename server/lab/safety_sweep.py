"""The safety sweep (`skyring experiment safety`): many seeded runs over the situations where MAVs collide.

Each run draws a team size (3..16), trees (the paper's, none, 10 or 20 random), a link loss (0..100 %), a
person (the paper's walk, or a random walker who runs at up to 3 m/s) and a method, and starts on the ring or
clustered side by side: exactly half of the runs from clustered starts (odd run indices). A run's
configuration and seed are a function of (base seed, run index) alone, so run i flies the same whether it is
run in a sweep of 1000 or alone (`--first i --runs 1`), and `sim_command()` flies it again with `skyring sim`.
The runs go through the experiments' pool or cluster runner (server/lab/experiments.py). What is recorded
per run is the four safety minima over the whole flight, take-off and spreading out included
(server/lab/metrics.py), each with when and between whom; `server/lab/safety_report.py` writes the report.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from server.lab.experiments import Condition, RunResult, RunSpec, derive_seed

FAMILY = "safety"
TEAM_SIZES: tuple[int, ...] = tuple(range(3, 17))
TREE_CHOICES: tuple[str, ...] = ("paper", "none", "10", "20")
LINK_LOSSES: tuple[float, ...] = (0.0, 0.1, 0.25, 0.5, 0.9, 1.0)
PERSON_CHOICES: tuple[str, ...] = ("paper", "random")  # random: walks, and runs at 2-3 m/s at times
STARTS: tuple[str, ...] = ("ring", "cluster")  # by run index: even ring, odd cluster
METHOD_CHOICES: tuple[str, ...] = ("active", "dqmpc", "price")
DEFAULT_RUNS = 1000
DEFAULT_DURATION_S = 90.0
DEFAULT_RATE_HZ = 10.0
# The simulator's warm-up only delays the tracking metrics, which the sweep does not read; a run shorter than
# twice the default warm-up takes half its length instead.
DEFAULT_WARMUP_S = 20.0
_CONFIG_STREAM = "safety-config"  # the stream the configurations are drawn from (the seeds: FAMILY's)


@dataclass(frozen=True)
class Thresholds:
    """What counts as a violation: a closest believed pair below believed_separation_m (the controllers'
    d_min), a closest true pair below true_separation_m (d_min less a GPS drift allowance), a trunk
    clearance below trunk_clearance_m (0: contact)."""

    believed_separation_m: float = 1.5
    true_separation_m: float = 1.0
    trunk_clearance_m: float = 0.0


@dataclass(frozen=True)
class SweepRun:
    """One run of the sweep: its index, simulator seed and configuration (`SimConfig` fields)."""

    index: int
    seed: int
    vehicles: int
    trees: str
    comm_loss: float
    person: str
    start: str
    method: str
    duration_s: float
    rate_hz: float
    warmup_s: float

    @property
    def label(self) -> str:
        """A short description for progress lines and the report."""
        return (
            f"{self.vehicles} MAVs, trees {self.trees}, loss {self.comm_loss * 100:g} %, "
            f"person {self.person}, {self.start} start, {self.method}"
        )

    def spec(self) -> RunSpec:
        """The run for the experiments' runner: a condition of its own, named by its configuration."""
        settings = (
            ("vehicles", self.vehicles),
            ("trees", self.trees),
            ("comm_loss", self.comm_loss),
            ("person", self.person),
            ("start", self.start),
            ("method", self.method),
            ("warmup_s", self.warmup_s),
        )
        condition = Condition(name=self.label, x=float(self.vehicles), settings=settings)
        return RunSpec(
            family=FAMILY,
            condition=condition,
            run_index=self.index,
            duration_s=self.duration_s,
            seed=self.seed,
            rate_hz=self.rate_hz,
        )

    def sim_command(self) -> str:
        """The `skyring sim` command that flies this run again, to the last digit of its minima."""
        return (
            f"skyring sim --headless --vehicles {self.vehicles} --seed {self.seed} --method {self.method} "
            f"--trees {self.trees} --person {self.person} --comm-loss {_number(self.comm_loss)} "
            f"--start {self.start} --rate {_number(self.rate_hz)} --duration {_number(self.duration_s)} "
            f"--warmup {_number(self.warmup_s)}"
        )

    def config(self) -> dict[str, Any]:
        """The configuration as JSON-ready data."""
        return asdict(self)


def _number(x: float) -> str:
    """`x` as the shortest text that reads back as the same float."""
    short = f"{x:g}"
    return short if float(short) == x else repr(float(x))


def sweep_run(
    *,
    base_seed: int,
    index: int,
    methods: Sequence[str] = ("active",),
    duration_s: float = DEFAULT_DURATION_S,
    rate_hz: float = DEFAULT_RATE_HZ,
) -> SweepRun:
    """Run `index` of the sweep with base seed `base_seed`: its draws come from a numpy `SeedSequence` of
    (base seed, index), its simulator seed from `derive_seed` (the experiments' rule); the start alternates
    with the index (odd: cluster) and the method cycles through `methods` every two runs, so each method
    gets as many clustered starts as ring starts."""
    if index < 0:
        raise ValueError(f"run index must be non-negative, got {index}")
    if not methods or any(m not in METHOD_CHOICES for m in methods):
        raise ValueError(f"methods must be some of {', '.join(METHOD_CHOICES)}, got {list(methods)}")
    entropy = np.random.SeedSequence(
        entropy=base_seed, spawn_key=(zlib.crc32(_CONFIG_STREAM.encode()), index)
    )
    rng = np.random.default_rng(entropy)
    return SweepRun(
        index=index,
        seed=derive_seed(base_seed=base_seed, family=FAMILY, run_index=index),
        vehicles=int(TEAM_SIZES[rng.integers(len(TEAM_SIZES))]),
        trees=TREE_CHOICES[rng.integers(len(TREE_CHOICES))],
        comm_loss=LINK_LOSSES[rng.integers(len(LINK_LOSSES))],
        person=PERSON_CHOICES[rng.integers(len(PERSON_CHOICES))],
        start=STARTS[index % 2],
        method=methods[(index // 2) % len(methods)],
        duration_s=float(duration_s),
        rate_hz=float(rate_hz),
        warmup_s=min(DEFAULT_WARMUP_S, float(duration_s) / 2.0),
    )


def plan_sweep(
    *,
    base_seed: int,
    runs: int = DEFAULT_RUNS,
    first: int = 0,
    methods: Sequence[str] = ("active",),
    duration_s: float = DEFAULT_DURATION_S,
    rate_hz: float = DEFAULT_RATE_HZ,
) -> list[SweepRun]:
    """Runs first .. first + runs - 1 of the sweep."""
    if runs < 1:
        raise ValueError(f"runs must be at least 1, got {runs}")
    return [
        sweep_run(base_seed=base_seed, index=i, methods=methods, duration_s=duration_s, rate_hz=rate_hz)
        for i in range(first, first + runs)
    ]


@dataclass(frozen=True)
class Minimum:
    """One safety minimum of a run: metres (None: nothing to measure, e.g. no trunk below the MAVs), the
    first time it was reached (s) and between what (vehicle ids; a vehicle and an obstacle; one vehicle)."""

    distance_m: float | None
    t_s: float | None
    between: tuple[int | str, ...]


# The four minima: (record attribute, metric name of the simulator's report, key of "between").
MINIMA: tuple[tuple[str, str, str], ...] = (
    ("separation", "min_separation_m", "min_separation_pair"),
    ("believed_separation", "min_believed_separation_m", "min_believed_separation_pair"),
    ("obstacle_clearance", "min_obstacle_clearance_m", "min_obstacle_clearance_pair"),
    ("person_distance", "min_person_distance_m", "min_person_distance_vehicle"),
)


@dataclass(frozen=True)
class RunOutcome:
    """What one run measured (or why it failed), with its configuration; wall_s is a timing."""

    run: SweepRun
    separation: Minimum
    believed_separation: Minimum
    obstacle_clearance: Minimum
    person_distance: Minimum
    error: str | None = None
    wall_s: float = 0.0

    def violations(self, thresholds: Thresholds) -> tuple[str, ...]:
        """The thresholds this run broke, by name: "believed", "true", "trunk"."""
        checks = (
            ("believed", self.believed_separation.distance_m, thresholds.believed_separation_m),
            ("true", self.separation.distance_m, thresholds.true_separation_m),
            ("trunk", self.obstacle_clearance.distance_m, thresholds.trunk_clearance_m),
        )
        return tuple(name for name, value, limit in checks if value is not None and value < limit)

    def to_json(self, thresholds: Thresholds) -> dict[str, Any]:
        """The run's entry in safety.json."""
        doc: dict[str, Any] = {"index": self.run.index, "config": self.run.config()}
        for attr, metric, between in MINIMA:
            m: Minimum = getattr(self, attr)
            doc[metric] = m.distance_m
            doc[metric.removesuffix("_m") + "_t_s"] = m.t_s
            doc[between] = list(m.between) or None
        doc["violations"] = list(self.violations(thresholds))
        doc["sim_command"] = self.run.sim_command()
        doc["error"] = self.error
        doc["wall_s"] = self.wall_s
        return doc


def outcome(run: SweepRun, result: RunResult) -> RunOutcome:
    """The run's safety minima from its simulator report (all None for a failed run)."""
    metrics: Mapping[str, Any] = (result.report or {}).get("metrics", {})
    minima = {attr: _minimum(metrics, metric, between) for attr, metric, between in MINIMA}
    return RunOutcome(run=run, **minima, error=result.error, wall_s=result.wall_s)


def _minimum(metrics: Mapping[str, Any], metric: str, between_key: str) -> Minimum:
    value = metrics.get(metric)
    t = metrics.get(metric.removesuffix("_m") + "_t_s")
    between = metrics.get(between_key)
    if between is None:
        between = ()
    elif not isinstance(between, list):
        between = (between,)
    return Minimum(
        distance_m=float(value) if isinstance(value, int | float) and math.isfinite(value) else None,
        t_s=float(t) if isinstance(t, int | float) else None,
        between=tuple(between),
    )
