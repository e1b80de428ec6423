"""The settings of a run, validated once where they enter: shared by `skyring sim`, `skyring serve` and the
experiments.

`RunSettings` is the world and team (a `Scenario`, which checks its own fields) plus how fast the controllers
run; `SimConfig` (server/lab/simulation.py) adds how long a headless run lasts. Every check lives in the
dataclass that owns the field, so nothing below re-checks it; a refusal is a `ParameterError` naming the
field, which the command line turns into one line naming the option.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from controller.gps_offset import GpsOffsetParams
from controller.params import MAX_TEAM_SIZE, FormationParams, Method, ParameterError
from vehicles.agent import AgentParams
from vehicles.sim.scenario import Scenario

RATE_RANGE_HZ = (1.0, 1000.0)
MAX_VEHICLES = MAX_TEAM_SIZE


def real_number(
    field: str, value: object, *, low: float, high: float = math.inf, low_open: bool = False
) -> float:
    """`value` as a finite float in [low, high] (or (low, high] with low_open); ParameterError otherwise."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ParameterError(field, f"must be a number, got {value!r}")
    number = float(value)
    below = number <= low if low_open else number < low
    if not math.isfinite(number) or below or number > high:
        lo = f"above {low:g}" if low_open else f"at least {low:g}"
        span = lo if math.isinf(high) else f"{lo} and at most {high:g}"
        raise ParameterError(field, f"must be {span}, got {value!r}")
    return number


@dataclass(frozen=True)
class RunSettings:
    """A simulated team in its world, and its control rate.

    vehicles: K, 1..MAX_VEHICLES (16: the controller is tuned and tested for K <= 16, and at the paper's
    d_des = 8 m a 17th MAV would put the finished ring inside the teammates' repulsion,
    docs/method.md#avoidance-guarantee); seed >= 0; method; trees: "paper", "none" or N random; person: paper,
    random or still; comm_loss in [0, 1]; start: ring or cluster; d_des_m, h_des_m: the operator's formation;
    latency_s: link latency; gps_drift; virtual_obstacles: none or paper (the paper's SE4); rate_hz: control
    rate (the paper: 100 Hz); replan_hz: 0 solves every MPC every tick (the paper), a positive rate <= rate_hz
    at most that often, following the latest plan in between (vehicles/agent.py); gps_offset: each MAV
    estimates its GPS offset relative to the team and places its teammates by it in its separation rows
    (controller/gps_offset.py; False: it takes their plans as their GPS puts them, as the paper's MAVs did).
    """

    vehicles: int = 3
    seed: int = 0
    method: Method = Method.ACTIVE
    trees: str = "paper"
    person: str = "paper"
    comm_loss: float = 0.0
    start: str = "ring"
    d_des_m: float = 8.0
    h_des_m: float = 8.0
    latency_s: float = 0.03
    gps_drift: bool = True
    virtual_obstacles: str = "none"
    rate_hz: float = 100.0
    replan_hz: float = 0.0
    gps_offset: bool = True

    def __post_init__(self) -> None:
        put = object.__setattr__
        for name in ("d_des_m", "h_des_m"):
            put(self, name, real_number(name, getattr(self, name), low=0.0, low_open=True))
        put(
            self, "rate_hz", real_number("rate_hz", self.rate_hz, low=RATE_RANGE_HZ[0], high=RATE_RANGE_HZ[1])
        )
        put(self, "replan_hz", real_number("replan_hz", self.replan_hz, low=0.0, high=self.rate_hz))
        world = self.scenario()  # vehicles, seed, method, trees, person, ...: checked by their owner
        for name in ("vehicles", "seed", "method", "trees"):
            put(self, name, getattr(world, name))  # as the scenario normalised them (int, Method, "12")

    @property
    def formation(self) -> FormationParams:
        return FormationParams(d_des_m=self.d_des_m, h_des_m=self.h_des_m)

    @property
    def replan_period_s(self) -> float:
        """Seconds between MPC solves when replan_hz > 0, else 0 (every tick)."""
        return 1.0 / self.replan_hz if self.replan_hz > 0 else 0.0

    @property
    def agent_params(self) -> AgentParams:
        """What every simulated MAV's agent runs with: the re-planning period and the GPS offset estimate."""
        return AgentParams(
            replan_period_s=self.replan_period_s, gps_offset=GpsOffsetParams() if self.gps_offset else None
        )

    def scenario(self) -> Scenario:
        """The world and team these settings fly."""
        return Scenario(
            vehicles=self.vehicles,
            seed=self.seed,
            method=self.method,
            trees=self.trees,
            person=self.person,
            comm_loss=self.comm_loss,
            latency_s=self.latency_s,
            start=self.start,
            gps_drift=self.gps_drift,
            virtual_obstacles=self.virtual_obstacles,
            formation=self.formation,
        )

    def to_dict(self) -> dict[str, Any]:
        """Every field by name, JSON-ready (the method as its name)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["method"] = self.method.value
        return out
