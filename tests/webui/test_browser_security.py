"""Sign-in and cross-site protection of the operator page in a real browser (Debian's chromium through
Playwright), over a live ground station that requires sign-in (an operator and an observer): nothing works
before signing in, an observer watches but cannot command, an operator lands every MAV, and a page of
another origin cannot command the station or read its stream, even from the operator's own browser.

The tests share one flying station; each checks that the team is flying in formation before it starts, and
the LAND ALL test comes last in the file (pytest and xdist keep this file's order on a worker).
"""

from __future__ import annotations

import http.server
import json
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
import viser
from live_harness import OBSERVER, OPERATOR, Live, close_page, new_page, open_tab, sign_in, software_gl
from playwright.sync_api import Page, expect

from vehicles.mission import Phase

pytestmark = pytest.mark.browser

SOCKET_TIMEOUT_MS = 15000  # a station under the full suite's load can take seconds to answer a handshake

# ([url, subprotocol or null]): opens a WebSocket; reports whether it opened, how many messages it received
# and its close code (null: still open when it ended). It ends at the first message (that answers whether the
# socket streams), at the close, or after SOCKET_TIMEOUT_MS.
PROBE_SOCKET_JS = """
([url, protocol]) => new Promise((resolve) => {
  const ws = protocol ? new WebSocket(url, protocol) : new WebSocket(url);
  const seen = { opened: false, messages: 0, code: null };
  ws.onopen = () => { seen.opened = true; };
  ws.onmessage = () => { seen.messages += 1; ws.onclose = null; ws.close(); resolve(seen); };
  ws.onclose = (event) => { seen.code = event.code; resolve(seen); };
  setTimeout(() => { ws.close(); resolve(seen); }, SOCKET_TIMEOUT_MS);
})
""".replace("SOCKET_TIMEOUT_MS", str(SOCKET_TIMEOUT_MS))


def probe_from_a_light_page(page: Page, live: Live, args: list) -> dict:
    """PROBE_SOCKET_JS run in a new tab of `page`'s context (same cookies) on the station's sign-in page: the
    operator page's software-rendered 3-D view can hold its own page's thread past the probe's time-out on a
    busy machine, so that a frame which arrived is never counted."""
    light = page.context.new_page()
    try:
        light.goto(f"{live.urls.api}login")
        return light.evaluate(PROBE_SOCKET_JS, args)
    finally:
        light.close()


def viser_socket(live: Live) -> tuple[str, str]:
    """The URL of viser's internal port and the subprotocol its page offers (so viser's own version check
    passes and only the station's admission is tested)."""
    return f"ws://127.0.0.1:{live.ui.port}/", f"viser-v{viser.__version__}"


def digest(live: Live) -> tuple:
    """What an attack would change: the formation, whether it runs, the obstacles, each MAV's phase and
    whether it is in the air."""
    snap = live.station.snapshot()
    return (
        snap.formation,
        snap.formation_enabled,
        tuple(o.obstacle_id for o in snap.obstacles),
        tuple((v.vehicle_id, v.phase, v.autopilot is not None and v.autopilot.in_air) for v in snap.vehicles),
    )


def assert_flying(live: Live) -> None:
    assert live.phases() == {Phase.FORMATION}, "the test needs the team flying in formation"


def audit_since(live: Live, start: int) -> list:
    return list(live.station.recent_audit)[start:]


