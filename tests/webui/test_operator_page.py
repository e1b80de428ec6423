"""Acceptance of the operator page for field work, in Debian's chromium over live ground stations.

- LAND ALL is visible and clickable at every scroll position of every tab, at 1280x800 and 1920x1080, with 3
  and with 16 MAVs; Shift+L opens its confirmation; confirming lands everyone.
- Injected conditions (a battery at 20 %, two MAVs within 1.4 m, the loop slowed below real time, a vehicle's
  link cut) each raise their alert in the page and in /api/state within a second; acknowledging keeps them
  in the list.
- The plots show data from the first sample, over mission seconds.
Every state is saved as a screenshot under test-artifacts/operator-*.png; no page logs a console error.
"""

from __future__ import annotations

import contextlib
import re
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import httpx
import numpy as np
import pytest
from live_harness import ARTIFACTS, Live, OpenPage, close_page, open_operator, open_tab, settle, start_live
from playwright.sync_api import Locator, Page, expect
from playwright.sync_api import TimeoutError as PlaywrightTimeoutError

from vehicles.mission import Phase

pytestmark = pytest.mark.browser

VIEWPORTS = ((1280, 800), (1920, 1080))
TABS = ("Team", "Alerts", "Formation", "View", "Plots")
ALERT_LATENCY_S = 1.0  # the acceptance bound: injected condition -> alert in the page and in /api/state


def screenshot(page: Page, name: str) -> None:
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=ARTIFACTS / f"operator-{name}.png")


def land_all_button(page: Page) -> Locator:
    return page.get_by_role("button", name="LAND ALL", exact=True)


REACHABLE_JS = """
() => {
  const button = [...document.querySelectorAll('button')].find(b => b.textContent.trim() === 'LAND ALL');
  const scrollers = [...document.querySelectorAll('*')].filter(e => {
    const s = getComputedStyle(e);
    return e.scrollHeight > e.clientHeight + 2 && ['auto', 'scroll'].includes(s.overflowY);
  });
  const reachable = () => {
    if (!button) return 'not found';
    const r = button.getBoundingClientRect();
    const inside = r.width > 0 && r.height > 0 && r.left >= 0 && r.top >= 0 && r.right <= innerWidth
      && r.bottom <= innerHeight;
    if (!inside) return `outside the window at ${JSON.stringify(r)}`;
    const hit = document.elementFromPoint(r.x + r.width / 2, r.y + r.height / 2);
    if (!button.contains(hit)) return `covered by ${hit && hit.outerHTML.slice(0, 120)}`;
    const style = getComputedStyle(button);
    if (style.visibility !== 'visible' || Number(style.opacity) <= 0.5) return 'hidden';
    return button.disabled ? 'disabled' : 'ok';
  };
  const found = {};
  for (const fraction of [0, 0.5, 1]) {
    for (const e of scrollers) {
      e.scrollTop = fraction * (e.scrollHeight - e.clientHeight);
      e.dispatchEvent(new Event('scroll'));
    }
    window.scrollTo(0, fraction * document.documentElement.scrollHeight);
    found[`scrolled to ${fraction * 100} %`] = reachable();
  }
  return {scrollers: scrollers.length, found};
}
"""


def assert_land_all_reachable(page: Page, where: str) -> int:
    """Scroll every scrollable area of the page to its top, middle and bottom; at each, LAND ALL must lie
    inside the window, shown and enabled, with a click at its centre landing on it (the hit test of
    Playwright's actionability check, done in the page in one call). Returns how many areas scroll."""
    result = page.evaluate(REACHABLE_JS)
    assert set(result["found"].values()) == {"ok"}, (where, result["found"])
    return result["scrollers"]


def check_every_scroll_position(page: Page, label: str, *, shots: str | None = None) -> int:
    """LAND ALL stays reachable at every scroll position of every tab, and after wheeling over the control
    panel; Playwright's own actionability check agrees. Returns how many areas scrolled at most. With
    `shots`, each tab is saved as a screenshot first (named after it)."""
    most = 0
    size = page.viewport_size
    assert size is not None
    for tab in TABS:
        open_tab(page, tab)
        if shots is not None:
            screenshot(page, f"{shots}-tab-{tab.lower()}")
        most = max(most, assert_land_all_reachable(page, f"{label}, tab {tab}"))
    page.mouse.move(size["width"] - 100, size["height"] / 2)
    page.mouse.wheel(0, 5000)
    assert_land_all_reachable(page, f"{label}, after wheeling over the control panel")
    land_all_button(page).click(trial=True)
    return most


