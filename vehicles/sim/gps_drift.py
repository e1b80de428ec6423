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

from dataclasses import dataclass

import numpy as np


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
    """One MAV's drifting offset. `advance_to(t_s)` moves it forward in fixed steps; `offset_m` (3,) and
    `velocity_mps` (3,) are the current values (zeros when disabled)."""

    def __init__(self, rng: np.random.Generator, params: DriftParams = DriftParams()) -> None:
        self._rng = rng
        self._p = params
        self._std = np.asarray(params.initial_std_m, dtype=float)
        self._noise = np.asarray(params.accel_noise, dtype=float)
        if params.enabled:
            self._offset = rng.normal(0.0, 1.0, size=3) * self._std
            self._target = rng.normal(0.0, 1.0, size=3) * self._std
        else:
            self._offset = np.zeros(3)
            self._target = np.zeros(3)
        self._velocity = np.zeros(3)
        self._t = 0.0
        self._leg_end = params.leg_s

    @property
    def offset_m(self) -> np.ndarray:
        return self._offset

    @property
    def velocity_mps(self) -> np.ndarray:
        return self._velocity

    def advance_to(self, t_s: float) -> None:
        """Step the drift to t_s (no-op for times already passed)."""
        p = self._p
        if not p.enabled:
            self._t = max(self._t, t_s)
            return
        dt = p.step_s
        while self._t + dt <= t_s + 1e-9:
            self._t += dt
            if self._t >= self._leg_end:
                self._target = self._rng.normal(0.0, 1.0, size=3) * self._std
                self._leg_end += p.leg_s
            wanted = (self._target - self._offset) / (0.5 * p.leg_s)
            self._velocity = (
                self._velocity
                + (wanted - self._velocity) * (dt / p.relax_s)
                + self._noise * np.sqrt(dt) * self._rng.normal(0.0, 1.0, size=3)
            )
            self._offset = self._offset + self._velocity * dt
