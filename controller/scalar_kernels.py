"""Scalar forms of numpy's elementwise `minimum` and `maximum`, and of eq. 15's age term, for compiled kernels
that replace numpy code and must give its bits (teammates.fresh_paths, separation_kernel.row_inflation).

numpy's minimum and maximum keep a NaN and, on a tie, return their second operand (which decides the sign
of a zero); Python's and numba's `min` and `max` do neither. Inlined into their callers (`inline="always"`).
"""

from __future__ import annotations

import numba


@numba.njit(cache=True, inline="always")
def minimum(a: float, b: float) -> float:  # pragma: no cover - compiled; tested through its callers
    """np.minimum(a, b) on two floats: a NaN a stays, a tie gives b."""
    return a if (a < b or a != a) else b


@numba.njit(cache=True, inline="always")
def maximum(a: float, b: float) -> float:  # pragma: no cover - compiled; tested through its callers
    """np.maximum(a, b) on two floats: a NaN a stays, a tie gives b."""
    return a if (a > b or a != a) else b


@numba.njit(cache=True, inline="always")
def age_term_m(age_s: float, speed_mps: float, grace_s: float) -> float:  # pragma: no cover - compiled
    """Eq. 15's r_comm of one plan age_s old (m): fields.teammate_age_term_m's
    speed * max(age - grace, 0), in its order."""
    return speed_mps * maximum(age_s - grace_s, 0.0)