def shift_l_opens_the_land_all_confirmation(page: Page) -> None:
    open_tab(page, "Team")  # focus on the page, not in a text field
    page.keyboard.press("Shift+L")
    expect(page.get_by_text("LAND ALL?", exact=True)).to_be_visible()
    expect(page.get_by_role("button", name="Confirm LAND ALL")).to_be_visible()


@contextlib.contextmanager
def flying(*, vehicles: int, speed: float, rate_hz: float, trees: str, seed: int) -> Iterator[Live]:
    """A live ground station of its own (stopped, and checked to stop, on the way out)."""
    live, thread = start_live(vehicles=vehicles, seed=seed, speed=speed, rate_hz=rate_hz, trees=trees)
    try:
        yield live
    finally:
        live.stop()
        thread.join(30.0)
    assert not thread.is_alive(), "the ground station did not stop"


def all_airborne(live: Live) -> bool:
    snap = live.station.snapshot()
    return all(v.autopilot is not None and v.autopilot.in_air for v in snap.vehicles)


# ---- LAND ALL ----------------------------------------------------------------------------------------------


def landing_everyone(live: Live) -> bool:
    """Every MAV in the LANDING phase, its autopilot in its land mode and coming down (or already down)."""
    for v in live.station.snapshot().vehicles:
        s = v.autopilot
        down = v.phase == Phase.LANDED or (s is not None and not s.in_air)
        coming_down = (
            v.phase == Phase.LANDING and s is not None and s.mode == "land" and s.velocity_mps[2] < -0.2
        )
        if not (down or coming_down):
            return False
    return True


@pytest.mark.parametrize(
    ("vehicles", "rate_hz", "speed", "wait_landed"),
    [
        pytest.param(3, 20.0, 4.0, True, id="3-mavs"),
        # alone: a 16-MAV page rendered in software, starved of CPU beside the parallel suite, once let a key
        # press wait past Playwright's 30 s (CI, 2026-11-30)
        pytest.param(16, 10.0, 2.0, False, id="16-mavs", marks=pytest.mark.alone),
    ],
)
def test_land_all_is_reachable_at_every_scroll_position_and_shift_l_lands_everyone(
    browser, vehicles, rate_hz, speed, wait_landed
):
    """16 MAVs are followed until every one is coming down in its land mode (touching down takes 13 s of
    simulated time, which 16 MAVs need a minute of this machine for); 3 MAVs, at four times real time, until
    they are on the ground."""
    with flying(vehicles=vehicles, speed=speed, rate_hz=rate_hz, trees="paper", seed=11) as live:
        live.wait_for(lambda: all_airborne(live), sim_s=30.0, what="every MAV in the air")
        opened = open_operator(browser, live.urls.operator, viewport=VIEWPORTS[0])
        page = opened.page
        try:
            for width, height in VIEWPORTS:
                page.set_viewport_size({"width": width, "height": height})
                label = f"{vehicles} MAVs at {width}x{height}"
                first = (width, height) == VIEWPORTS[0]
                shots = f"{vehicles}mavs-{width}x{height}" if first else None
                scrollers = check_every_scroll_position(page, label, shots=shots)
                assert scrollers >= 1, f"{label}: nothing scrolls, so the check proved nothing"
                open_tab(page, "Team")
                page.evaluate(REACHABLE_JS)  # leaves every list scrolled to its end
                screenshot(page, f"{vehicles}mavs-{width}x{height}-team-scrolled")
                shift_l_opens_the_land_all_confirmation(page)
                screenshot(page, f"{vehicles}mavs-{width}x{height}-land-all-dialog")
                if (width, height) != VIEWPORTS[-1]:
                    page.get_by_role("button", name="Cancel").click()
                    expect(page.get_by_text("LAND ALL?", exact=True)).to_be_hidden()
                    assert all(v.phase != Phase.LANDING for v in live.station.snapshot().vehicles)
            assert all_airborne(live)
            page.get_by_role("button", name="Confirm LAND ALL").click()
            expect(page.get_by_text("All MAVs landing")).to_be_visible()
            phases = {v.phase for v in live.station.snapshot().vehicles}
            assert phases <= {Phase.LANDING, Phase.LANDED}, phases
            live.wait_for(lambda: landing_everyone(live), sim_s=5.0, what="every MAV coming down")
            if wait_landed:
                live.wait_for(lambda: live.phases() == {Phase.LANDED}, sim_s=40.0, what="every MAV landed")
            screenshot(page, f"{vehicles}mavs-landing")
        finally:
            close_page(opened)
        assert opened.console_errors == [], opened.console_errors
        if wait_landed:
            assert all(
                v.autopilot is not None and not v.autopilot.in_air for v in live.station.snapshot().vehicles
            )


