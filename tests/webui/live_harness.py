"""Harness for the browser tests: a live ground station served exactly as `skyring serve` serves it (the same
`serve_station` path, in a background thread, faster than real time), and helpers to drive its page."""

from __future__ import annotations

import asyncio
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from playwright.sync_api import Browser, FrameLocator, Locator, Page
from viser import transforms as tf

from server.station.api.gate import Gate
from server.station.api.users import Users, user_line
from server.station.ground_station import GroundStation
from server.station.live import Urls, serve_station
from vehicles.mission import Phase
from vehicles.sim.scenario import Scenario, SimSetup, build_sim
from webui.access import Role
from webui.app import OperatorUi

RATE_HZ = 20.0  # control rate of the live station in these tests (20 Hz; the MPC's own step is 0.1 s)
SPEED = 4.0  # simulated seconds per wall second
ACTION_TIMEOUT_MS = 90_000
"""A click, key press or navigation may wait this long (Playwright's default is 30 s): beside the parallel
suite a software-rendered page can leave its thread to the renderer for half a minute (seen on CI and here
with the CPU loaded). No test bounds latency through it: the latency tests (marked `alone`) give their own
time-outs."""
PAGE_LOAD_TIMEOUT_MS = 60_000  # the viser page on a software renderer, on a 2-core machine shared with others
ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
    # software WebGL on a busy machine can stall past the GPU watchdog; a killed GPU process (three in a
    # session) would leave every later page of the session without WebGL
    "--disable-gpu-watchdog",
    "--disable-gpu-process-crash-limit",
]


OPERATOR = ("alice", "alice-secret-1")  # name, secret
OBSERVER = ("bob", "bob-secret-22")


def signed_in_gate() -> Gate:
    """A gate that requires sign-in, with OPERATOR (role operator) and OBSERVER (role observer)."""
    text = "\n".join(
        [
            user_line(OPERATOR[0], Role.OPERATOR, OPERATOR[1]),
            user_line(OBSERVER[0], Role.OBSERVER, OBSERVER[1]),
        ]
    )
    return Gate(Users.parse(text, source="test users"))


@dataclass
class Live:
    """A running ground station: its station, URLs and viser UI, and the thread that serves them."""

    station: GroundStation
    urls: Urls
    ui: OperatorUi
    stop: Callable[[], None]
    setup: SimSetup | None = None
    speed: float = SPEED
    pages: list[Page] = field(default_factory=list)

    def wait_for(self, condition: Callable[[], bool], *, sim_s: float, what: str) -> float:
        """Wait until condition() holds; fail if sim_s of simulated time pass first (or, should the simulation
        stall, five times the wall time that should take). Returns the simulated seconds it took."""
        start, wall_start = self.station.time_s, time.monotonic()
        while not condition():
            assert self.station.time_s - start < sim_s, f"{what}: not within {sim_s} s of simulated time"
            stalled = time.monotonic() - wall_start > 5.0 * sim_s / self.speed + 10.0
            assert not stalled, f"{what}: the simulation stalled"
            time.sleep(0.05)
        return self.station.time_s - start

    def mean_horizontal_distance_m(self) -> float:
        with self.station.lock:
            snap = self.station.snapshot()
            assert snap.person_truth is not None
            person = snap.person_truth.position_m[:2]
            flying = [v.autopilot.position_m[:2] for v in snap.vehicles if v.autopilot is not None]
            return float(np.mean([np.hypot(*(p - person)) for p in flying]))

    def phases(self) -> set[Phase]:
        return {v.phase for v in self.station.snapshot().vehicles}


