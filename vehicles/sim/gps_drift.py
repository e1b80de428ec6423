"""GPS random-walk drift of a MAV's self-localisation: reported position = true position + offset(t).

docs/method.md#simulated-world: an initial offset with std (0.5, 0.5, 1) m that drifts towards a new random
target every 240 s leg, disturbed by white acceleration noise with std (0.005, 0.005, 0.01). skyring's
reading: the offset's velocity relaxes (time constant `relax_s`) towards (target - offset) / (leg_s / 2), so
the offset heads for each leg's target exponentially and never rushes at a leg's end; the noise is white
acceleration noise of that spectral density (m/s^2 per sqrt(Hz)). The offset stays of the order of the initial
std and changes smoothly (mm/s to cm/s), as GPS drift does: the noise alone moves it by about sigma * relax_s
* sqrt(leg_s) = 0.15 m (x, y) over a leg.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller.messages import read_only

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class DriftParams:
    """initial_std_m (x, y, z) also draws each leg's target; leg_s; accel_noise (x, y, z) m/s^2/sqrt(Hz);
    relax_s the velocity's relaxation time; step_s the update step (drift is slow, 0.1 s is ample)."""

    initial_std_m: tuple[float, float, float] = (0.5, 0.5, 1.0)
    leg_s: float = 240.0
    accel_noise: tuple[float, float, float] = (0.005, 0.005, 0.01)
    relax_s: float = 2.0
    step_s: float = 0.1
    enabled: bool = True


class GpsDrift:
    """One MAV's drifting offset. `advance_to(t_s)` moves it forward in fixed steps; `offset` and `velocity`
    are the current values as three floats, `offset_m` (3,) and `velocity_mps` (3,) as read-only arrays
    (zeros when disabled).

    The state is plain floats: the vehicle reads it every physics step, and numpy's per-call cost on three
    numbers was most of the work. Each component takes the operations numpy's elementwise ones took, in the
    same order, so the values are the same to the bit.
    """

    def __init__(self, rng: np.random.Generator, params: DriftParams = DriftParams()) -> None:
        self._rng = rng
        self._p = params
        sx, sy, sz = params.initial_std_m
        self._std = (float(sx), float(sy), float(sz))
        root_dt = math.sqrt(params.step_s)  # correctly rounded, as numpy's square root
        nx, ny, nz = params.accel_noise
        self._noise = (float(nx) * root_dt, float(ny) * root_dt, float(nz) * root_dt)
        zeros = (0.0, 0.0, 0.0)
        self._offset = self._draw() if params.enabled else zeros
        self._target = self._draw() if params.enabled else zeros
        self._velocity = zeros
        self._arrays: tuple[np.ndarray, np.ndarray] | None = None
        self._t = 0.0
        self._next_t = self._t + params.step_s
        self._leg_end = params.leg_s

    @property
    def offset(self) -> Vec3:
        return self._offset

    @property
    def velocity(self) -> Vec3:
        return self._velocity

    @property
    def offset_m(self) -> np.ndarray:
        return self._read_only()[0]

    @property
    def velocity_mps(self) -> np.ndarray:
        return self._read_only()[1]

    def advance_to(self, t_s: float) -> None:
        """Step the drift to t_s (no-op for times already passed)."""
        p = self._p
        if not p.enabled or self._next_t > t_s + 1e-9:  # asked every physics step, it moves every tenth
            return
        dt = p.step_s
        gain, half_leg_s = dt / p.relax_s, 0.5 * p.leg_s
        nx, ny, nz = self._noise
        while self._t + dt <= t_s + 1e-9:
            self._t += dt
            if self._t >= self._leg_end:
                self._target = self._draw()
                self._leg_end += p.leg_s
            (tx, ty, tz), (ox, oy, oz), (vx, vy, vz) = self._target, self._offset, self._velocity
            wx, wy, wz = (tx - ox) / half_leg_s, (ty - oy) / half_leg_s, (tz - oz) / half_leg_s
            ex, ey, ez = self._rng.normal(0.0, 1.0, size=3).tolist()
            vx = vx + (wx - vx) * gain + nx * ex
            vy = vy + (wy - vy) * gain + ny * ey
            vz = vz + (wz - vz) * gain + nz * ez
            self._velocity = (vx, vy, vz)
            self._offset = (ox + vx * dt, oy + vy * dt, oz + vz * dt)
        self._next_t = self._t + dt
        self._arrays = None

    def _draw(self) -> Vec3:
        """The initial offset or a leg's target: standard normals scaled by initial_std_m."""
        ex, ey, ez = self._rng.normal(0.0, 1.0, size=3).tolist()
        sx, sy, sz = self._std
        return ex * sx, ey * sy, ez * sz

    def _read_only(self) -> tuple[np.ndarray, np.ndarray]:
        """Offset and velocity as read-only arrays, made once per drift step: messages and poses take them
        as they are, without a copy."""
        if self._arrays is None:
            self._arrays = read_only(np.array(self._offset)), read_only(np.array(self._velocity))
        return self._arrays