# ---- alerts ------------------------------------------------------------------------------------------------
# Each alert test times the alert against ALERT_LATENCY_S of wall time, so they are marked `alone`: `make
# test` runs them after the parallel suite, with nothing else on the machine (beside it, a busy 2-core machine
# held the page's update past the bound in all three tries).


@pytest.fixture(scope="module")
def alert_live() -> Iterator[Live]:
    """Three MAVs at real time (the loop has room to spare, so that it is not behind before a test slows it),
    no trees (no alert of their own), in the air."""
    with flying(vehicles=3, speed=1.0, rate_hz=20.0, trees="none", seed=12) as live:
        live.wait_for(lambda: all_airborne(live), sim_s=20.0, what="every MAV in the air")
        yield live


@pytest.fixture(scope="module")
def alert_page(alert_live, browser) -> Iterator[OpenPage]:
    """The operator page at 1280x800 on its Alerts tab."""
    opened = open_operator(browser, alert_live.urls.operator, viewport=VIEWPORTS[0], ui=alert_live.ui)
    open_tab(opened.page, "Alerts")
    yield opened
    close_page(opened)
    assert opened.console_errors == [], opened.console_errors


@pytest.mark.alone
def test_plots_draw_altitude_and_speed_per_mav_from_the_first_sample_over_mission_seconds(
    alert_live, alert_page
):
    assert alert_live.station.time_s < 100.0, "the run is older than the plots' window: the test proves less"
    charts = plotted(alert_page)
    by_title = {c["title"]: c for c in charts}
    assert {"Altitude per MAV", "Speed per MAV", "Fused position covariance trace"} <= set(by_title)
    altitude = by_title["Altitude per MAV"]
    assert altitude["x"][0] <= 0.25  # from the first sample of the run, not two minutes in
    assert len(altitude["y"]) == 3  # one line per MAV
    early = [y for x, y in zip(altitude["x"], altitude["y"][0], strict=True) if x <= 5.0 and y is not None]
    assert early, "no altitude plotted in the first 5 s of mission time"
    for chart in charts:
        assert chart["time"] is False
        assert chart["ticks"] and all(float(t) >= 0.0 for t in chart["ticks"])  # seconds, not dates


def first_seen(condition: Callable[[], bool], *, timeout_s: float) -> float | None:
    """Wall seconds until condition() first holds (polled every 20 ms), None if not within timeout_s."""
    start = time.monotonic()
    while time.monotonic() - start < timeout_s:
        if condition():
            return time.monotonic() - start
        time.sleep(0.02)
    return None


def api_alerts(live: Live, kind: str, client: httpx.Client | None = None) -> list[dict]:
    url = f"{live.urls.api}api/state"
    state = (client.get(url, timeout=5.0) if client is not None else httpx.get(url, timeout=5.0)).json()
    return [a for a in state["alerts"] if a["kind"] == kind and a["active"]]


ROW_SHOWN_JS = """
([text]) => [...document.querySelectorAll('table.skyring-alerts tbody tr')].some(
  r => r.textContent.includes(text) && r.textContent.includes('ACTIVE'))
"""
ROW_CLEARED_JS = f"(arg) => !({ROW_SHOWN_JS.strip()})(arg)"


def page_shows_within(page: Page, text: str, *, timeout_s: float) -> float | None:
    """Wall seconds until the page's alert list has an active row containing `text` (polled in the page
    every 20 ms, so the measurement costs no round trips), None if not within timeout_s."""
    start = time.monotonic()
    try:
        page.wait_for_function(ROW_SHOWN_JS, arg=[text], polling=20, timeout=timeout_s * 1e3)
    except PlaywrightTimeoutError:
        return None
    return time.monotonic() - start


@dataclass(frozen=True)
class Raised:
    api_s: float | None
    page_s: float | None
    alert: dict | None