def start_live(
    *,
    vehicles: int = 3,
    seed: int = 5,
    speed: float = SPEED,
    rate_hz: float = RATE_HZ,
    trees: str = "paper",
    gate: Gate | None = None,
) -> tuple[Live, threading.Thread]:
    """Serve a simulated team in a background thread (gate: sign-in rules; None: open, loopback only)."""
    setup = build_sim(Scenario(vehicles=vehicles, seed=seed, trees=trees), clock=time.perf_counter)
    station = GroundStation(mission=setup.mission, control_period_s=1.0 / rate_hz)
    ready = threading.Event()
    box: dict[str, Any] = {}
    loop = asyncio.new_event_loop()
    stop_event = asyncio.Event()

    def on_ready(urls: Urls, ui: object) -> None:
        box.update(urls=urls, ui=ui)
        ready.set()

    def serve() -> None:
        asyncio.set_event_loop(loop)
        try:
            box["stats"] = loop.run_until_complete(
                serve_station(
                    station,
                    host="127.0.0.1",
                    port=0,
                    viser_port=0,
                    speed=speed,
                    stop=stop_event,
                    on_ready=on_ready,
                    handle_signals=False,
                    gate=gate,
                )
            )
        except BaseException as exc:  # noqa: BLE001 - reported to the test thread below
            box["error"] = exc
            ready.set()
        finally:
            loop.close()

    thread = threading.Thread(target=serve, name="ground-station", daemon=True)
    thread.start()
    assert ready.wait(30.0), "the ground station did not start within 30 s"
    error = box.get("error")
    if isinstance(error, BaseException):
        raise error
    urls = box["urls"]
    assert isinstance(urls, Urls)

    def stop() -> None:
        loop.call_soon_threadsafe(stop_event.set)

    live = Live(station=station, urls=urls, ui=box["ui"], stop=stop, setup=setup, speed=speed)
    STARTED.append(live)
    return live, thread


STARTED: deque[Live] = deque(maxlen=2)  # the ground stations this process started last, for `delivery_report`


@dataclass
class OpenPage:
    """A browser page on the landing page, with everything it logged and requested, and its viser client.

    console: every console line of the page and its frames, stamped with wall-clock seconds (a failing
    browser test prints the newest of them: `recent_console`)."""

    page: Page
    console_errors: list[str]
    requests: list[str]
    client: object = None
    embedded: bool = True
    console: list[str] = field(default_factory=list)

    @property
    def operator(self) -> FrameLocator | Page:
        """The operator page: the landing page's embedded one (`open_page`), or the page itself
        (`open_operator`)."""
        return self.page.frame_locator("#operator-view") if self.embedded else self.page


OPENED: list[OpenPage] = []  # every page this process opened, for `recent_console`


def recent_console(pages: int = 4, lines: int = 40) -> str:
    """The newest console lines of the pages opened last (what a failing test's report shows: viser logs its
    websocket's connects and disconnects there), without the software renderer's GL driver notes."""
    parts = []
    for n, opened in list(enumerate(OPENED, 1))[-pages:]:
        kept = [line for line in opened.console if "GL Driver Message" not in line][-lines:]
        parts.append(f"page {n} ({'closed' if opened.page.is_closed() else 'open'}):\n" + "\n".join(kept))
    return "\n".join(parts)


PAGE_STATE_JS = """
() => new Promise(resolve => {
  const mutable = window.__viserMutable;
  let frames = 0;
  const count = () => { frames += 1; requestAnimationFrame(count); };
  requestAnimationFrame(count);
  setTimeout(() => resolve({
    queued: mutable ? mutable.messageQueue.length : 'no viewer',
    render: mutable ? mutable.getRenderRequestState : 'no viewer',
    drain: mutable ? mutable.drainMessageQueue !== null : 'no viewer',
    hidden: document.hidden,
    framesIn1s: frames,
  }), 1000);
})
"""


def delivery_report() -> str:
    """Where the station's updates stand on their way to each open page, for a failing test's report: per
    station, viser's broadcast buffer (messages pushed, atomic blocks open) and how far each client's sender
    has got; per open page, what waits in viser's queue, its render state and how many animation frames ran
    in one second. A page that stops showing updates is then seen to be the station's side or the page's."""
    parts = []
    for live in STARTED:
        websock = live.ui.server._websock_server  # noqa: SLF001 - diagnosis only
        buffer = websock._broadcast_buffer  # noqa: SLF001
        clients = {
            cid: (state.message_buffer.message_counter, state.message_buffer.atomic_counter)
            for cid, state in websock._client_state_from_id.items()  # noqa: SLF001
        }
        parts.append(
            f"station on {live.urls.operator}: broadcast pushed {buffer.message_counter}, atomic "
            f"{buffer.atomic_counter}, sent up to {dict(buffer.generator_cursors)}; own buffers (pushed, "
            f"atomic) {clients}"
        )
    for n, opened in enumerate(OPENED, 1):
        if opened.page.is_closed():
            continue
        try:
            state = opened.page.wait_for_function(PAGE_STATE_JS, timeout=5_000).json_value()
        except Exception as exc:  # noqa: BLE001 - a page that does not answer is the finding
            state = f"no answer within 5 s ({type(exc).__name__})"
        parts.append(f"page {n} ({opened.page.url}): {state}")
    return "\n".join(parts)


