"""The plots' history: mission seconds, a sample per period over a window, gaps where values are missing."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scene_views import flying_mav, scene_view

from controller.messages import PersonEstimate
from webui.plots import PlotHistory, with_gaps
from webui.view import PersonEstimateView, SceneView


def view(t: float, *, estimate: bool = True, stale: int | None = None) -> SceneView:
    vehicles = tuple(
        flying_mav(
            i,
            position_m=np.array([0.0, 0.0, 9.0 + i]),
            velocity_mps=np.array([3.0, 4.0, 0.0]) * i,
            link_stale=i == stale,
        )
        for i in (1, 2)
    )
    cov = np.eye(6) * 0.1
    person = PersonEstimate(
        stamp_s=t, position_m=np.array([0.0, 0.0, 0.9]), velocity_mps=np.zeros(3), cov=cov
    )
    return scene_view(
        vehicles,
        time_s=t,
        person_estimate=PersonEstimateView.of(person) if estimate else None,
        tracking_error_m=0.4 if estimate else None,
    )


def test_the_first_sample_is_recorded_at_once_with_mission_seconds():
    history = PlotHistory([1, 2])
    assert history.record(view(0.05))
    assert history.times() == pytest.approx([0.05])
    assert history.altitudes()[0] == pytest.approx([10.0, 11.0])
    assert history.speeds()[0] == pytest.approx([5.0, 10.0])


def test_samples_are_taken_once_per_period_and_kept_for_the_window():
    history = PlotHistory([1, 2], window_s=10.0, sample_period_s=0.25)
    for k in range(1, 601):  # 30 s at 20 Hz
        history.record(view(k * 0.05))
    t = history.times()
    assert np.diff(t) == pytest.approx(np.full(len(t) - 1, 0.25))
    assert t[-1] == pytest.approx(29.8)  # 0.05 + 0.25 k
    assert t[0] >= t[-1] - 10.0 - 1e-9 and t[0] < t[-1] - 10.0 + 0.25


def test_missing_values_are_nan_in_the_history_and_gaps_for_the_charts():
    history = PlotHistory([1, 2])
    history.record(view(0.0, estimate=False, stale=2))
    history.record(view(1.0))
    assert math.isnan(history.traces()[0]) and history.traces()[1] == pytest.approx(0.3)
    assert math.isnan(history.altitudes()[0, 1])  # stale telemetry is not plotted as if it were fresh
    assert with_gaps(history.traces()) == [None, 0.3]


def test_a_vehicle_that_vanished_from_the_view_is_a_gap():
    history = PlotHistory([1, 2, 3])
    history.record(view(0.0))
    assert math.isnan(history.altitudes()[0, 2])


def test_with_gaps_rounds_and_turns_every_non_finite_value_into_none():
    assert with_gaps(np.array([1.23456, np.nan, np.inf, -2.0])) == [1.235, None, None, -2.0]
