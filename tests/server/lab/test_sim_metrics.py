"""The run metrics on hand-made recordings with known answers."""

import math
from dataclasses import replace

import numpy as np
import pytest

from controller.messages import Obstacle
from server.lab.metrics import (
    Recorder,
    TickSample,
    min_pair_distance_m,
    spacing_error_deg,
    tracking_error_by_vehicle_m,
)
from server.separation import obstacle_clearance_m

PERSON = np.array([1.0, 2.0, 0.9])


def _ring(bearings_deg, radius=8.0, height=8.9, person=PERSON):
    b = np.radians(bearings_deg)
    return np.stack(
        [person[0] + radius * np.cos(b), person[1] + radius * np.sin(b), np.full(len(b), height)], axis=1
    )


def _sample(positions, *, estimates=None, traces=None, in_formation=None, t=0.0, d_des=8.0, h_des=8.0):
    k = len(positions)
    return TickSample(
        t_s=t,
        positions_m=positions,
        in_formation=np.ones(k, bool) if in_formation is None else in_formation,
        in_air=np.ones(k, bool),
        person_m=PERSON,
        estimates_m=np.tile(PERSON, (k, 1)) if estimates is None else estimates,
        cov_traces_m2=np.ones(k) if traces is None else traces,
        d_des_m=d_des,
        h_des_m=h_des,
    )


def _metrics(samples, frames=(), offsets=(), ticks=(), obstacles=(), sim_s=10.0, wall_s=2.0, detected=None):
    rec = Recorder(obstacles=obstacles)
    for s in samples:
        rec.add_tick(s)
    for i, (f, o) in enumerate(zip(frames, offsets, strict=True)):
        rec.add_frame(in_frame=f, center_offset_px=o, detected=None if detected is None else detected[i])
    for t in ticks:
        rec.add_tick_time(t)
    return rec.metrics(sim_s=sim_s, wall_s=wall_s)


def test_uniform_spacing_has_zero_spacing_error_whatever_the_rotation():
    for k in (2, 3, 5, 8, 16):
        pos = _ring(np.arange(k) * 360.0 / k + 17.0)
        error = spacing_error_deg(positions_xy_m=pos[:, :2], person_xy_m=PERSON[:2])
        assert error == pytest.approx(0, abs=1e-9)


def test_spacing_error_of_a_known_configuration():
    # gaps 90, 90, 180 against 120: |30| + |30| + |60| over 3 = 40 degrees
    pos = _ring([0.0, 90.0, 180.0])
    assert spacing_error_deg(positions_xy_m=pos[:, :2], person_xy_m=PERSON[:2]) == pytest.approx(40.0)


def test_spacing_error_is_undefined_for_a_single_mav():
    assert math.isnan(spacing_error_deg(positions_xy_m=np.zeros((1, 2)), person_xy_m=np.zeros(2)))


def test_a_perfect_formation_has_zero_distance_height_and_spacing_error():
    m = _metrics([_sample(_ring([0, 120, 240]))])
    assert m["spacing_error_deg"] == pytest.approx(0.0, abs=1e-6)
    assert m["distance_error_m"] == pytest.approx(0.0, abs=1e-6)
    assert m["height_error_m"] == pytest.approx(0.0, abs=1e-6)


def test_distance_and_height_errors_are_mean_absolute_errors():
    pos = np.vstack([_ring([0], radius=9.0, height=8.4), _ring([180], radius=7.5, height=9.9)])
    m = _metrics([_sample(pos)])
    assert m["distance_error_m"] == pytest.approx((1.0 + 0.5) / 2)
    assert m["height_error_m"] == pytest.approx((0.5 + 1.0) / 2)


def test_tracking_error_pools_mavs_and_ticks_and_skips_missing_estimates():
    pos = _ring([0, 180])
    s1 = _sample(
        pos, estimates=np.array([PERSON + [1.0, 0, 0], PERSON + [0, 3.0, 0]]), traces=np.array([2.0, 4.0])
    )
    s2 = _sample(
        pos, estimates=np.array([PERSON + [0, 0, 2.0], [np.nan] * 3]), traces=np.array([6.0, np.nan])
    )
    m = _metrics([s1, s2])
    assert m["tracking_error_m"]["mean"] == pytest.approx(2.0)
    assert m["tracking_error_m"]["median"] == pytest.approx(2.0)
    assert m["tracking_error_m"]["p90"] == pytest.approx(np.percentile([1.0, 3.0, 2.0], 90))
    assert m["cov_trace_m2"] == {"mean": pytest.approx(4.0), "median": pytest.approx(4.0)}
    assert m["estimate_fraction"] == pytest.approx(0.75)
    assert tracking_error_by_vehicle_m([s1, s2]) == [pytest.approx(1.5), pytest.approx(3.0)]


