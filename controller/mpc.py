"""The convex MPC of one MAV (paper Sec. III-D, eqs. 9-11), solved with OSQP.

TODO(helper mpc): implement `ModelPredictiveController`.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class MpcParams:
    """MPC horizon, bounds and weights (METHOD.md "The MPC"). ENU, z up.

    horizon_steps: N (inputs u(0..N), states x(1..N+1)); dt_s: step length.
    Bounds are per axis (x, y, z). input_*_mps2 bound the commanded acceleration u *before* gravity is added
    (hover is u_z = gravity_mps2). Position and velocity bounds are soft (slack with an exact penalty).
    effort: what the input-effort term penalises: "hover" = u + g (skyring's default, hover costs nothing),
    "planned" = u + f + g (the authors' code), "raw" = u (the paper as written).
    """

    horizon_steps: int = 15
    dt_s: float = 0.1
    position_min_m: tuple[float, float, float] = (-20.0, -20.0, 3.0)
    position_max_m: tuple[float, float, float] = (20.0, 20.0, 10.0)
    velocity_min_mps: tuple[float, float, float] = (-5.0, -5.0, -0.5)
    velocity_max_mps: tuple[float, float, float] = (5.0, 5.0, 0.5)
    input_min_mps2: tuple[float, float, float] = (-3.0, -3.0, 3.0)
    input_max_mps2: tuple[float, float, float] = (3.0, 3.0, 11.0)
    gravity_mps2: float = 9.81
    input_weight: float = 10.0
    terminal_position_weight: float = 100.0
    terminal_velocity_weight: float = 100.0
    effort: str = "hover"
    slack_weight: float = 1.0e4
