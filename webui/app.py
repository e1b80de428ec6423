"""The operator's page: one viser server with the 3-D scene and the control panel, fed with `SceneView`s.

viser serves its own page and WebSocket on its own port from a daemon thread; `publish` may be called from
any thread (the ground station calls it from its asyncio loop at about 10 Hz) and applies a whole frame
atomically. Layout: the control panel docked on the right (its tabs scroll on their own), the Mission window
with LAND ALL floating at the bottom left of the 3-D view (`webui.panels`). A new page opens with its camera
framing the formation (`webui.camera`).
"""

from __future__ import annotations

import contextlib
import io
import threading

import viser

from webui.camera import FOV_RAD, CameraDirector, formation_frame, orbit_pose
from webui.panels import CONTROL_PANEL_WIDTH_PX, OperatorPanel
from webui.scene import SceneRenderer
from webui.view import OperatorActions, SceneView


class OperatorUi:
    """Owns the viser server, the scene renderer and the control panel.

    host/port: where viser listens (port 0 picks a free port; a busy port makes viser take the next free
    one: read `port` for the real one). sigma: size of the covariance ellipsoid in standard deviations.
    shadows: cast shadows (off by default: without a GPU they halve the browser's frame rate).
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
    ) -> None:
        with contextlib.redirect_stdout(io.StringIO()):  # viser prints its own URL box; callers print ours
            self.server = viser.ViserServer(
                host=host, port=port, label="skyring ground station", verbose=False
            )
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
        self._lock = threading.Lock()
        self._latest = initial
        self.camera = CameraDirector()
        self.scene = SceneRenderer(self.server.scene, sigma=sigma, on_vehicle_click=self._on_vehicle_click)
        self.panel = OperatorPanel(self.server, actions, initial, camera=self.camera, sigma=sigma)
        self.server.on_client_connect(self._on_connect)
        self.server.on_client_disconnect(lambda client: self.camera.forget(client.client_id))
        self.publish(initial)

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