def test_mavs_out_of_formation_are_left_out_of_formation_metrics():
    pos = np.vstack([_ring([0, 180]), [[50.0, 50.0, 0.0]]])
    m = _metrics([_sample(pos, in_formation=np.array([True, True, False]))])
    assert m["spacing_error_deg"] == pytest.approx(0.0, abs=1e-6)
    assert m["distance_error_m"] == pytest.approx(0.0, abs=1e-6)


def test_in_frame_fraction_and_centre_offset_over_in_frame_frames():
    m = _metrics(
        [_sample(_ring([0, 180]))], frames=[True, True, False, True], offsets=[10.0, 20.0, 900.0, 60.0]
    )
    assert m["in_frame_fraction"] == pytest.approx(0.75)
    assert m["center_offset_px"] == {"mean": pytest.approx(30.0), "median": pytest.approx(20.0)}
    assert m["frames"] == 4


def test_detected_fraction_leaves_out_frames_where_a_trunk_hid_the_person():
    m = _metrics(
        [_sample(_ring([0, 180]))],
        frames=[True, True, False, True],
        offsets=[0.0] * 4,
        detected=[True, False, False, True],
    )
    assert m["in_frame_fraction"] == pytest.approx(0.75)
    assert m["detected_fraction"] == pytest.approx(0.5)


def test_minimum_separation_clearance_and_person_distance():
    pos = np.array([[4.0, 2.0, 8.0], [4.0, 4.0, 9.5], [-6.0, 2.0, 8.0]])
    tree = Obstacle(obstacle_id="t", center_m=np.array((-6.0, 5.0)), radius_m=0.5, height_m=12.0)
    m = _metrics([_sample(pos)], obstacles=(tree,))
    assert m["min_separation_m"] == pytest.approx(math.hypot(2.0, 1.5))
    assert m["min_obstacle_clearance_m"] == pytest.approx(2.5)
    assert m["min_person_distance_m"] == pytest.approx(3.0)
    assert min_pair_distance_m(pos[:1]) == math.inf


def test_a_trunk_lower_than_the_mav_does_not_count_for_clearance():
    short = Obstacle(obstacle_id="s", center_m=np.array((0.0, 0.0)), radius_m=0.3, height_m=5.0)
    assert obstacle_clearance_m(np.array([[0.5, 0.0, 8.0]]), (short,)) == math.inf
    assert obstacle_clearance_m(np.array([[0.5, 0.0, 4.0]]), (short,)) == pytest.approx(0.2)


def test_timings_are_reported_in_milliseconds_and_as_a_real_time_factor():
    m = _metrics([_sample(_ring([0]))], ticks=[0.001] * 99 + [0.010], sim_s=120.0, wall_s=30.0)
    assert m["tick_ms"]["median"] == pytest.approx(1.0)
    assert m["tick_ms"]["p99"] == pytest.approx(np.percentile([1.0] * 99 + [10.0], 99))
    assert m["realtime_factor"] == pytest.approx(4.0)


def test_metrics_without_data_are_null():
    m = _metrics([])
    assert m["tracking_error_m"] == {"mean": None, "median": None, "p90": None}
    assert m["in_frame_fraction"] is None and m["spacing_error_deg"] is None
    assert m["min_separation_m"] is None and m["min_obstacle_clearance_m"] is None


def test_believed_separation_is_measured_between_the_self_localised_positions():
    truth = np.array([[0.0, 0.0, 8.0], [1.0, 0.0, 8.0]])
    believed = np.array([[-0.5, 0.0, 8.0], [1.5, 0.0, 8.0]])
    sample = TickSample(
        t_s=0.0,
        positions_m=truth,
        in_formation=np.ones(2, bool),
        in_air=np.ones(2, bool),
        person_m=PERSON,
        estimates_m=np.tile(PERSON, (2, 1)),
        cov_traces_m2=np.ones(2),
        d_des_m=8.0,
        h_des_m=8.0,
        believed_positions_m=believed,
    )
    m = _metrics([sample])
    assert m["min_separation_m"] == pytest.approx(1.0)
    assert m["min_believed_separation_m"] == pytest.approx(2.0)


def test_believed_separation_defaults_to_the_true_one_without_self_localisation():
    m = _metrics([_sample(_ring([0.0, 20.0]))])
    assert m["min_believed_separation_m"] == pytest.approx(m["min_separation_m"])


