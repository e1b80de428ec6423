"""Fixtures for the browser tests: Debian's chromium through Playwright, and live ground stations flying in
formation (see live_harness.py). The harness is imported inside the fixtures, so the plain webui tests in this
folder do not load the server and the simulator."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # the harness beside this file

if TYPE_CHECKING:
    from live_harness import Live, OpenPage
    from playwright.sync_api import Browser

    from server.station.api.gate import Gate


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    """A failing browser test's report ends with the newest console lines of the pages it (or its module)
    opened, and where the stations' updates stand on their way to the open pages: an intermittent failure on
    CI is only ever seen there."""
    report = yield
    if report.failed and "live_harness" in sys.modules:
        harness = sys.modules["live_harness"]
        report.sections.append(("browser console", harness.recent_console()))
        report.sections.append(("viser delivery", harness.delivery_report()))
    return report


EXPECT_TIMEOUT_MS = 60_000  # a software-rendered page on a busy 2-core machine can stall for half a minute


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    """One headless chromium per test module. Not per session: Playwright's sync API keeps its event loop
    running in the worker's main thread while the browser is open, and the longest (browser) tests run
    first (tests/conftest.py), so a session-wide browser broke every later test that runs its own loop."""
    from live_harness import CHROMIUM_ARGS
    from playwright.sync_api import expect, sync_playwright

    expect.set_options(timeout=EXPECT_TIMEOUT_MS)
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path="/usr/bin/chromium", headless=True, args=CHROMIUM_ARGS)
        yield b
        b.close()


def _flying(*, seed: int, gate: Gate | None = None) -> Iterator[Live]:
    """Start a live ground station, wait until every MAV flies in formation, hand it over, stop it."""
    from live_harness import start_live

    from vehicles.mission import Phase

    live, thread = start_live(seed=seed, gate=gate)
    try:
        live.wait_for(lambda: live.phases() == {Phase.FORMATION}, sim_s=40.0, what="all MAVs in formation")
        yield live
    finally:
        live.stop()
        thread.join(20.0)
    assert not thread.is_alive(), "the ground station did not stop"


@pytest.fixture(scope="module")
def live() -> Iterator[Live]:
    """A live ground station (3 MAVs, paper trees and person) flying in formation, shared by a module."""
    yield from _flying(seed=5)


@pytest.fixture(scope="module")
def operator_page(live: Live, browser: Browser) -> Iterator[OpenPage]:
    """One browser page on `live`'s operator page (viser's own address, as `skyring serve` prints it),
    shared by a module's tests that only drive the controls; the landing page has tests of its own."""
    from live_harness import close_page, open_operator

    opened = open_operator(browser, live.urls.operator, viewport=(1100, 700), ui=live.ui)
    yield opened
    close_page(opened)


@pytest.fixture(scope="module")
def secured_live() -> Iterator[Live]:
    """A live ground station that requires sign-in (`SIGNED_IN_USERS`: an operator and an observer), flying
    in formation, shared by a module."""
    from live_harness import signed_in_gate

    yield from _flying(seed=7, gate=signed_in_gate())
