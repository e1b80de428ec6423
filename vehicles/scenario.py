"""Build the embedded simulation: person, trees, simulated vehicles, cameras, links and the mission over them.

Both the deterministic runner (`server/simulation.py`) and the live ground station build their simulated team
here, so the two fly the same world. Every random choice comes from one seed, split with numpy's SeedSequence
into independent streams (person, trees, links, and per vehicle: GPS drift and detector noise), so a given
seed gives the same world and the same run whatever the number of vehicles asks of the other streams.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from controller.messages import Obstacle
from controller.params import ControllerParams, FormationParams, Method
from vehicles.agent import AgentParams
from vehicles.gps_drift import DriftParams, GpsDrift
from vehicles.links import LinkParams, SimLinks
from vehicles.mission import Mission, MissionParams
from vehicles.person import PERSON_MODES, PathPerson, PersonModel, RandomPerson, StillPerson, paper_path
from vehicles.sim_autopilot import AirframeParams, SimAutopilot
from vehicles.trees import PAPER_TREES_XY, TREE_HEIGHT_M, TREE_RADIUS_M, TreeSpec, paper_trees, random_trees
from vehicles.world import DetectorParams, SimWorld

START_LAYOUTS = ("ring", "cluster")
VIRTUAL_OBSTACLE_LAYOUTS = ("none", "paper")
START_CLEARANCE_M = 2.0  # a start spot keeps this much from any trunk surface
CLUSTER_SPACING_M = 2.5  # neighbours on the launch arc of the "cluster" layout


@dataclass(frozen=True)
class Scenario:
    """The simulated world and team.

    vehicles: K >= 1; seed; method; trees: "paper", "none" or N random; person: paper | random | still;
    comm_loss in [0, 1]; latency_s: link latency (plus up to jitter_s); start: "ring" (on the ground at the
    roster slots, d_des from the person, as a crew would set them out) or "cluster" (side by side, 2.5 m
    apart, south of the person: the team has to spread out); gps_drift: simulate self-localisation drift;
    virtual_obstacles: "none" or "paper" (the paper's 13 tree positions as the operator's virtual obstacles:
    avoided like trunks but invisible to the cameras, the paper's SE4).
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
        if not (isinstance(self.vehicles, int) and 1 <= self.vehicles <= 64):
            raise ValueError(f"vehicles must be an integer from 1 to 64, got {self.vehicles!r}")
        if not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {self.seed!r}")
        object.__setattr__(self, "method", Method(self.method))
        TreeSpec.parse(self.trees)
        if self.person not in PERSON_MODES:
            raise ValueError(f"person must be one of {', '.join(PERSON_MODES)}, got {self.person!r}")
        if self.start not in START_LAYOUTS:
            raise ValueError(f"start must be one of {', '.join(START_LAYOUTS)}, got {self.start!r}")
        if self.virtual_obstacles not in VIRTUAL_OBSTACLE_LAYOUTS:
            raise ValueError(f"virtual_obstacles must be one of {', '.join(VIRTUAL_OBSTACLE_LAYOUTS)}, "
                             f"got {self.virtual_obstacles!r}")
        LinkParams(loss=self.comm_loss, latency_s=self.latency_s, jitter_s=self.jitter_s)
        if not (math.isfinite(self.physics_step_s) and 0 < self.physics_step_s <= 0.05):
            raise ValueError(f"physics_step_s must be in (0, 0.05], got {self.physics_step_s}")

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


def start_positions(*, count: int, layout: str, d_des_m: float, person_xy_m: np.ndarray,
                    obstacles: tuple[Obstacle, ...] = ()) -> np.ndarray:
    """(count, 3) ground positions of the MAVs, d_des_m from the person, each turned along the circle in
    2-degree steps (alternating sides, up to 40 degrees) until it keeps START_CLEARANCE_M from every trunk."""
    if layout == "ring":
        bearings = [2.0 * math.pi * k / count for k in range(count)]
    else:
        step = CLUSTER_SPACING_M / d_des_m
        bearings = [-math.pi / 2.0 + (k - (count - 1) / 2.0) * step for k in range(count)]
    out = []
    for b in bearings:
        for j in range(41):
            turn = math.radians(2.0 * ((j + 1) // 2) * (1 if j % 2 else -1))
            xy = person_xy_m + d_des_m * np.array([math.cos(b + turn), math.sin(b + turn)])
            if _clearance(xy, obstacles) >= START_CLEARANCE_M:
                break
        out.append([xy[0], xy[1], 0.0])
    return np.array(out)


def paper_virtual_obstacles() -> tuple[Obstacle, ...]:
    """The paper's 13 tree positions as virtual obstacles (kind "virtual"), ids virtual-1..virtual-13."""
    return tuple(Obstacle(obstacle_id=f"virtual-{i + 1}", center_m=xy, radius_m=TREE_RADIUS_M,
                          height_m=TREE_HEIGHT_M, kind="virtual") for i, xy in enumerate(PAPER_TREES_XY))


def _person(mode: str, rng: np.random.Generator) -> PersonModel:
    if mode == "paper":
        return PathPerson(path_xy_m=paper_path())
    if mode == "random":
        return RandomPerson(rng)
    return StillPerson()


def build_sim(scenario: Scenario, *, controller_params: ControllerParams | None = None,
              mission_params: MissionParams | None = None, agent_params: AgentParams | None = None,
              airframe: AirframeParams | None = None, detector: DetectorParams | None = None,
              clock: Callable[[], float] | None = None) -> SimSetup:
    """Build the world and the mission for `scenario`. controller_params defaults to the method's defaults;
    clock (e.g. time.perf_counter) is only used to time agent ticks."""
    cparams = controller_params or ControllerParams(method=scenario.method)
    if cparams.method != scenario.method:
        raise ValueError(f"controller_params.method {cparams.method.value} differs from the scenario's "
                         f"{scenario.method.value}")
    root = np.random.SeedSequence(scenario.seed)
    person_ss, trees_ss, links_ss, vehicles_ss = root.spawn(4)
    person = _person(scenario.person, np.random.default_rng(person_ss))
    person_xy = np.asarray(person.truth(0.0).position_m[:2])
    d_des = scenario.formation.d_des_m
    spec = scenario.tree_spec
    virtual = paper_virtual_obstacles() if scenario.virtual_obstacles == "paper" else ()
    if spec.kind == "paper":
        trees = paper_trees()
        starts = start_positions(count=scenario.vehicles, layout=scenario.start, d_des_m=d_des,
                                 person_xy_m=person_xy, obstacles=trees + virtual)
    else:
        starts = start_positions(count=scenario.vehicles, layout=scenario.start, d_des_m=d_des,
                                 person_xy_m=person_xy, obstacles=virtual)
        keep = [(person_xy, 3.0)] + [(s[:2], 3.0) for s in starts]
        trees = () if spec.kind == "none" else random_trees(
            np.random.default_rng(trees_ss), count=spec.count, keep_clear=keep,
            keep_clear_path_xy_m=person.path_xy_m if isinstance(person, PathPerson) else None)
    ids = list(range(1, scenario.vehicles + 1))
    autopilots, rngs = [], {}
    drift_params = DriftParams(enabled=scenario.gps_drift)
    for vid, start, vss in zip(ids, starts, vehicles_ss.spawn(scenario.vehicles), strict=True):
        drift_ss, detector_ss = vss.spawn(2)
        to_person = person_xy - start[:2]
        autopilots.append(SimAutopilot(
            vehicle_id=vid, start_position_m=start, start_yaw_rad=math.atan2(to_person[1], to_person[0]),
            drift=GpsDrift(np.random.default_rng(drift_ss), drift_params),
            params=airframe or AirframeParams()))
        rngs[vid] = np.random.default_rng(detector_ss)
    world = SimWorld(person=person, obstacles=trees, bodies=autopilots, rngs=rngs,
                     detector=detector or DetectorParams(), physics_step_s=scenario.physics_step_s)
    links = SimLinks(vehicle_ids=ids, rng=np.random.default_rng(links_ss), params=LinkParams(
        loss=scenario.comm_loss, latency_s=scenario.latency_s, jitter_s=scenario.jitter_s))
    mission = Mission(autopilots=autopilots, world=world, links=links, controller_params=cparams,
                      formation=scenario.formation, params=mission_params, agent_params=agent_params,
                      clock=clock, virtual_obstacles=virtual)
    return SimSetup(scenario=scenario, mission=mission, world=world, autopilots=tuple(autopilots),
                    links=links, person=person)
