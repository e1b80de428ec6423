"""The one angle-wrapping rule (controller/angles.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller.angles import wrap_angle


def test_wrap_angle_lands_in_half_open_interval():
    assert wrap_angle(math.pi) == pytest.approx(-math.pi)
    assert wrap_angle(3 * math.pi + 0.25) == pytest.approx(-math.pi + 0.25)
    assert wrap_angle(-math.pi) == pytest.approx(-math.pi)


def test_wrap_angle_keeps_angles_already_inside():
    assert wrap_angle(0.5) == pytest.approx(0.5, abs=1e-15)
    assert wrap_angle(-3.0) == pytest.approx(-3.0, abs=1e-15)


def test_wrap_angle_works_elementwise_on_arrays():
    out = wrap_angle(np.array([0.0, 2.0 * math.pi + 0.1, -2.0 * math.pi - 0.1]))
    np.testing.assert_allclose(out, [0.0, 0.1, -0.1], atol=1e-12)
    assert isinstance(wrap_angle(7.0), float)