def raise_and_time(live: Live, page: Page, *, kind: str, text: str, inject: Callable[[], None]) -> Raised:
    """Inject a condition; time how long until its alert is active in /api/state (in a thread) and in the
    page's alert list. The page is let settle first (drawing frames again after the last tab switch)."""
    settle(page)
    seen: dict[str, float | None] = {}

    def poll_api() -> None:
        with httpx.Client() as client:  # one kept-alive connection, as a client polling the state would
            seen["api"] = first_seen(lambda: bool(api_alerts(live, kind, client)), timeout_s=10.0)

    poller = threading.Thread(target=poll_api)
    poller.start()
    inject()
    page_s = page_shows_within(page, text, timeout_s=10.0)
    poller.join()
    alerts = api_alerts(live, kind)
    return Raised(api_s=seen.get("api"), page_s=page_s, alert=alerts[0] if alerts else None)


def acknowledge_in_the_page(live: Live, page: Page, alert_id: str) -> None:
    page.get_by_role("button", name=re.compile(f"^Acknowledge {alert_id}:")).click()
    expect(page.locator(f'tr[data-alert="{alert_id}"]')).to_contain_text("ack")
    listed = httpx.get(f"{live.urls.api}api/alerts", timeout=5.0).json()
    (kept,) = [a for a in listed if a["alert_id"] == alert_id]
    assert kept["acknowledged"]


def within_bound(raised: Raised) -> bool:
    """The alert is active, in /api/state and in the page, each within ALERT_LATENCY_S."""
    times = (raised.api_s, raised.page_s)
    return raised.alert is not None and all(t is not None and t <= ALERT_LATENCY_S for t in times)


def raise_within_a_second(
    live: Live,
    page: Page,
    *,
    kind: str,
    text: str,
    inject: Callable[[], None],
    restore: Callable[[], None],
    attempts: int = 3,
) -> dict:
    """Inject a condition and time its alert (`raise_and_time`) up to `attempts` times, removing the
    condition and waiting for the alert to clear between tries; the alert of the try that met the bound (in
    /api/state and in the page within ALERT_LATENCY_S), else the failure lists every try. More than one try:
    on a machine shared with the rest of the suite one try can be held up by a spike of load that has nothing
    to do with the station; a station that is slow every time still fails. Each time is written to
    test-artifacts/operator-alert-latency.txt."""
    tries: list[str] = []
    ARTIFACTS.mkdir(exist_ok=True)
    for attempt in range(attempts):
        if attempt:
            restore()
            cleared = first_seen(lambda: not api_alerts(live, kind), timeout_s=15.0)
            assert cleared is not None, f"{kind}: the alert stayed active after its condition was removed"
            page.wait_for_function(ROW_CLEARED_JS, arg=[text], polling=20, timeout=15_000)
        raised = raise_and_time(live, page, kind=kind, text=text, inject=inject)
        tries.append(f"/api/state after {raised.api_s} s, page after {raised.page_s} s")
        with (ARTIFACTS / "operator-alert-latency.txt").open("a") as f:
            f.write(f"{kind} try {attempt + 1}: {tries[-1]}\n")
        if raised.alert is not None and within_bound(raised):
            return raised.alert
    listed = "; ".join(tries)
    raise AssertionError(f"{kind}: not within {ALERT_LATENCY_S} s in any of {attempts} tries: {listed}")


def autopilot(live: Live, vehicle_id: int):
    assert live.setup is not None
    return {a.vehicle_id: a for a in live.setup.autopilots}[vehicle_id]


@pytest.mark.alone
def test_a_battery_at_20_percent_raises_its_alert_in_the_page_and_the_api_within_a_second(
    alert_live, alert_page
):
    ap = autopilot(alert_live, 1)
    alert = raise_within_a_second(
        alert_live,
        alert_page.page,
        kind="battery",
        text="battery low",
        inject=lambda: ap.set_battery(0.20),
        restore=lambda: ap.set_battery(0.9),
    )
    assert alert["vehicle_id"] == 1 and alert["severity"] == "warning" and "20 %" in alert["message"]
    screenshot(alert_page.page, "alert-battery")
    acknowledge_in_the_page(alert_live, alert_page.page, alert["alert_id"])
    screenshot(alert_page.page, "alert-battery-acknowledged")
    ap.set_battery(0.9)


