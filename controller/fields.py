"""Potential fields: the cotangential magnitude function and every external input f(n) (paper Sec. III-E).

TODO(helper fields): implement.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class FieldParams:
    """Gains and thresholds of the external inputs (METHOD.md "The external inputs"). Distances in m, angles
    in rad, forces in m/s^2 (they enter the dynamics as accelerations)."""

    gain: float = 50.0
    f_max_mps2: float = 8.0
