"""`skyring serve --px4`: vehicle URLs and option checks (server/station/px4.py); the flights themselves are
in tests/vehicles/px4/test_px4_e2e.py."""

from __future__ import annotations

from typing import Any

import pytest
import typer

from server.cli.serve import run_px4
from server.settings import RunSettings
from server.station.px4 import px4_urls


def test_sitl_shorthand_gives_one_local_port_per_instance():
    assert px4_urls(sitl=2) == ["udpin://0.0.0.0:14540", "udpin://0.0.0.0:14541"]


def test_explicit_urls_are_kept_in_order():
    urls = ["udpin://0.0.0.0:14541", "serial:///dev/ttyUSB0:57600"]
    assert px4_urls(urls=urls) == urls


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({}, "no PX4 vehicle"),
        ({"urls": ["udpin://0.0.0.0:14540"], "sitl": 1}, "not both"),
        ({"sitl": 11}, "1 to 10"),
        ({"urls": ["localhost:14540"]}, "not a MAVSDK connection URL"),
        ({"urls": ["udpin://0.0.0.0:14540", "udpin://0.0.0.0:14540"]}, "its own URL"),
    ],
)
def test_bad_vehicle_lists_are_refused_with_the_reason(kw, message):
    with pytest.raises(ValueError, match=message):
        px4_urls(**kw)


def _run(**overrides: Any) -> None:
    kw: dict[str, Any] = dict(
        px4=[],
        sitl=0,
        origin=None,
        settings=RunSettings(person="still", trees="none", rate_hz=20.0),
        host="127.0.0.1",
        port=0,
        viser_port=0,
        speed=1.0,
    )
    kw.update(overrides)
    run_px4(**kw)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"sitl": 2, "origin": "47.3,8.5"}, "lat,lon,alt"),
        ({"px4": ["udpin://0.0.0.0:14540,udpin://0.0.0.0:14540"]}, "its own URL"),
        ({"sitl": 1, "speed": 2.0}, "real time"),
    ],
)
def test_command_refuses_bad_options_before_connecting(overrides, message):
    with pytest.raises(typer.BadParameter, match=message):
        _run(**overrides)
