"""Run settings validated once (server/settings.py, server/lab/simulation.py): a refusal names the field."""

from __future__ import annotations

import pytest

from controller.params import MAX_TEAM_SIZE, Method, ParameterError
from server.lab.simulation import SimConfig
from server.settings import RunSettings


def test_settings_normalise_what_they_accept():
    settings = RunSettings(**{"vehicles": 5, "method": "DQMPC", "trees": 7, "seed": 3})  # as JSON holds them
    assert settings.method is Method.DQMPC and settings.trees == "7" and settings.vehicles == 5
    assert settings.scenario().vehicles == 5 and settings.formation.d_des_m == 8.0


@pytest.mark.parametrize(
    ("fields", "field"),
    [
        ({"vehicles": MAX_TEAM_SIZE + 1}, "vehicles"),
        ({"vehicles": 0}, "vehicles"),
        ({"vehicles": True}, "vehicles"),
        ({"seed": -1}, "seed"),
        ({"method": "magic"}, "method"),
        ({"trees": "forest"}, "trees"),
        ({"person": "dancing"}, "person"),
        ({"comm_loss": 1.5}, "comm_loss"),
        ({"start": "circle"}, "start"),
        ({"d_des_m": float("nan")}, "d_des_m"),
        ({"h_des_m": 0.0}, "h_des_m"),
        ({"rate_hz": 0.5}, "rate_hz"),
        ({"rate_hz": 10.0, "replan_hz": 20.0}, "replan_hz"),
    ],
)
def test_a_setting_out_of_range_is_refused_naming_its_field(fields, field):
    with pytest.raises(ParameterError) as err:
        RunSettings(**fields)
    assert err.value.field == field


@pytest.mark.parametrize(
    ("fields", "field"),
    [({"duration_s": 0.0}, "duration_s"), ({"duration_s": 30.0, "warmup_s": 30.0}, "warmup_s")],
)
def test_a_run_length_out_of_range_is_refused_naming_its_field(fields, field):
    with pytest.raises(ParameterError) as err:
        SimConfig(**fields)
    assert err.value.field == field


def test_a_sim_config_is_run_settings_plus_its_length():
    config = SimConfig(vehicles=4, duration_s=30.0, warmup_s=5.0)
    assert isinstance(config, RunSettings)
    assert config.to_dict()["method"] == "active" and config.to_dict()["duration_s"] == 30.0
