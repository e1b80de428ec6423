"""The operator's page: one viser server with the 3-D scene and the control panel, fed with `SceneView`s.

viser serves its own page and WebSocket on its own port from a daemon thread; `publish` may be called from
any thread (the ground station calls it from its asyncio loop at about 10 Hz) and applies a whole frame
atomically. With a `ClientAccess`, each viser client's connection is matched to the operator it was
forwarded for (the ticket header the ground station's front puts on it), and every control acts on that
operator's behalf.
"""

from __future__ import annotations

import contextlib
import io
import threading

import viser

from webui.access import ClientAccess, OpenAccess
from webui.panels import OperatorPanel
from webui.scene import SceneRenderer
from webui.view import OperatorActions, SceneView

TICKET_HEADER = "X-Skyring-Ticket"
"""The header on a forwarded viser connection that names the signed-in browser behind it."""


class OperatorUi:
    """Owns the viser server, the scene renderer and the control panel.

    host/port: where viser listens (port 0 picks a free port; a busy port makes viser take the next free
    one: read `port` for the real one). sigma: size of the covariance ellipsoid in standard deviations.
    shadows: cast shadows (off by default: without a GPU they halve the browser's frame rate). access:
    who each client is (default: every client is an operator, for a station on loopback without sign-in).
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
        access: ClientAccess | None = None,
    ) -> None:
        with contextlib.redirect_stdout(io.StringIO()):  # viser prints its own URL box; callers print ours
            self.server = viser.ViserServer(
                host=host, port=port, label="skyring ground station", verbose=False
            )
        self.server.gui.configure_theme(
            control_width="medium", show_share_button=False, show_logo=False, dark_mode=False
        )
        self.server.initial_camera.position = (9.0, -34.0, 30.0)
        self.server.initial_camera.look_at = (9.0, 0.0, 0.0)
        self.server.initial_camera.up = (0.0, 0.0, 1.0)
        self.server.scene.configure_default_lights(cast_shadow=shadows)
        self._lock = threading.Lock()
        self.access = access or OpenAccess()
        self.server.on_client_connect(self._on_connect)
        self.server.on_client_disconnect(lambda client: self.access.client_disconnected(client.client_id))
        self.scene = SceneRenderer(self.server.scene, sigma=sigma)
        self.panel = OperatorPanel(self.server, actions, initial, access=self.access)
        self.publish(initial)

    def _on_connect(self, client: viser.ClientHandle) -> None:
        # viser keeps each client's websocket connection (with its handshake) by client id
        connection = self.server._websock_server._live_connections.get(client.client_id)  # noqa: SLF001
        request = getattr(connection, "request", None)
        ticket = request.headers.get(TICKET_HEADER) if request is not None else None
        self.access.client_connected(client.client_id, ticket)

    @property
    def port(self) -> int:
        """The TCP port viser really listens on."""
        return self.server.get_port()

    def publish(self, view: SceneView) -> None:
        """Draw `view` in every connected browser as one atomic update."""
        with self._lock, self.server.atomic():
            self.scene.draw(view)
            self.panel.refresh(view)

    def stop(self) -> None:
        """Close viser's server and threads."""
        with contextlib.redirect_stdout(io.StringIO()):  # viser announces its stop on stdout
            self.server.stop()
