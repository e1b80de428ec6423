"""The operator's page: one viser server with the 3-D scene and the control panel, fed with `SceneView`s.

viser serves its own page and WebSocket on its own port from a daemon thread; `publish` may be called from
any thread (the ground station calls it from its asyncio loop at about 10 Hz) and applies a whole frame
atomically. Layout: the control panel docked on the right (its tabs scroll on their own), the Mission window
with LAND ALL floating at the bottom left of the 3-D view (`webui.panels`). A new page opens with its camera
framing the formation (`webui.camera`). With a `ClientAccess`, each viser client's connection is matched to
the operator it was forwarded for (the ticket header the ground station's front puts on it), and every
control acts on that operator's behalf.
"""

from __future__ import annotations

import contextlib
import io
import threading
from dataclasses import dataclass

import viser
import viser.infra

from webui.access import ClientAccess, OpenAccess
from webui.camera import FOV_RAD, CameraDirector, formation_frame, orbit_pose
from webui.early_input import EarlyInput
from webui.panels import CONTROL_PANEL_WIDTH_PX, OperatorPanel
from webui.scene import SceneRenderer
from webui.view import OperatorActions, SceneView
from webui.wakeup import wake_safely

TICKET_HEADER = "X-Skyring-Ticket"
"""The header on a forwarded viser connection that names the signed-in browser behind it."""


@dataclass(frozen=True)
class HemisphereLight:
    """A sky-to-ground light (three.js HemisphereLight): colours as RGB 0-255, intensity as three.js's."""

    name: str
    sky_color: tuple[int, int, int]
    ground_color: tuple[int, int, int]
    intensity: float


SKY_LIGHT = HemisphereLight(
    "/lights/sky", sky_color=(255, 255, 255), ground_color=(150, 140, 120), intensity=2.5
)
"""What lights the scene, with viser's default lights, in place of its environment map: a white sky over
warm ground, as bright as the map left the trees, MAVs and ellipsoid. Measured in chromium rendering WebGL in
software (2 cores, 2026-12-06): once the page showed its controls, the map kept the page's thread busy for
another 4.5-5.3 s (prefiltering it; no click is answered meanwhile), the light for at most 0.36 s; and each
frame costs about 40 % less (0.27 against 0.47 of a core at the same frame rate)."""


class OperatorUi:
    """Owns the viser server, the scene renderer and the control panel.

    host/port: where viser listens (port 0 picks a free port; a busy port makes viser take the next free
    one: read `port` for the real one). sigma: size of the covariance ellipsoid in standard deviations.
    shadows: cast shadows (off by default: without a GPU they halve the browser's frame rate).
    environment_map: light the scene with viser's default HDRI environment map instead of `SKY_LIGHT` (off by
    default: without a GPU the page prefilters the map for about 5 s after it shows, and every frame costs
    about 40 % more; the hemisphere light gives the same colours). access: who each client is (default:
    every client is an operator, for a station on loopback without sign-in).
    """

    def __init__(
        self,
        *,
        actions: OperatorActions,
        initial: SceneView,
        host: str = "127.0.0.1",
        port: int = 8080,
        sigma: float = 2.0,
        shadows: bool = False,
        environment_map: bool = False,
        access: ClientAccess | None = None,
    ) -> None:
        with contextlib.redirect_stdout(io.StringIO()):  # viser prints its own URL box; callers print ours
            self.server = viser.ViserServer(
                host=host, port=port, label="skyring ground station", verbose=False
            )
        wake_safely(self.server)  # before any page connects: see webui.wakeup
        self.server.gui.configure_theme(
            control_width="large", show_share_button=False, show_logo=False, dark_mode=False
        )
        self.server.gui.main_panel.dock_right()
        self.server.gui.main_panel.set_width(CONTROL_PANEL_WIDTH_PX)
        center, radius = formation_frame(initial)
        pose = orbit_pose(center, radius)
        self.server.initial_camera.fov = FOV_RAD
        self.server.initial_camera.up = pose.up
        self.server.initial_camera.position = tuple(pose.position_m)
        self.server.initial_camera.look_at = tuple(pose.look_at_m)
        self.server.scene.configure_default_lights(cast_shadow=shadows)
        if not environment_map:
            self.server.scene.configure_environment_map(hdri=None)
            self.server.scene.add_light_hemisphere(
                SKY_LIGHT.name,
                sky_color=SKY_LIGHT.sky_color,
                ground_color=SKY_LIGHT.ground_color,
                intensity=SKY_LIGHT.intensity,
            )
        self._lock = threading.Lock()
        self.access = access or OpenAccess()
        # viser's own connect hook runs in its event loop before it sends a new client anything (the
        # public on_client_connect runs only after the client has received the whole scene)
        self._websock = self.server._websock_server  # noqa: SLF001
        self._websock.on_client_connect(self._admit)
        self._websock.on_client_disconnect(lambda conn: self.access.client_disconnected(conn.client_id))
        self._latest = initial
        self.camera = CameraDirector()
        self.scene = SceneRenderer(self.server.scene, sigma=sigma, on_vehicle_click=self._on_vehicle_click)
        self.panel = OperatorPanel(
            self.server, actions, initial, camera=self.camera, sigma=sigma, access=self.access
        )
        # what a page sends before its first camera report (viser would drop it) runs once viser knows it
        self.early_input = EarlyInput(self.server)
        self.server.on_client_connect(self._on_connect)
        self.server.on_client_disconnect(lambda client: self.camera.forget(client.client_id))
        self.publish(initial)

    async def _admit(self, connection: viser.infra.WebsockClientConnection) -> None:
        """Match a new connection to its operator by its ticket header; close it at once, before viser
        sends it the scene, when `access` does not admit it."""
        socket = self._websock._live_connections.get(connection.client_id)  # noqa: SLF001
        request = getattr(socket, "request", None)
        ticket = request.headers.get(TICKET_HEADER) if request is not None else None
        if not self.access.client_connected(connection.client_id, ticket) and socket is not None:
            await socket.close(1008, "connect through the ground station's own page (sign-in)")

    @property
    def port(self) -> int:
        """The TCP port viser really listens on."""
        return self.server.get_port()

    def publish(self, view: SceneView) -> None:
        """Draw `view` in every connected browser as one atomic update."""
        with self._lock, self.server.atomic():
            self._latest = view
            self.scene.draw(view)
            self.panel.refresh(view)
            self.camera.update(self.server.get_clients(), view)

    def stop(self) -> None:
        """Close viser's server and threads."""
        with contextlib.redirect_stdout(io.StringIO()):  # viser announces its stop on stdout
            self.server.stop()

    def _on_connect(self, client: viser.ClientHandle) -> None:
        """Once a new page reports its camera, frame the formation as it is now (not as it was at start)."""
        framed = threading.Event()

        def frame(_: object) -> None:
            if framed.is_set():
                return
            framed.set()
            with contextlib.suppress(AssertionError, ValueError):  # the page went away meanwhile
                self.camera.frame_formation(client, self._latest)

        client.camera.on_update(frame)

    def _on_vehicle_click(self, vehicle_id: int, client: viser.ClientHandle | None) -> None:
        self.panel.select_vehicle(vehicle_id, client)