FRAME_CAP_FPS = 10
"""The pages' animation frames in these tests, per second at most (see `FRAME_CAP`)."""
FRAME_CAP = f"""(() => {{
  const gap = 1000 / {FRAME_CAP_FPS};
  const raf = window.requestAnimationFrame.bind(window);
  let queue = new Map(), next = 1, pending = false, last = -Infinity;
  const run = (t) => {{
    if (t - last < gap - 2) {{ setTimeout(() => raf(run), gap - (t - last)); return; }}
    last = t;
    pending = false;
    const due = queue;
    queue = new Map();
    for (const callback of due.values()) {{
      try {{ callback(t); }} catch (error) {{ setTimeout(() => {{ throw error; }}); }}
    }}
  }};
  window.requestAnimationFrame = (callback) => {{
    const id = next++;
    queue.set(id, callback);
    if (!pending) {{ pending = true; raf(run); }}
    return id;
  }};
  window.cancelAnimationFrame = (id) => {{ queue.delete(id); }};
}})();"""
"""Every page's `requestAnimationFrame` (the page's own, not Playwright's) runs at most FRAME_CAP_FPS times a
second, its callbacks batched into one frame as the browser batches them. Why: viser renders the 3-D view for
a quarter of a second after every scene update, and the station updates it ten times a second, so the view
renders without pause, as fast as the CPU allows. Chromium renders WebGL in software here, and one open page
then kept 1.3 of the machine's two cores busy (measured with viser's environment map: 36 ms of CPU per frame
at SOFTWARE_GL_DPR 0.25, 56 ms at 0.5); at 10 frames a second it needs a quarter of that. The page shows the
same scene and controls, a frame at most 0.1 s late; viser handles its queued messages once per frame, so none
is lost."""


def _recording(browser: Browser, viewport: tuple[int, int]) -> OpenPage:
    context = browser.new_context(viewport={"width": viewport[0], "height": viewport[1]})
    context.add_init_script(FRAME_CAP)
    context.set_default_timeout(ACTION_TIMEOUT_MS)
    page = context.new_page()
    opened = OpenPage(page=page, console_errors=[], requests=[])
    OPENED.append(opened)
    page.on("console", lambda m: opened.console_errors.append(m.text) if m.type == "error" else None)
    page.on("console", lambda m: opened.console.append(f"{time.time():.3f} {m.type}: {m.text}"))
    page.on("pageerror", lambda e: opened.console_errors.append(str(e)))
    page.on("request", lambda r: opened.requests.append(r.url))
    page.on("websocket", lambda ws: opened.requests.append(ws.url))
    return opened


SOFTWARE_GL_DPR = 0.25  # see open_operator and FRAME_CAP


def software_gl(url: str) -> str:
    """`url` (a station page without a query) asking for the 3-D view at `SOFTWARE_GL_DPR`."""
    return f"{url}?fixedDpr={SOFTWARE_GL_DPR:g}"


def wait_for_operator_view(opened: OpenPage, *, ui=None) -> OpenPage:
    """Wait for the operator page's canvas and controls (embedded or the page itself: `opened.operator`);
    with the station's `ui`, also find the page's viser client (the one that connected last)."""
    view = opened.operator
    view.locator("canvas").first.wait_for(state="visible", timeout=PAGE_LOAD_TIMEOUT_MS)
    view.get_by_text("LAND ALL", exact=True).wait_for(state="visible", timeout=PAGE_LOAD_TIMEOUT_MS)
    settle(opened.page)
    if ui is not None:
        opened.client = newest_client(ui)
    return opened


def new_page(browser: Browser, viewport: tuple[int, int] = (1100, 700)) -> OpenPage:
    """A page in a new browser context (its own cookies), recording console errors, page errors and every
    request URL."""
    return _recording(browser, viewport)


def open_page(browser: Browser, url: str, *, ui=None, viewport: tuple[int, int] = (1100, 700)) -> OpenPage:
    """Open the landing page `url` in a new context, recording console errors, page errors and every request
    URL; wait for the embedded operator page's canvas and controls. With the station's `ui`, also find the
    page's viser client (the one that connected last). The landing page hands its `fixedDpr` on to the
    embedded view, which renders at a quarter of the resolution (see `open_operator`)."""
    opened = _recording(browser, viewport)
    opened.page.goto(software_gl(url))
    return wait_for_operator_view(opened, ui=ui)


