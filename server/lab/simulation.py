"""The deterministic simulation runner: world + mission stepped in simulated time as fast as the CPU allows.

Fixed control step 1 / rate_hz, physics on a 10 ms grid, one seed for everything: the same config gives the
same report to the last digit, except the two timing metrics (tick_ms, realtime_factor), which are the only
things that read the wall clock. `run_simulation(SimConfig) -> SimReport` is what `skyring sim` and the
experiments' worker processes call.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from controller.params import ControllerParams, ParameterError
from server.lab.metrics import WARMUP_EPS_S, Recorder, TickSample
from server.settings import RunSettings, real_number
from vehicles.mission import MissionSnapshot, Phase, VehicleSnapshot
from vehicles.sim.autopilot import SimAutopilot
from vehicles.sim.scenario import SimSetup, build_sim

TIMING_METRICS = ("tick_ms", "realtime_factor")


@dataclass(frozen=True)
class SimConfig(RunSettings):
    """One headless run: the team, world and rates of `RunSettings` (server/settings.py), and its length.

    duration_s: simulated seconds (> 0), warm-up included; warmup_s: the tracking and formation metrics start
    after this (0 <= warmup_s < duration_s; the default covers takeoff, about 7 s, and settling); the safety
    minima cover the whole flight (server/lab/metrics.py).
    """

    duration_s: float = 60.0
    warmup_s: float = 20.0

    def __post_init__(self) -> None:
        super().__post_init__()
        duration = real_number("duration_s", self.duration_s, low=0.0, low_open=True)
        object.__setattr__(self, "duration_s", duration)
        warmup = real_number("warmup_s", self.warmup_s, low=0.0)
        if warmup >= duration:
            raise ParameterError("warmup_s", f"must be below duration_s ({duration:g} s), got {warmup:g}")
        object.__setattr__(self, "warmup_s", warmup)


@dataclass(frozen=True, eq=False)
class SimReport:
    """A run's config and metrics (server.lab.metrics names); `to_json()` is the report file."""

    config: SimConfig
    metrics: Mapping[str, Any]

    def to_dict(self) -> dict[str, Any]:
        return {"config": self.config.to_dict(), "metrics": dict(self.metrics)}

    def to_json(self) -> dict[str, Any]:
        """The report as JSON-ready data: {"config": {...}, "metrics": {...}}."""
        return json.loads(json.dumps(self.to_dict()))

    def dumps(self) -> str:
        """The report file's text."""
        return json.dumps(self.to_dict(), indent=2) + "\n"


def _sample(setup: SimSetup, snap: MissionSnapshot, t: float) -> TickSample:
    truth = snap.person_truth
    if truth is None:
        raise ValueError("the simulated world must know where the person is")
    person = np.asarray(truth.position_m)
    k = len(snap.vehicles)
    estimates = np.full((k, 3), np.nan)
    traces = np.full(k, np.nan)
    for i, v in enumerate(snap.vehicles):
        if v.person is not None:
            estimates[i] = v.person.position_m
            traces[i] = v.person.position_cov_trace_m2
    return TickSample(
        t_s=t,
        positions_m=np.array([a.true_position_m for a in setup.autopilots]),
        in_formation=np.array([v.phase == Phase.FORMATION for v in snap.vehicles]),
        in_air=np.array([a.in_air for a in setup.autopilots]),
        person_m=person,
        estimates_m=estimates,
        cov_traces_m2=traces,
        d_des_m=snap.formation.d_des_m,
        h_des_m=snap.formation.h_des_m,
        believed_positions_m=np.array(
            [_believed(v, a) for v, a in zip(snap.vehicles, setup.autopilots, strict=True)]
        ),
    )


def _believed(vehicle: VehicleSnapshot, autopilot: SimAutopilot) -> np.ndarray:
    """(3,) where the MAV thinks it is: its autopilot's self-localised position less its estimated GPS offset
    (the truth before the first telemetry)."""
    believed = vehicle.believed_position_m
    return np.asarray(believed if believed is not None else autopilot.true_position_m, dtype=float)