@pytest.mark.alone
def test_two_mavs_forced_within_1_4_m_raise_a_separation_alert_within_a_second(alert_live, alert_page):
    mover, other = autopilot(alert_live, 2), autopilot(alert_live, 3)

    def squeeze() -> None:  # MAV 2's reported position 1.2 m east of MAV 3's (GPS drift included)
        drift = mover.state().position_m - mover.true_position_m
        mover.place_at(other.state().position_m + np.array([1.2, 0.0, 0.0]) - drift)

    alert = raise_within_a_second(
        alert_live,
        alert_page.page,
        kind="separation",
        text="m apart",
        inject=squeeze,
        restore=lambda: None,  # formation control moves the two apart again
    )
    assert (alert["vehicle_id"], alert["subject"], alert["severity"]) == (2, "MAV 3", "critical")
    screenshot(alert_page.page, "alert-separation")
    acknowledge_in_the_page(alert_live, alert_page.page, alert["alert_id"])


@pytest.mark.alone
def test_a_cut_link_raises_a_link_alert_within_a_second(alert_live, alert_page):
    ap = autopilot(alert_live, 3)
    try:
        alert = raise_within_a_second(
            alert_live,
            alert_page.page,
            kind="link",
            text="link stale",
            inject=ap.cut_link,
            restore=ap.restore_link,
        )
        assert alert["vehicle_id"] == 3 and alert["severity"] == "critical"
        open_tab(alert_page.page, "Team")
        expect(alert_page.page.locator('tr[data-vehicle="3"]')).to_contain_text("STALE")
        screenshot(alert_page.page, "alert-link-team")
        open_tab(alert_page.page, "Alerts")
        screenshot(alert_page.page, "alert-link")
        acknowledge_in_the_page(alert_live, alert_page.page, alert["alert_id"])
    finally:
        ap.restore_link()


@pytest.mark.alone
def test_a_control_loop_slowed_below_real_time_raises_its_alert_within_a_second(alert_live, alert_page):
    station = alert_live.station
    behind = first_seen(lambda: not api_alerts(alert_live, "realtime"), timeout_s=15.0)
    assert behind is not None, (
        "the loop is behind real time before the test slows it: the machine is too busy"
    )
    real_tick = station.tick

    def slow_tick() -> None:  # each 0.05 s tick now costs 0.1 s: half of real time
        time.sleep(0.1)
        real_tick()

    try:
        alert = raise_within_a_second(
            alert_live,
            alert_page.page,
            kind="realtime",
            text="behind real time",
            inject=lambda: setattr(station, "tick", slow_tick),
            restore=lambda: delattr(station, "tick"),
        )
        assert alert["vehicle_id"] is None and "1x asked" in alert["message"]
        screenshot(alert_page.page, "alert-realtime")
    finally:
        del station.tick  # the instance attribute goes, the method is back
    acknowledge_in_the_page(alert_live, alert_page.page, alert["alert_id"])
    screenshot(alert_page.page, "alerts-acknowledged")
    listed = httpx.get(f"{alert_live.urls.api}api/alerts", timeout=5.0).json()
    assert {"realtime"} <= {a["kind"] for a in listed}


# ---- plots -------------------------------------------------------------------------------------------------

UPLOTS_JS = """
() => Object.values(window.__viserTestpoints?.uplots || {}).map(u => ({
  title: u.chart.root.querySelector('.u-title')?.textContent || '',
  x: Array.from(u.chart.data[0]),
  y: u.chart.data.slice(1).map(s => Array.from(s)),
  time: u.chart.scales.x.time,
  ticks: u.chart.axes[0]._values || [],
}))
"""


def plotted(opened: OpenPage) -> list[dict]:
    """The four charts as the page draws them, once each has a few samples and its x axis drawn (within 5 s of
    asking: a chart takes new data at once and draws it, axes included, in the page's next frame)."""
    open_tab(opened.page, "Plots")
    try:
        expect(opened.page.get_by_text("Altitude per MAV")).to_be_visible()
        charts: list[dict] = []

        def drawn() -> bool:
            charts[:] = opened.page.evaluate(UPLOTS_JS)
            return len(charts) == 4 and all(len(c["x"]) > 2 and c["ticks"] for c in charts)

        assert first_seen(drawn, timeout_s=5.0) is not None, "the plots showed no data within 5 s"
        screenshot(opened.page, "plots")
        return charts
    finally:
        open_tab(opened.page, "Alerts")