def sign_in(browser: Browser, url: str, user: tuple[str, str], *, ui=None) -> OpenPage:
    """Open the landing page `url` of a station that requires sign-in, as a browser would: it sends the page
    to the sign-in form; type `user` (name, secret) into it, and wait for the operator view."""
    opened = new_page(browser)
    opened.page.goto(software_gl(url))
    opened.page.wait_for_url(f"**/login?next=/%3FfixedDpr%3D{SOFTWARE_GL_DPR:g}")  # the display setting kept
    opened.page.fill("#name", user[0])
    opened.page.fill("#secret", user[1])
    opened.page.click("#sign-in")
    opened.page.wait_for_url(software_gl(url))
    return wait_for_operator_view(opened, ui=ui)


def open_operator(browser: Browser, url: str, *, viewport: tuple[int, int], ui=None) -> OpenPage:
    """Open the operator page itself (viser's URL, as `skyring serve` prints it) full window at `viewport`,
    recording console errors and requests; wait for its canvas and LAND ALL. The 3-D view renders at
    SOFTWARE_GL_DPR (viser's `fixedDpr`: a quarter of the resolution; the panels are unaffected) and at most
    FRAME_CAP_FPS frames a second: chromium renders WebGL in software here, and at full resolution on a busy
    two-core machine the renderer keeps the page's thread so busy that every step of a test waits seconds
    for it. Per frame it cost 36 ms of CPU at 0.25, 56 ms at 0.5 and 120 ms at 1 (2026-12-06, with viser's
    environment map, which the scene no longer uses: `webui.app.SKY_LIGHT`)."""
    opened = _recording(browser, viewport)
    opened.embedded = False
    opened.page.goto(software_gl(url))
    return wait_for_operator_view(opened, ui=ui)


def settle(page: Page) -> None:
    """Wait until the page draws frames again: right after loading, chromium's software WebGL compiles the
    scene's shaders and the page answers nothing for seconds on a busy machine."""
    page.wait_for_function(
        "() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(true))))",
        timeout=PAGE_LOAD_TIMEOUT_MS,
    )


def close_page(opened: OpenPage) -> None:
    opened.page.context.close()


def scene_canvas(frame: FrameLocator | Page) -> Locator:
    """The 3-D canvas of the operator page (three.js renders it; the GUI's plots are canvases too)."""
    return frame.locator('canvas[data-engine^="three.js"]')


def number_input(frame: FrameLocator | Page, label: str) -> Locator:
    """The number box of the viser slider or number input labelled `label`."""
    return frame.get_by_text(label, exact=True).locator(
        "xpath=ancestor::div[contains(@class,'mantine-Flex-root')][1]//input[contains(@class,'NumberInput-input')]"
    )


def newest_client(ui) -> object:
    """The viser client that connected last (the page a test just opened)."""
    clients = ui.server.get_clients()
    return clients[max(clients)]


def ground_to_canvas_fraction(camera, point_m: np.ndarray) -> tuple[float, float]:
    """Where the world point appears in a client's canvas, as fractions of its width and height (OpenCV
    pinhole: viser's camera looks along +z with +y down; fov is vertical)."""
    r = tf.SO3(np.asarray(camera.wxyz)).as_matrix()
    p = r.T @ (np.asarray(point_m, dtype=float) - np.asarray(camera.position))
    assert p[2] > 0, "the point is behind the camera"
    t = math.tan(camera.fov / 2.0)
    return 0.5 + p[0] / p[2] / (2.0 * t * camera.aspect), 0.5 + p[1] / p[2] / (2.0 * t)


def open_tab(root: Page | FrameLocator, name: str) -> None:
    """Show the control panel's tab `name`. By keyboard (Enter on the tab, which `press` focuses first: a
    separate focus() cost one more round trip to a busy page): a pointer press on a tab starts viser's tab
    drag, which a busy software-rendered page can take for a drag."""
    from playwright.sync_api import expect

    tab = root.get_by_role("tab", name=name, exact=True)
    tab.press("Enter")
    expect(tab).to_have_attribute("aria-selected", "true")
