"""Fixtures for the browser tests: Debian's chromium through Playwright, and live ground stations flying in
formation (see live_harness.py)."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from playwright.sync_api import Browser, sync_playwright

sys.path.insert(0, str(Path(__file__).resolve().parent))  # the harness beside this file

from live_harness import CHROMIUM_ARGS, Live, start_live  # noqa: E402

from vehicles.mission import Phase  # noqa: E402


@pytest.fixture(scope="session")
def browser() -> Iterator[Browser]:
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path="/usr/bin/chromium", headless=True, args=CHROMIUM_ARGS)
        yield b
        b.close()


def _flying(live: Live) -> Iterator[Live]:
    try:
        live.wait_for(lambda: live.phases() == {Phase.FORMATION}, sim_s=40.0, what="all MAVs in formation")
        yield live
    finally:
        live.stop()


@pytest.fixture(scope="module")
def live() -> Iterator[Live]:
    """A live ground station (3 MAVs, paper trees and person) flying in formation, shared by a module."""
    live_station, thread = start_live()
    yield from _flying(live_station)
    thread.join(20.0)
    assert not thread.is_alive(), "the ground station did not stop"


@pytest.fixture
def fresh_live() -> Iterator[Live]:
    """A live ground station of its own, flying in formation (for tests that end the flight)."""
    live_station, thread = start_live(seed=6)
    yield from _flying(live_station)
    thread.join(20.0)
    assert not thread.is_alive(), "the ground station did not stop"


