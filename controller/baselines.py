"""The `price` baseline's potential field (Price et al., RA-L 2018), applied after the MPC.

Price et al. (docs/method.md#baselines) steer each MAV with an MPC to the point on the d_des circle (zero
terminal velocity, terminal weight 1000, input weight 0.1, no external inputs) and then correct its way-point
with a
potential field: repulsion from the teammates' current positions and attraction to that goal point. They share
no horizon plans: a `price` MAV uses only x(0) of each received plan, the teammate's position when it planned
(the plan is still published, for the ground station's display). There is no angular-spacing term. skyring's
field also repels from trees and virtual obstacles (surface distance, the same thresholds as eq. 13): without
it the baseline flew through the paper's trees, which says nothing about formation control.

The field f (m/s^2, horizontal) is computed at the MAV's start position and then added to the MPC's inputs
over the whole horizon (the plan is rolled out again with it, `mpc.predict`): the way-point, the published
plan and the next tick's reference state all include it, so its effect accumulates from tick to tick as a
field's should.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.fields import FieldParams, ObstacleSet, clamp_norm, cotangential_magnitude, peak_gain


@dataclass(frozen=True)
class PriceParams:
    """The `price` baseline's weights and post-MPC field.

    input_weight, terminal_weight: its MPC's W_E and terminal position/velocity weights.
    attraction_gain_per_s2: goal attraction k (m/s^2 per m of distance to the goal point), clamped at
        attraction_max_mps2. Teammate and obstacle repulsion use FieldParams' thresholds and peaks.
    """

    input_weight: float = 0.1
    terminal_weight: float = 1000.0
    attraction_gain_per_s2: float = 0.5
    attraction_max_mps2: float = 1.0

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"PriceParams.{name} must be a finite number >= 0, got {value}")
        if self.input_weight <= 0.0:
            raise ValueError("PriceParams.input_weight must be > 0")


def _repulsion(
    diff: np.ndarray, dist: np.ndarray, *, d_min: float, d_max, peak: float, fields: FieldParams
) -> np.ndarray:
    """(2,) sum of cotangential repulsions F(dist) (J,) along diff (J, 2)."""
    gain = peak_gain(peak, d_min=d_min, d_max=d_max, freeze_fraction=fields.freeze_fraction)
    mag = np.asarray(
        cotangential_magnitude(
            dist, d_min=d_min, d_max=d_max, gain=gain, freeze_fraction=fields.freeze_fraction
        )
    )
    norm = np.sqrt(np.einsum("ji,ji->j", diff, diff))
    return (mag[:, None] * diff / np.where(norm > 1e-9, norm, np.inf)[:, None]).sum(axis=0)


def price_field(
    *,
    own_position_m: np.ndarray,
    goal_position_m: np.ndarray,
    teammate_positions_m: np.ndarray,
    teammate_d_max_m: np.ndarray,
    obstacles: ObstacleSet,
    fields: FieldParams,
    params: PriceParams,
) -> np.ndarray:
    """(3,) the post-MPC field: repulsion from teammates and obstacles (cotangential, horizontal) plus goal
    attraction, clamped to fields.f_max_mps2.

    teammate_positions_m: (J, 3) current positions; teammate_d_max_m: (J,) repulsion d_max of each (eq. 15).
    """
    own_xy = own_position_m[:2]
    force = np.zeros(2)
    if len(teammate_positions_m):
        diff = own_xy[None, :] - teammate_positions_m[:, :2]
        d_min = fields.teammate_d_min_m
        force += _repulsion(
            diff,
            np.sqrt(np.einsum("ji,ji->j", diff, diff)),
            d_min=d_min,
            d_max=np.maximum(teammate_d_max_m, d_min + 1e-3),
            peak=fields.teammate_peak_mps2,
            fields=fields,
        )
    if obstacles.count:
        diff = own_xy[None, :] - obstacles.centers_m
        surface = np.sqrt(np.einsum("ji,ji->j", diff, diff)) - obstacles.radii_m
        below = own_position_m[2] < obstacles.heights_m + fields.obstacle_d_min_m
        force += _repulsion(
            diff[below],
            surface[below],
            d_min=fields.obstacle_d_min_m,
            d_max=fields.obstacle_d_max_m,
            peak=fields.obstacle_peak_mps2,
            fields=fields,
        )
    pull = params.attraction_gain_per_s2 * (goal_position_m[:2] - own_xy)
    force += clamp_norm(pull, params.attraction_max_mps2)
    force = clamp_norm(force, fields.f_max_mps2)
    return np.array([force[0], force[1], 0.0])
