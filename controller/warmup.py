"""Compile (first start) or load (later starts) every compiled kernel of the controller before a real-time
loop needs it.

The kernels (numba, `cache=True`) compile on their first call and are cached on disk beside their modules; a
fresh install compiles them once (about 28 s of CPU, docs/fast-core.md), later starts load them in about
1.5 s. A live ground station calls `warm_up()` before its first control tick, so that tick is not the one
that pays.
"""

from __future__ import annotations

import numpy as np

from controller.formation import FormationController
from controller.messages import Detection, HorizonPlan, Obstacle, PersonEstimate, VehicleState
from controller.mpc import ModelPredictiveController
from controller.params import ControllerParams, FormationParams
from controller.qp import ExactQp
from controller.teammates import TeammateTable
from controller.tracker import PersonTracker


def warm_up(params: ControllerParams | None = None) -> None:
    """One tracker update and estimate, formation-controller steps with a teammate's plan from the plan table
    and an obstacle within reach (one with a phantom teammate as well), an MPC solve with an active bound
    (the active-set path), and a QP whose coupling rows need the compiled active-set step, so every kernel
    on the tick's path has run once."""
    params = params or ControllerParams()
    tracker = PersonTracker(params.tracker)
    for stamp in (0.0, 0.02):  # the second predicts (the transition kernel) before it updates
        tracker.update(Detection(source_id=2, stamp_s=stamp, position_m=np.zeros(3), cov_m2=np.eye(3)))
    person = tracker.estimate(0.05) or PersonEstimate(
        stamp_s=0.05, position_m=np.zeros(3), velocity_mps=np.zeros(3), cov=np.eye(6)
    )
    steps = params.mpc.horizon_steps + 2
    table = TeammateTable(own_id=1, plan_length=steps)
    table.update(
        HorizonPlan(
            vehicle_id=2,
            stamp_s=0.0,
            dt_s=params.mpc.dt_s,
            positions_m=np.tile([7.0, 2.0, 8.0], (steps, 1)),
            velocities_mps=np.zeros((steps, 3)),
        )
    )
    controller = FormationController(vehicle_id=1, params=params)
    own = VehicleState(
        vehicle_id=1, stamp_s=0.05, position_m=np.array([8.0, 0.0, 8.0]), velocity_mps=np.zeros(3)
    )
    trunk = Obstacle(obstacle_id="warm-up", center_m=np.array([9.0, -1.5]), radius_m=0.3)
    phantom = HorizonPlan(
        vehicle_id=3,
        stamp_s=0.0,
        dt_s=params.mpc.dt_s,
        positions_m=np.tile([9.0, -2.0, 8.0], (steps, 1)),
        velocities_mps=np.zeros((steps, 3)),
    )
    # formation flight in one call (tick_kernel.py), then the wrappers' kernels, which a tick with a phantom
    # teammate (a stand-in for one not heard) calls one by one
    for now, extra in ((0.05, ()), (0.06, ()), (0.07, (phantom,))):
        controller.step(
            now_s=now,
            own=own,
            person=person,
            teammates=table.view(-1.0, extra),
            obstacles=(trunk,),
            formation=FormationParams(),
        )
    constrained = ModelPredictiveController(params.mpc)
    constrained.solve(
        position_m=np.array([0.0, 0.0, 6.0]),
        velocity_mps=np.zeros(3),
        target_position_m=np.array([60.0, 0.0, 6.0]),
        target_velocity_mps=np.zeros(3),
        external_inputs_mps2=np.zeros((steps - 1, 3)),
    )
    # min |x - (10, 10)|^2 / 2 with y <= 0 and x - y <= 5 as coupling rows: step 3, by the compiled solver
    ExactQp(np.eye(2), np.eye(2), np.zeros(2, dtype=bool), active_set="compiled").solve(
        np.array([-10.0, -10.0]),
        np.full(2, -100.0),
        np.full(2, 100.0),
        np.array([[0.0, 1.0], [1.0, -1.0]]),
        np.full(2, -np.inf),
        np.array([0.0, 5.0]),
    )
