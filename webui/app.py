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
import viser.infra

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
        # viser's own connect hook runs in its event loop before it sends a new client anything (the
        # public on_client_connect runs only after the client has received the whole scene)
        self._websock = self.server._websock_server  # noqa: SLF001
        self._websock.on_client_connect(self._admit)
        self._websock.on_client_disconnect(lambda conn: self.access.client_disconnected(conn.client_id))
        self.scene = SceneRenderer(self.server.scene, sigma=sigma)
        self.panel = OperatorPanel(self.server, actions, initial, access=self.access)
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
            self.scene.draw(view)
            self.panel.refresh(view)

    def stop(self) -> None:
        """Close viser's server and threads."""
        with contextlib.redirect_stdout(io.StringIO()):  # viser announces its stop on stdout
            self.server.stop()
