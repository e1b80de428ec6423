"""Build the embedded simulation: person, trees, simulated vehicles, cameras, links and the mission over them.

Both the deterministic runner (`server/lab/simulation.py`) and the live ground station build their simulated
team here, so the two fly the same world. Every random choice comes from one seed, split with numpy's
SeedSequence into independent streams (person, trees, links, and per vehicle: GPS drift and detector noise),
so a given seed gives the same world and the same run whatever the number of vehicles asks of the other
streams.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from controller.messages import Obstacle
from controller.params import MAX_TEAM_SIZE, ControllerParams, FormationParams, Method, ParameterError
from vehicles.agent import AgentParams
from vehicles.links import LinkParams, SimLinks
from vehicles.mission import Mission, MissionParams
from vehicles.sim.autopilot import AirframeParams, SimAutopilot
from vehicles.sim.gps_drift import DriftParams, GpsDrift
from vehicles.sim.person import PERSON_MODES, PathPerson, RandomPerson, StillPerson, paper_path
from vehicles.sim.trees import (
    PAPER_TREES_XY,
    TREE_HEIGHT_M,
    TREE_RADIUS_M,
    TreeSpec,
    paper_trees,
    random_trees,
)
from vehicles.sim.world import DetectorParams, SimWorld
from vehicles.world import PersonModel

START_LAYOUTS = ("ring", "cluster")
VIRTUAL_OBSTACLE_LAYOUTS = ("none", "paper")
START_CLEARANCE_M = 2.0  # a start spot keeps this much from any trunk surface
CLUSTER_SPACING_M = 2.5  # neighbours on the launch arc of the "cluster" layout, and any two start spots
BELIEVED_SPACING_M = 2.0  # any two start spots as their GPS sees them (the station's take-off check)


@dataclass(frozen=True)
class Scenario:
    """The simulated world and team.

    vehicles: K, 1..MAX_TEAM_SIZE; seed >= 0; method; trees: "paper", "none" or N random; person: paper |
    random | still; comm_loss in [0, 1]; latency_s: link latency (plus up to jitter_s); start: "ring" (on the
    ground at the roster slots, d_des from the person, as a crew would set them out) or "cluster" (side by
    side, 2.5 m apart, south of the person: the team has to spread out); gps_drift: simulate self-localisation
    drift; virtual_obstacles: "none" or "paper" (the paper's 13 tree positions as the operator's virtual
    obstacles: avoided like trunks but invisible to the cameras, the paper's SE4).
    """

    vehicles: int = 3
    seed: int = 0
    method: Method = Method.ACTIVE
    trees: str = "paper"
    person: str = "paper"
    comm_loss: float = 0.0
    latency_s: float = 0.03
    jitter_s: float = 0.02
    start: str = "ring"
    formation: FormationParams = field(default_factory=FormationParams)
    gps_drift: bool = True
    physics_step_s: float = 0.01
    virtual_obstacles: str = "none"

    def __post_init__(self) -> None:
        vehicles, seed = self.vehicles, self.seed
        if isinstance(vehicles, bool) or not isinstance(vehicles, int | np.integer):
            raise ParameterError("vehicles", f"must be a whole number, got {vehicles!r}")
        if not 1 <= vehicles <= MAX_TEAM_SIZE:
            raise ParameterError("vehicles", f"must be from 1 to {MAX_TEAM_SIZE}, got {vehicles}")
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            raise ParameterError("seed", f"must be a whole number >= 0, got {seed!r}")
        object.__setattr__(self, "vehicles", int(vehicles))
        object.__setattr__(self, "seed", int(seed))
        try:
            object.__setattr__(
                self, "method", Method(str(getattr(self.method, "value", self.method)).lower())
            )
        except ValueError:
            choices = ", ".join(m.value for m in Method)
            raise ParameterError("method", f"must be one of {choices}, got {self.method!r}") from None
        try:
            object.__setattr__(self, "trees", str(TreeSpec.parse(self.trees)))
        except ValueError as exc:
            raise ParameterError("trees", str(exc).removeprefix("trees ")) from None
        for name, value, choices in (
            ("person", self.person, PERSON_MODES),
            ("start", self.start, START_LAYOUTS),
            ("virtual_obstacles", self.virtual_obstacles, VIRTUAL_OBSTACLE_LAYOUTS),
        ):
            if value not in choices:
                raise ParameterError(name, f"must be one of {', '.join(choices)}, got {value!r}")
        if not (isinstance(self.comm_loss, int | float) and 0.0 <= self.comm_loss <= 1.0):
            raise ParameterError("comm_loss", f"must be a probability in [0, 1], got {self.comm_loss!r}")
        try:
            LinkParams(loss=self.comm_loss, latency_s=self.latency_s, jitter_s=self.jitter_s)
        except ValueError as exc:
            raise ParameterError("latency_s", str(exc)) from None
        if not (math.isfinite(self.physics_step_s) and 0 < self.physics_step_s <= 0.05):
            raise ParameterError("physics_step_s", f"must be in (0, 0.05], got {self.physics_step_s}")

    @property
    def tree_spec(self) -> TreeSpec:
        return TreeSpec.parse(self.trees)


@dataclass(frozen=True, eq=False)
class SimSetup:
    """A built simulation: the mission to step, and the simulated parts behind it (for truth and metrics)."""

    scenario: Scenario
    mission: Mission
    world: SimWorld
    autopilots: tuple[SimAutopilot, ...]
    links: SimLinks
    person: PersonModel


def _clearance(xy: np.ndarray, obstacles: tuple[Obstacle, ...]) -> float:
    if not obstacles:
        return math.inf
    return min(float(np.hypot(*(xy - o.center_m))) - o.radius_m for o in obstacles)


def start_positions(
    *,
    count: int,
    layout: str,
    d_des_m: float,
    person_xy_m: np.ndarray,
    obstacles: tuple[Obstacle, ...] = (),
    gps_offsets_m: np.ndarray | None = None,
) -> np.ndarray:
    """(count, 3) ground positions of the MAVs, d_des_m from the person, each turned along the circle in
    2-degree steps (alternating sides, up to 180 degrees) until it keeps START_CLEARANCE_M from every trunk
    and CLUSTER_SPACING_M from every spot already placed (a crew does not set two MAVs down side by side to
    dodge a tree; the separation guarantee starts on the ground), and BELIEVED_SPACING_M as their GPS sees
    them (gps_offsets_m (count, 3): each MAV's self-localisation offset at power-on; the crew moves a MAV
    the station's take-off check refuses); where no spot keeps all, the one that misses them by the least."""
    if layout == "ring":
        bearings = [2.0 * math.pi * k / count for k in range(count)]
    else:
        step = CLUSTER_SPACING_M / d_des_m
        bearings = [-math.pi / 2.0 + (k - (count - 1) / 2.0) * step for k in range(count)]
    offsets = np.zeros((count, 2)) if gps_offsets_m is None else np.asarray(gps_offsets_m, float)[:, :2]
    out: list[list[float]] = []
    for k, b in enumerate(bearings):
        best, best_score = None, -math.inf
        for j in range(181):
            turn = math.radians(2.0 * ((j + 1) // 2) * (1 if j % 2 else -1))
            xy = person_xy_m + d_des_m * np.array([math.cos(b + turn), math.sin(b + turn)])
            apart = min((math.hypot(xy[0] - o[0], xy[1] - o[1]) for o in out), default=math.inf)
            seen = xy + offsets[k]
            seen_apart = min(
                (math.hypot(*(seen - np.asarray(o[:2]) - offsets[j])) for j, o in enumerate(out)),
                default=math.inf,
            )
            # what the spot lacks, as a fraction of each requirement; 0: it meets all three
            score = (
                min(0.0, _clearance(xy, obstacles) / START_CLEARANCE_M - 1.0)
                + min(0.0, apart / CLUSTER_SPACING_M - 1.0)
                + min(0.0, seen_apart / BELIEVED_SPACING_M - 1.0)
            )
            if score > best_score:
                best, best_score = xy, score
            if score >= -1e-9:
                break
        assert best is not None
        out.append([best[0], best[1], 0.0])
    return np.array(out)


def fan_slot_offset_rad(starts_m: np.ndarray, person_xy_m: np.ndarray) -> float:
    """The roster's slot offset that fans a launch arc out: slot k (vehicle ids in order, as the arc is laid
    out) at the arc's mean bearing about the person + (k - (K - 1) / 2) 2 pi / K. Every MAV then moves away
    from the arc's middle, the order kept, so no two transit paths cross: what keeps a team apart that hears
    nothing of each other (with total link loss each MAV flies to its slot; docs/safety.md)."""
    rel = np.asarray(starts_m, dtype=float)[:, :2] - np.asarray(person_xy_m, dtype=float)
    angles = np.arctan2(rel[:, 1], rel[:, 0])
    mean = math.atan2(float(np.sin(angles).sum()), float(np.cos(angles).sum()))
    return mean - 0.5 * (len(angles) - 1) * 2.0 * math.pi / len(angles)


def paper_virtual_obstacles() -> tuple[Obstacle, ...]:
    """The paper's 13 tree positions as virtual obstacles (kind "virtual"), ids virtual-1..virtual-13."""
    return tuple(
        Obstacle(
            obstacle_id=f"virtual-{i + 1}",
            center_m=np.array(xy),
            radius_m=TREE_RADIUS_M,
            height_m=TREE_HEIGHT_M,
            kind="virtual",
        )
        for i, xy in enumerate(PAPER_TREES_XY)
    )


class SeedStreams(NamedTuple):
    """Independent random streams split from one seed (numpy SeedSequence), one per part of the world."""

    person: np.random.SeedSequence
    trees: np.random.SeedSequence
    links: np.random.SeedSequence
    vehicles: np.random.SeedSequence

    @classmethod
    def from_seed(cls, seed: int) -> SeedStreams:
        return cls(*np.random.SeedSequence(seed).spawn(4))

    def vehicle_rngs(self, count: int) -> list[tuple[np.random.Generator, np.random.Generator]]:
        """(GPS drift, detector noise) generators of vehicles 1..count, in order."""
        out = []
        for vss in self.vehicles.spawn(count):
            drift_ss, detector_ss = vss.spawn(2)
            out.append((np.random.default_rng(drift_ss), np.random.default_rng(detector_ss)))
        return out


def make_person(mode: str, streams: SeedStreams) -> PersonModel:
    """The person model by name (PERSON_MODES); ValueError for another name."""
    if mode not in PERSON_MODES:
        raise ValueError(f"person must be one of {', '.join(PERSON_MODES)}, got {mode!r}")
    if mode == "paper":
        return PathPerson(path_xy_m=paper_path())
    if mode == "random":
        return RandomPerson(np.random.default_rng(streams.person))
    return StillPerson()


def make_trees(
    spec: TreeSpec, streams: SeedStreams, *, person: PersonModel, starts_xy_m: Sequence[np.ndarray]
) -> tuple[Obstacle, ...]:
    """The trunks of `spec`: the paper's 13, none, or N random ones kept 3 m clear of the person's start,
    of every vehicle's start and of the person's scripted path."""
    if spec.kind == "paper":
        return paper_trees()
    if spec.kind == "none":
        return ()
    person_xy = np.asarray(person.truth(0.0).position_m[:2])
    keep = [(person_xy, 3.0)] + [(np.asarray(s, dtype=float)[:2], 3.0) for s in starts_xy_m]
    return random_trees(
        np.random.default_rng(streams.trees),
        count=spec.count,
        keep_clear=keep,
        keep_clear_path_xy_m=person.path_xy_m if isinstance(person, PathPerson) else None,
    )


def build_sim(
    scenario: Scenario,
    *,
    controller_params: ControllerParams | None = None,
    mission_params: MissionParams | None = None,
    agent_params: AgentParams | None = None,
    airframe: AirframeParams | None = None,
    detector: DetectorParams | None = None,
    clock: Callable[[], float] | None = None,
) -> SimSetup:
    """Build the world and the mission for `scenario`. controller_params defaults to the method's defaults;
    mission_params to the defaults, with a clustered start's slots fanned out from its arc
    (`fan_slot_offset_rad`); clock (e.g. time.perf_counter) is only used to time agent ticks."""
    cparams = controller_params or ControllerParams(method=scenario.method)
    if cparams.method != scenario.method:
        raise ValueError(
            f"controller_params.method {cparams.method.value} differs from the scenario's "
            f"{scenario.method.value}"
        )
    streams = SeedStreams.from_seed(scenario.seed)
    person = make_person(scenario.person, streams)
    person_xy = np.asarray(person.truth(0.0).position_m[:2])
    spec = scenario.tree_spec
    virtual = paper_virtual_obstacles() if scenario.virtual_obstacles == "paper" else ()
    # Paper trees stand first and the starts avoid them; random trees are placed round the starts.
    fixed = paper_trees() if spec.kind == "paper" else ()
    drift_params = DriftParams(enabled=scenario.gps_drift)
    vehicle_rngs = streams.vehicle_rngs(scenario.vehicles)
    drifts = [GpsDrift(drift_rng, drift_params) for drift_rng, _ in vehicle_rngs]
    starts = start_positions(
        count=scenario.vehicles,
        layout=scenario.start,
        d_des_m=scenario.formation.d_des_m,
        person_xy_m=person_xy,
        obstacles=fixed + virtual,
        gps_offsets_m=np.array([d.offset_m for d in drifts]),
    )
    trees = make_trees(spec, streams, person=person, starts_xy_m=list(starts))
    ids = list(range(1, scenario.vehicles + 1))
    autopilots, rngs = [], {}
    for vid, start, drift, (_, detector_rng) in zip(ids, starts, drifts, vehicle_rngs, strict=True):
        to_person = person_xy - start[:2]
        autopilots.append(
            SimAutopilot(
                vehicle_id=vid,
                start_position_m=start,
                start_yaw_rad=math.atan2(to_person[1], to_person[0]),
                drift=drift,
                params=airframe or AirframeParams(),
            )
        )
        rngs[vid] = detector_rng
    world = SimWorld(
        person=person,
        obstacles=trees,
        bodies=autopilots,
        rngs=rngs,
        detector=detector or DetectorParams(),
        physics_step_s=scenario.physics_step_s,
    )
    links = SimLinks(
        vehicle_ids=ids,
        rng=np.random.default_rng(streams.links),
        params=LinkParams(loss=scenario.comm_loss, latency_s=scenario.latency_s, jitter_s=scenario.jitter_s),
    )
    if mission_params is None and scenario.start == "cluster":
        mission_params = MissionParams(slot_offset_rad=fan_slot_offset_rad(starts, person_xy))
    mission = Mission(
        autopilots=autopilots,
        world=world,
        links=links,
        controller_params=cparams,
        formation=scenario.formation,
        params=mission_params,
        agent_params=agent_params,
        clock=clock,
        virtual_obstacles=virtual,
    )
    return SimSetup(
        scenario=scenario,
        mission=mission,
        world=world,
        autopilots=tuple(autopilots),
        links=links,
        person=person,
    )
