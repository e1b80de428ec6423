"""The deterministic runner: reproducibility, report shape, every method, config validation."""

import json
from typing import Any

import pytest

from server.lab.simulation import SimConfig, run_simulation, without_timings

ISSUE_METRICS = {
    "tracking_error_m": {"mean", "median", "p90"},
    "cov_trace_m2": {"mean", "median"},
    "in_frame_fraction": None,
    "center_offset_px": {"mean", "median"},
    "spacing_error_deg": None,
    "distance_error_m": None,
    "height_error_m": None,
    "min_separation_m": None,
    "min_obstacle_clearance_m": None,
    "min_person_distance_m": None,
    "tick_ms": {"median", "p99"},
    "realtime_factor": None,
}


def _short(**kw):
    """A short, cheap run: 3 MAVs, 10 Hz control, 14 s with 10 s warm-up."""
    base = {"vehicles": 3, "duration_s": 14.0, "warmup_s": 10.0, "rate_hz": 10.0, "seed": 5}
    return SimConfig(**{**base, **kw})


def _shape(obj):
    if isinstance(obj, dict):
        return {k: _shape(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_shape(v) for v in obj]
    return type(obj).__name__ if obj is not None else "null"


@pytest.fixture(scope="module")
def report():
    return run_simulation(_short()).to_json()


def test_the_same_seed_gives_the_same_report_byte_for_byte(report):
    again = run_simulation(_short()).to_json()
    assert json.dumps(without_timings(again)) == json.dumps(without_timings(report))


def test_different_seeds_give_different_reports(report):
    other = run_simulation(_short(seed=6)).to_json()
    assert json.dumps(without_timings(other)["metrics"]) != json.dumps(without_timings(report)["metrics"])


def test_the_report_is_config_and_metrics_with_the_issue_names(report):
    assert set(report) == {"config", "metrics"}
    for name, keys in ISSUE_METRICS.items():
        assert name in report["metrics"]
        if keys is not None:
            assert set(report["metrics"][name]) == keys
    assert report["config"]["vehicles"] == 3 and report["config"]["method"] == "active"
    assert report["metrics"]["tracking_error_m"]["mean"] > 0.0
    assert report["metrics"]["realtime_factor"] > 0.0


def test_the_report_counts_what_each_mav_fused(report):
    vehicles = report["metrics"]["vehicles"]
    assert [v["vehicle_id"] for v in vehicles] == [1, 2, 3]
    assert all(v["own_detections_fused"] > 0 and v["teammate_detections_fused"] > 0 for v in vehicles)
    assert report["metrics"]["counters"]["controller_errors"] == 0


@pytest.mark.parametrize("method", ["dqmpc", "price"])
def test_baselines_give_the_same_report_shape(report, method):
    other = run_simulation(_short(method=method)).to_json()
    assert other["config"]["method"] == method
    assert _shape(other["metrics"]) == _shape(report["metrics"])


def test_the_report_file_text_is_the_json_of_the_report(report):
    result = run_simulation(_short(duration_s=11.0))
    assert json.loads(result.dumps()) == result.to_json()


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"vehicles": 0}, "vehicles"),
        ({"duration_s": -1.0}, "duration_s"),
        ({"comm_loss": 1.5}, "comm_loss"),
        ({"method": "magic"}, "method"),
        ({"trees": "forest"}, "trees"),
        ({"person": "dancing"}, "person"),
        ({"warmup_s": 30.0, "duration_s": 20.0}, "warmup_s"),
        ({"rate_hz": 0.0}, "rate_hz"),
        ({"start": "line"}, "start"),
        ({"d_des_m": float("nan")}, "d_des_m"),
        ({"seed": -3}, "seed"),
        ({"replan_hz": 200.0, "rate_hz": 100.0}, "replan_hz"),
        ({"replan_hz": -1.0}, "replan_hz"),
    ],
)
def test_bad_configs_are_refused_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        SimConfig(**kwargs)


def test_trees_may_be_given_as_a_number():
    as_json: dict[str, Any] = {"trees": 7}  # a number, as a JSON config may hold it
    assert SimConfig(**as_json).trees == "7"
    assert SimConfig(trees="NONE").trees == "none"
