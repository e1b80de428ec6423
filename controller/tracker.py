"""The cooperative person tracker (paper Sec. III-B): a Kalman filter replica per MAV.

TODO(helper tracker): implement.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TrackerParams:
    """Motion model, gating and reset of the person tracker (METHOD.md "Person tracker")."""

    gate_sigma: float = 6.0
    reset_after_s: float = 10.0