def test_the_operator_page_controls_work_only_while_signed_in(secured_live, browser):
    live = secured_live
    assert_flying(live)
    before, clients = digest(live), len(live.ui.server.get_clients())
    opened = new_page(browser)
    try:
        page = opened.page
        page.goto(live.urls.api)
        page.wait_for_url("**/login?next=/")  # the landing page sends a stranger to the sign-in form
        page.goto(live.urls.operator)
        page.wait_for_url("**/login?next=/operator/")  # so does the 3-D page itself
        expect(page.get_by_text("LAND ALL", exact=True)).to_have_count(0)
        land_all = page.evaluate("async () => (await fetch('/api/land_all', {method: 'POST'})).status")
        stream = page.evaluate(PROBE_SOCKET_JS, [ws_url(live, "ws"), None])
        operator = page.evaluate(PROBE_SOCKET_JS, [ws_url(live, "operator"), None])
        assert land_all == 401
        assert (stream["opened"], stream["messages"]) == (False, 0)
        assert (operator["opened"], operator["messages"]) == (False, 0)
        with foreign_site("<!doctype html><title>a local page</title>") as url:
            page.goto(url)  # a page without the station's CSP, trying viser's internal port straight
            direct = page.evaluate(PROBE_SOCKET_JS, list(viser_socket(live)))
        assert (direct["messages"], direct["code"]) == (0, 1008)  # closed before it is sent any scene
        assert digest(live) == before
        assert len(live.ui.server.get_clients()) == clients  # no operator page connected

        page.goto(software_gl(live.urls.operator))  # signing in brings the controls and the stream
        page.fill("#name", OPERATOR[0])
        page.fill("#secret", OPERATOR[1])
        page.click("#sign-in")
        page.wait_for_url(software_gl(live.urls.operator))  # back on the page asked for, its setting kept
        expect(page.get_by_text("LAND ALL", exact=True)).to_be_visible()
        stream = probe_from_a_light_page(page, live, [ws_url(live, "ws"), None])
        assert stream["opened"] and stream["messages"] > 0, stream

        assert page.request.post(f"{live.urls.api}auth/logout").status == 204  # as from another tab
        open_tab(page, "Formation")
        page.get_by_text("Stop formation (hold)", exact=True).click()  # the page is still open
        expect(page.get_by_text("sign in as an operator", exact=False)).to_be_visible()
        assert digest(live) == before
    finally:
        close_page(opened)


def test_a_wrong_secret_is_refused_on_the_sign_in_form(secured_live, browser):
    opened = new_page(browser)
    try:
        page = opened.page
        page.goto(secured_live.urls.api)
        page.fill("#name", OPERATOR[0])
        page.fill("#secret", "not-the-secret")
        page.click("#sign-in")
        expect(page.locator("#error")).to_have_text("wrong name or secret")
        assert "/login" in page.url
    finally:
        close_page(opened)


def test_an_observer_watches_the_team_but_land_all_is_refused(secured_live, browser):
    live = secured_live
    assert_flying(live)
    opened = sign_in(browser, live.urls.api, OBSERVER, ui=live.ui)
    try:
        frame = opened.operator
        open_tab(frame, "Team")
        expect(frame.locator("tr[data-vehicle]")).to_have_count(3)  # watching works: a row per MAV
        assert opened.page.request.get(f"{live.urls.api}api/state").status == 200
        before, start = digest(live), len(live.station.recent_audit)
        frame.get_by_text("LAND ALL", exact=True).click()
        expect(frame.get_by_text("only an operator may command", exact=False)).to_be_visible()
        expect(frame.get_by_role("button", name="Confirm LAND ALL")).to_have_count(0)
        open_tab(frame, "Formation")
        frame.get_by_text("Stop formation (hold)", exact=True).click()
        deadline = time.monotonic() + 20.0
        while len(audit_since(live, start)) < 2:  # the click reached the station and was refused
            assert time.monotonic() < deadline, "the second refused command was not audited within 20 s"
            time.sleep(0.1)
        # notifications close after 6 s: on a loaded machine the first may be gone when the second shows
        expect(frame.get_by_text("only an operator may command", exact=False).last).to_be_visible()
        assert digest(live) == before
        refused = [(r.command, r.operator, r.role, r.surface, r.accepted) for r in audit_since(live, start)]
        assert refused == [
            ("land_all", "bob", "observer", "page", False),
            ("set_formation_enabled", "bob", "observer", "page", False),
        ]
    finally:
        close_page(opened)
    assert_flying(live)


@contextmanager
def foreign_site(html: str) -> Iterator[str]:
    """Serve `html` at / from a second local web server on a free port: another origin than the station's."""
    body = html.encode()

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # noqa: N802 - the http.server interface
            self.send_response(200)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, format: str, *args: object) -> None:  # noqa: A002 - the base's name
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(5.0)


