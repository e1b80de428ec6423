"""A teammate gone silent: where the others must assume it is.

When a vehicle's telemetry stops (`AutopilotState.link_lost`), nothing computed for it reaches it any more and
its autopilot's own failsafe flies it (PX4 with skyring's parameters: it keeps its last set-point for
COM_OF_LOSS_T, holds, then lands). Its teammates stop counting it in the formation and avoid it as an
obstacle: a vertical cylinder around its last reported position and its last horizon plan, whose radius grows
with the time it has been silent (the uncertainty of where it is), up to a bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller.messages import HorizonPlan, Obstacle
from vehicles.autopilot import AutopilotState


@dataclass(frozen=True)
class SilentVehicleParams:
    """body_radius_m: the vehicle itself; drift_mps: how fast the uncertainty of its position grows while it
    is silent (a holding or landing multirotor drifts slowly; wind and a failsafe's braking distance are in
    it); max_radius_m: the bound on that growth; headroom_m: the cylinder reaches this far above the highest
    point it may be at."""

    body_radius_m: float = 0.5
    drift_mps: float = 0.5
    max_radius_m: float = 6.0
    headroom_m: float = 2.0

    def __post_init__(self) -> None:
        values = (self.body_radius_m, self.drift_mps, self.max_radius_m, self.headroom_m)
        if not all(math.isfinite(v) and v >= 0 for v in values) or self.body_radius_m <= 0:
            raise ValueError(f"silent-vehicle parameters must be finite and non-negative, got {values}")


def silent_vehicle_obstacle(
    *,
    state: AutopilotState,
    plan: HorizonPlan | None,
    now_s: float,
    params: SilentVehicleParams = SilentVehicleParams(),
) -> Obstacle:
    """The cylinder teammates avoid around a silent vehicle, id "silent-<vehicle id>", kind "vehicle".

    Centre and spread: the smallest axis-aligned box around the last reported position and the last plan's
    positions (M, 3), radius to its farthest point; plus body_radius_m and drift_mps times the silence
    (now_s - state.stamp_s), the growth bounded by max_radius_m.
    """
    return _silent_obstacle(
        vehicle_id=state.vehicle_id,
        position_m=state.position_m,
        stamp_s=state.stamp_s,
        plan=plan,
        now_s=now_s,
        params=params,
    )


def silent_teammate_obstacle(
    *, plan: HorizonPlan, now_s: float, params: SilentVehicleParams = SilentVehicleParams()
) -> Obstacle:
    """The same cylinder for a teammate known only by its last plan (an onboard agent that stopped hearing
    it): its last known position is the plan's x(0) at the plan's stamp."""
    return _silent_obstacle(
        vehicle_id=plan.vehicle_id,
        position_m=plan.positions_m[0],
        stamp_s=plan.stamp_s,
        plan=plan,
        now_s=now_s,
        params=params,
    )


def _silent_obstacle(
    *,
    vehicle_id: int,
    position_m: np.ndarray,
    stamp_s: float,
    plan: HorizonPlan | None,
    now_s: float,
    params: SilentVehicleParams,
) -> Obstacle:
    points = np.asarray(position_m, dtype=float)[None, :]
    if plan is not None and np.all(np.isfinite(plan.positions_m)):
        points = np.vstack([points, plan.positions_m])
    xy = points[:, :2]
    center = 0.5 * (xy.min(axis=0) + xy.max(axis=0))
    spread = float(np.max(np.linalg.norm(xy - center, axis=1)))
    silence = max(0.0, now_s - stamp_s)
    growth = min(params.drift_mps * silence, params.max_radius_m)
    height = max(float(points[:, 2].max()), 0.0) + params.headroom_m
    return Obstacle(
        obstacle_id=f"silent-{vehicle_id}",
        center_m=center,
        radius_m=params.body_radius_m + spread + growth,
        height_m=height,
        kind="vehicle",
    )
