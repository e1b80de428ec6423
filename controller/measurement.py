"""The detection measurement model (paper eqs. 1-2): spherical camera noise as a Cartesian covariance.

TODO(helper tracker): implement.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class NoiseParams:
    """Detection noise in spherical coordinates about the camera (METHOD.md "Measurement model").

    sigma_r^2 = (range_sigma_fraction * r)^2, i.e. C1 = range_sigma_fraction^2; bearing (azimuth) and
    inclination standard deviations are constant, in radians.
    """

    range_sigma_fraction: float = 0.10
    bearing_sigma_rad: float = float(np.deg2rad(1.0))
    inclination_sigma_rad: float = float(np.deg2rad(1.0))