def attack_page(live: Live) -> str:
    """A page that, once opened, submits a form to POST /api/land_all (classic cross-site request forgery),
    fetches POST /api/land_all and /api/formation/start with the browser's cookies, and opens the stream, the
    operator page's socket and viser's internal port; it writes what it saw into #results."""
    target = live.urls.api.rstrip("/")
    viser_url, protocol = viser_socket(live)
    return f"""<!doctype html><html><body><pre id="results">running</pre>
<iframe name="sink" style="display:none"></iframe>
<form id="csrf" method="POST" action="{target}/api/land_all" enctype="text/plain" target="sink">
<input type="hidden" name='{{"x":"' value='"}}'></form>
<script>
const probe = {PROBE_SOCKET_JS};
async function post(path) {{
  try {{
    await fetch("{target}" + path, {{method: "POST", mode: "no-cors", credentials: "include",
                                     headers: {{"content-type": "text/plain"}}, body: "{{}}"}});
    return "sent";
  }} catch (error) {{ return "failed: " + error; }}
}}
(async () => {{
  document.getElementById("csrf").submit();
  const results = {{
    land_all: await post("/api/land_all"),
    formation_start: await post("/api/formation/start"),
    stream: await probe(["{target.replace("http", "ws", 1)}/ws", null]),
    operator: await probe(["{target.replace("http", "ws", 1)}/operator", null]),
    viser: await probe(["{viser_url}", "{protocol}"]),
  }};
  document.getElementById("results").textContent = JSON.stringify(results);
}})();
</script></body></html>"""


def test_a_page_of_another_origin_cannot_land_start_formation_or_open_the_stream(secured_live, browser):
    live = secured_live
    assert_flying(live)
    live.station.set_formation_enabled(False)  # every MAV holds: starting the formation would be a change
    victim = new_page(browser)  # the operator's own browser, signed in
    try:
        signed = victim.page.request.post(
            f"{live.urls.api}auth/login", data={"name": OPERATOR[0], "secret": OPERATOR[1]}
        )
        assert signed.status == 200
        victim.page.goto(f"{live.urls.api}login")
        before, start = digest(live), len(live.station.recent_audit)
        assert before[1] is False and all(in_air for *_, in_air in before[3])
        attacker = victim.page.context.new_page()
        with foreign_site(attack_page(live)) as url:
            attacker.goto(url)
            expect(attacker.locator("#results")).not_to_have_text("running", timeout=4 * SOCKET_TIMEOUT_MS)
        results = json.loads(attacker.locator("#results").text_content() or "")
        live.wait_for(
            lambda: sum(r.command == "POST /api/land_all" for r in audit_since(live, start)) >= 2,
            sim_s=20.0,
            what="the form and the fetch reach the station",
        )
        assert digest(live) == before
        for name in ("stream", "operator"):
            assert (results[name]["opened"], results[name]["messages"]) == (False, 0), name
        assert (results["viser"]["messages"], results["viser"]["code"]) == (0, 1008)
        own = victim.page.evaluate(PROBE_SOCKET_JS, [ws_url(live, "ws"), None])
        assert own["opened"] and own["messages"] > 0, own  # the station's own page opens the same stream
        refused = audit_since(live, start)
        assert {r.command for r in refused} == {"POST /api/land_all", "POST /api/formation/start"}
        assert all(not r.accepted and "another origin" in r.message for r in refused)
        assert {r.operator for r in refused} == {OPERATOR[0]}  # the session cookie came along: still refused
    finally:
        close_page(victim)
        live.station.set_formation_enabled(True)
    live.wait_for(lambda: live.phases() == {Phase.FORMATION}, sim_s=20.0, what="back in formation")


def test_an_operator_lands_every_mav_with_land_all(secured_live, browser):
    live = secured_live
    assert_flying(live)
    opened = sign_in(browser, live.urls.api, OPERATOR, ui=live.ui)
    try:
        start = len(live.station.recent_audit)
        opened.operator.get_by_text("LAND ALL", exact=True).click()
        opened.operator.get_by_role("button", name="Confirm LAND ALL").click()
        expect(opened.operator.get_by_text("All MAVs landing")).to_be_visible()
        live.wait_for(lambda: live.phases() == {Phase.LANDED}, sim_s=40.0, what="every MAV landed")
    finally:
        close_page(opened)
    assert all(v.autopilot is not None and not v.autopilot.in_air for v in live.station.snapshot().vehicles)
    accepted = [(r.command, r.operator, r.role, r.surface, r.accepted) for r in audit_since(live, start)]
    assert accepted == [("land_all", "alice", "operator", "page", True)]


def ws_url(live: Live, path: str) -> str:
    """The WebSocket URL of `path` on the station's front."""
    return live.urls.api.replace("http", "ws", 1) + path