def run_simulation(
    config: SimConfig,
    *,
    progress: Callable[[float], None] | None = None,
    controller_params: ControllerParams | None = None,
) -> SimReport:
    """Run `config` headless and return its report. progress(t_s), if given, is called about once a
    simulated second; controller_params (default: the method's) is for benchmarks that compare solvers."""
    setup = build_sim(
        config.scenario(),
        clock=time.perf_counter,
        agent_params=config.agent_params,
        controller_params=controller_params,
    )
    mission, world = setup.mission, setup.world
    ids = mission.vehicle_ids
    recorder = Recorder(obstacles=mission.obstacles(), warmup_s=config.warmup_s, vehicle_ids=ids)
    steps = max(1, round(config.duration_s * config.rate_hz))
    per_second = max(1, round(config.rate_hz))
    wall0 = None
    first = steps + 1
    for i in range(1, steps + 1):
        t = i / config.rate_hz
        if wall0 is None and t >= config.warmup_s - WARMUP_EPS_S:
            wall0, first = time.perf_counter(), i  # timing starts with the first measured tick
        mission.step(t)
        frames = world.drain_frames()
        snap = mission.snapshot()
        sample = _sample(setup, snap, t)
        recorder.add_tick(sample)  # every tick: the safety minima cover the whole flight
        if wall0 is None:
            if progress is not None and i % per_second == 0:
                progress(t)
            continue
        formation = {vid for vid, f in zip(ids, sample.in_formation, strict=True) if f}
        for f in frames:
            if f.vehicle_id in formation and f.stamp_s >= config.warmup_s - WARMUP_EPS_S:
                recorder.add_frame(
                    in_frame=f.view.in_frame, center_offset_px=f.view.center_offset_px, detected=f.detected
                )
        for v in snap.vehicles:
            if v.vehicle_id in formation and v.tick_s is not None:
                recorder.add_tick_time(v.tick_s)
        if progress is not None and i % per_second == 0:
            progress(t)
    wall_s = time.perf_counter() - wall0 if wall0 is not None else 0.0
    metrics = recorder.metrics(sim_s=(steps - first + 1) / config.rate_hz, wall_s=wall_s)
    metrics.update(_extras(setup, recorder.tracking_error_by_vehicle_m()))
    return SimReport(config=config, metrics=metrics)


def _extras(setup: SimSetup, errors_m: list[float | None]) -> dict[str, Any]:
    """Counters: rejected inputs, link traffic, and per vehicle what its tracker fused."""
    snap = setup.mission.snapshot()
    links = setup.links.stats()
    return {
        "counters": {
            "rejected_detections": snap.counters.rejected_detections,
            "rejected_messages": snap.counters.rejected_messages,
            "controller_errors": snap.counters.controller_errors,
            "braking_ticks": snap.counters.braking_ticks,
            "escape_ticks": snap.counters.escape_ticks,
            "hold_ticks": snap.counters.hold_ticks,
            "messages_sent": links.sent,
            "messages_delivered": links.delivered,
            "messages_dropped": links.dropped,
            "failsafe_holds": sum(a.failsafe_holds for a in setup.autopilots),
        },
        "vehicles": [
            {
                "vehicle_id": v.vehicle_id,
                "phase": v.phase.value,
                "tracking_error_m_mean": errors_m[i] if i < len(errors_m) else None,
                "own_detections_fused": v.counters.own_detections_fused,
                "teammate_detections_fused": v.counters.teammate_detections_fused,
                "slot_ticks": v.counters.slot_ticks,
                "hold_ticks": v.counters.hold_ticks,
            }
            for i, v in enumerate(snap.vehicles)
        ],
    }


def without_timings(report: Mapping[str, Any]) -> dict[str, Any]:
    """A report's JSON data with the wall-clock metrics removed (what determinism compares)."""
    metrics = {k: v for k, v in report["metrics"].items() if k not in TIMING_METRICS}
    return {"config": dict(report["config"]), "metrics": metrics}