def _flight(positions, t, in_air=None):
    """A tick of two or more MAVs during any phase (tracking inputs perfect, so only safety differs)."""
    k = len(positions)
    return replace(
        _sample(np.asarray(positions, float), t=t), in_air=np.ones(k, bool) if in_air is None else in_air
    )


def test_mavs_touching_during_the_warm_up_set_the_minimum_separation_with_when_and_which():
    rec = Recorder(warmup_s=20.0, vehicle_ids=(4, 7, 9))
    far = _ring([0, 120, 240])
    touching = far.copy()
    touching[2] = touching[1] + [0.05, 0.0, 0.0]  # vehicles 7 and 9 touch while spreading out
    rec.add_tick(_flight(far, t=1.0))
    rec.add_tick(_flight(touching, t=3.5))
    rec.add_tick(_flight(far, t=20.0))
    m = rec.metrics(sim_s=10.0, wall_s=1.0)
    assert m["min_separation_m"] == pytest.approx(0.05)
    assert m["min_separation_t_s"] == pytest.approx(3.5)
    assert m["min_separation_pair"] == [7, 9]
    assert m["min_believed_separation_m"] == pytest.approx(0.05)
    assert m["min_believed_separation_pair"] == [7, 9]
    assert m["flight_ticks"] == 3 and m["samples"] == 1


def test_tracking_metrics_leave_out_the_warm_up_samples():
    rec = Recorder(warmup_s=20.0)
    pos = _ring([0, 180])
    bad = np.array([PERSON + [5.0, 0, 0], PERSON + [5.0, 0, 0]])
    rec.add_tick(_sample(_ring([0, 10], radius=3.0), estimates=bad, traces=np.full(2, 50.0), t=5.0))
    rec.add_tick(_sample(pos, estimates=np.array([PERSON + [1.0, 0, 0]] * 2), t=20.0 - 1e-12))
    m = rec.metrics(sim_s=10.0, wall_s=1.0)
    assert m["tracking_error_m"]["mean"] == pytest.approx(1.0)
    assert m["cov_trace_m2"]["mean"] == pytest.approx(1.0)
    assert m["spacing_error_deg"] == pytest.approx(0.0, abs=1e-6)
    assert m["distance_error_m"] == pytest.approx(0.0, abs=1e-6)
    assert m["samples"] == 1
    assert rec.tracking_error_by_vehicle_m() == [pytest.approx(1.0), pytest.approx(1.0)]


def test_grounded_mavs_are_left_out_until_they_take_off():
    rec = Recorder()
    side_by_side = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [9.0, 0.0, 8.0]])
    rec.add_tick(_flight(side_by_side, t=0.1, in_air=np.array([False, False, True])))
    rec.add_tick(_flight(side_by_side + [0, 0, 1.0], t=0.2, in_air=np.array([True, True, True])))
    m = rec.metrics(sim_s=1.0, wall_s=1.0)
    assert m["min_separation_m"] == pytest.approx(0.3)
    assert m["min_separation_t_s"] == pytest.approx(0.2)
    assert m["min_separation_pair"] == [1, 2]


def test_obstacle_and_person_minima_say_when_and_which():
    tree = Obstacle(obstacle_id="tree-3", center_m=np.array((0.0, 0.0)), radius_m=0.5, height_m=12.0)
    rec = Recorder(obstacles=(tree,), warmup_s=30.0, vehicle_ids=(1, 2))
    rec.add_tick(_flight([[3.0, 0.0, 8.0], [0.0, 9.0, 8.0]], t=2.0))
    rec.add_tick(_flight([[0.4, 0.0, 8.0], [0.0, 9.0, 8.0]], t=4.0))  # vehicle 1 inside the trunk
    rec.add_tick(_flight([[3.0, 0.0, 8.0], [PERSON[0], PERSON[1] + 0.5, 8.0]], t=6.0))
    m = rec.metrics(sim_s=1.0, wall_s=1.0)
    assert m["min_obstacle_clearance_m"] == pytest.approx(-0.1)
    assert m["min_obstacle_clearance_t_s"] == pytest.approx(4.0)
    assert m["min_obstacle_clearance_pair"] == [1, "tree-3"]
    assert m["min_person_distance_m"] == pytest.approx(0.5)
    assert m["min_person_distance_t_s"] == pytest.approx(6.0)
    assert m["min_person_distance_vehicle"] == 2
    assert m["tracking_error_m"]["mean"] is None  # all three ticks were in the warm-up


def test_without_airborne_ticks_the_where_and_when_are_null():
    m = _metrics([])
    assert m["min_separation_t_s"] is None and m["min_separation_pair"] is None
    assert m["min_person_distance_vehicle"] is None and m["flight_ticks"] == 0
