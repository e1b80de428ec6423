"""Angles: the one rule for wrapping them, used wherever a bearing or yaw difference is formed."""

from __future__ import annotations

import math
from typing import overload

import numpy as np

TWO_PI = 2.0 * math.pi


@overload
def wrap_angle(angle_rad: float) -> float: ...
@overload
def wrap_angle(angle_rad: np.ndarray) -> np.ndarray: ...
def wrap_angle(angle_rad: float | np.ndarray) -> float | np.ndarray:
    """The angle (radians) wrapped into [-pi, pi); elementwise for an array, a float for a float."""
    if isinstance(angle_rad, np.ndarray):
        return (angle_rad + np.pi) % TWO_PI - np.pi
    return (float(angle_rad) + math.pi) % TWO_PI - math.pi
