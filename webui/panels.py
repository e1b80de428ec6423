"""The operator's controls in viser's GUI.

Two windows:
- the **Mission** window, floating at the bottom left of the 3-D view, apart from every scrolling list: the
  header (mission time, UTC, recording with the log's path, real-time factor), the alert summary and
  **LAND ALL**. Shift+L (a viser command hotkey, handled in the page itself: nothing is loaded from outside)
  opens the same confirmation as the button. It stays where it is whatever the other panel scrolls to,
  with 3 or 16 MAVs.
- the control panel, docked on the right, in tabs: Team (`team_panel`: the table of MAVs, one MAV's detail
  with Hold / Land / Release), Alerts (`alerts_panel`), Formation (d_des / h_des, start / stop, virtual
  obstacles), View (camera: frame the formation, follow the person, top-down; the colour legend; the
  ellipsoid's size; the team origin) and Plots (`plots`).

Every control calls the same `OperatorActions` the REST API calls; a refusal (ValueError) becomes a
notification to the client that asked, and the control snaps back to the ground station's value. Every
control acts on behalf of the client's signed-in operator (`webui.access`): the ground station refuses (and
audits) a command from a client that is not signed in as an operator. Whatever takes a MAV off the ground
(Start formation, Release of a landed MAV) or lands it (Land, LAND ALL) sits behind a per-client confirmation
modal, shown only to operators; when the pre-take-off checks (person keep-out, d_min) refuse a start or a
release, a second modal offers the logged override. viser runs these callbacks on its own threads, so the
actions object must be thread-safe (the ground station's is).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
import viser

from webui.access import ClientAccess, OpenAccess, acting_as
from webui.alerts_panel import AlertsPanel
from webui.camera import CameraDirector
from webui.cards import alert_summary_html, header_html, legend_html
from webui.geometry import ellipsoid_pose, ground_point
from webui.notifications import NotifyColor, notify, remove_notification
from webui.plots import LivePlots, PlotHistory
from webui.scene import LEGEND, ellipsoid_label
from webui.team_panel import TeamPanel
from webui.view import OperatorActions, SceneView

log = logging.getLogger(__name__)

LAND_ALL_HOTKEY = "L"
LAND_ALL_MODIFIER = "shift"
LAND_ALL_SHORTCUT = "Shift+L"
MISSION_WINDOW_WIDTH_PX = 430
CONTROL_PANEL_WIDTH_PX = 470


def status_line(view: SceneView) -> str:
    """Markdown summary at the top of the Formation tab: its state, the team in formation, d_des and h_des."""
    flying = sum(v.in_formation for v in view.vehicles)
    state = "running" if view.formation_enabled else "stopped (holding)"
    return (
        f"formation {state} · {flying}/{len(view.vehicles)} MAVs flying formation  \n"
        f"d_des {view.formation.d_des_m:.1f} m · h_des {view.formation.h_des_m:.1f} m"
    )


def view_info(view: SceneView, sigma: float) -> str:
    """Markdown of the View tab: the drawn ellipsoid's size and the team origin."""
    lines = []
    estimate = view.person_estimate
    size = "no estimate yet"
    if estimate is not None and np.all(np.isfinite(estimate.position_m)):
        try:
            semi_axes, _ = ellipsoid_pose(estimate.position_cov_m2, sigma=sigma)
            size = ellipsoid_label(2.0 * semi_axes, sigma)
        except ValueError:
            size = "covariance not finite"
    lines.append(f"person ellipsoid (full axes, {sigma:g} standard deviations): {size}")
    o = view.origin
    if o is None:
        lines.append("team origin: no geodetic origin (simulation: the local ENU frame only)")
    else:
        lines.append(
            f"team origin: {o.lat_deg:.6f}, {o.lon_deg:.6f} (lat, lon, WGS-84), {o.alt_m:.1f} m AMSL; "
            "x east, y north, z up"
        )
    return "  \n".join(lines)


class OperatorPanel:
    """Builds the GUI once from the first view and refreshes it from every later one (`refresh`)."""

    def __init__(
        self,
        server: viser.ViserServer,
        actions: OperatorActions,
        initial: SceneView,
        *,
        plot_every: int = 5,
        camera: CameraDirector | None = None,
        sigma: float = 2.0,
        access: ClientAccess | None = None,
    ) -> None:
        self._server = server
        self._actions = actions
        self._camera = camera or CameraDirector()
        self._sigma = sigma
        self._access = access or OpenAccess()
        self._lock = threading.Lock()
        # client id -> radius (m) of the obstacle it places and its "click" prompt (None until shown)
        self._pending_clicks: dict[int, tuple[float, viser.NotificationHandle | None]] = {}
        self._click_registered = False
        self._open_modals: dict[tuple[int, str], Any] = {}  # (client id, title) -> the modal shown
        self._view = initial
        self._shown_formation = initial.formation
        self._plot_every = plot_every
        self._refreshes = 0
        gui = server.gui
        self._build_mission_window(gui, initial)
        tabs = gui.add_tab_group()
        with tabs.add_tab("Team", viser.Icon.USERS) as team_tab:
            self.team = TeamPanel(gui, actions, initial, run=self._run, confirm=self._confirm)
        alerts_tab = tabs.add_tab("Alerts", viser.Icon.ALERT_TRIANGLE)
        self.alerts = AlertsPanel(gui, alerts_tab, actions, clicked=self.clicked, announce=self._announce)
        with tabs.add_tab("Formation", viser.Icon.CIRCLE_DOTTED):
            self._build_formation(gui, initial)
            self._build_obstacles(gui, initial)
        with tabs.add_tab("View", viser.Icon.CAMERA):
            self._build_view(gui, initial)
        with tabs.add_tab("Plots", viser.Icon.CHART_LINE):
            ids = [v.vehicle_id for v in initial.vehicles]
            self.history = PlotHistory(ids)
            self.plots = LivePlots(gui, ids, self.team.colors)
        del team_tab
        self.refresh(initial)

    # ---- building -----------------------------------------------------------------------------------------

    def _build_mission_window(self, gui: viser.GuiApi, initial: SceneView) -> None:
        # The shortcut first: a page that shows the button already answers Shift+L (the other way round, a
        # key pressed as the button appeared could be lost).
        self.land_all_command = gui.add_command(
            "LAND ALL",
            description="Land every MAV where it is (asks to confirm)",
            hotkey=LAND_ALL_HOTKEY,
            modifier=LAND_ALL_MODIFIER,
            icon=viser.Icon.PLANE_ARRIVAL,
        )
        self.land_all_command.on_trigger(self._on_land_all)
        self.mission_window = gui.add_panel()
        with self.mission_window.add_tab("Mission", viser.Icon.SHIELD_CHECK):
            self.header = gui.add_html(header_html(initial))
            self.alert_summary = gui.add_html(alert_summary_html(initial.alerts))
            self.land_all_button = gui.add_button(
                "LAND ALL",
                color="red",
                icon=viser.Icon.PLANE_ARRIVAL,
                hint=f"Land every MAV where it is (asks to confirm). Shortcut: {LAND_ALL_SHORTCUT}",
            )
            gui.add_markdown(
                f"Shortcut **{LAND_ALL_SHORTCUT}** (with the 3-D view focused) opens the same dialog."
            )
        self.mission_window.float(x=12, y=-12, width=MISSION_WINDOW_WIDTH_PX)
        self.land_all_button.on_click(self._on_land_all)

    def _build_formation(self, gui: viser.GuiApi, initial: SceneView) -> None:
        self._status = gui.add_markdown(status_line(initial))
        f = initial.formation
        self._d_des = gui.add_slider(
            "d_des (m)",
            min=initial.d_des_range_m.low,
            max=initial.d_des_range_m.high,
            step=0.1,
            initial_value=f.d_des_m,
            hint="Desired horizontal distance from the person",
        )
        self._h_des = gui.add_slider(
            "h_des (m)",
            min=initial.h_des_range_m.low,
            max=initial.h_des_range_m.high,
            step=0.1,
            initial_value=f.h_des_m,
            hint="Desired height above the person",
        )
        self._d_des.on_update(self._on_formation_input)
        self._h_des.on_update(self._on_formation_input)
        start = gui.add_button("Start formation", color="green", icon=viser.Icon.PLAYER_PLAY)
        stop = gui.add_button("Stop formation (hold)", icon=viser.Icon.PLAYER_PAUSE)
        start.on_click(self._on_start_formation)
        stop.on_click(
            self.clicked(
                lambda: self._actions.set_formation_enabled(False), "Formation stopped: MAVs hold position"
            )
        )

    def _build_obstacles(self, gui: viser.GuiApi, initial: SceneView) -> None:
        self._obstacle_folder = gui.add_folder("Virtual obstacles")
        with self._obstacle_folder:
            radii = initial.obstacle_radius_range_m
            self._radius = gui.add_number(
                "radius (m)",
                initial_value=min(max(1.0, radii.low), radii.high),
                min=radii.low,
                max=radii.high,
                step=0.1,
            )
            add = gui.add_button("Add obstacle, then click the ground", icon=viser.Icon.CIRCLE_PLUS)
            add.on_click(self._on_add_obstacle)
            self._obstacle_list = gui.add_markdown("none")
        self._obstacle_buttons: dict[str, Any] = {}

    def _build_view(self, gui: viser.GuiApi, initial: SceneView) -> None:
        frame = gui.add_button("Frame the formation", icon=viser.Icon.FOCUS_CENTERED)
        follow = gui.add_button("Follow the person (on / off)", icon=viser.Icon.WALK)
        top = gui.add_button("Top-down, north up", icon=viser.Icon.ARROW_BIG_DOWN_LINES)
        frame.on_click(lambda e: self._camera_action(e, "frame"))
        follow.on_click(lambda e: self._camera_action(e, "follow"))
        top.on_click(lambda e: self._camera_action(e, "top"))
        self._view_info = gui.add_markdown(view_info(initial, self._sigma))
        gui.add_html(legend_html(LEGEND + (("each MAV: its own colour (Team tab)", (31, 119, 180)),)))

    # ---- refresh from the ground station -------------------------------------------------------------------

    def refresh(self, view: SceneView) -> None:
        """Show `view`: header, alerts, team, formation, obstacles, view information, plots."""
        self._view = view
        _set(self.header, header_html(view))
        _set(self.alert_summary, alert_summary_html(view.alerts))
        self.team.refresh(view)
        self.alerts.refresh(view.alerts)
        _set(self._status, status_line(view))
        _set_range(self._d_des, view.d_des_range_m.low, view.d_des_range_m.high)
        _set_range(self._h_des, view.h_des_range_m.low, view.h_des_range_m.high)
        if view.formation != self._shown_formation:  # changed elsewhere (the API, another client)
            self._show_formation(view)
        self._refresh_obstacles(view)
        _set(self._view_info, view_info(view, self._sigma))
        self._record(view)

    def _refresh_obstacles(self, view: SceneView) -> None:
        virtual = [o for o in view.obstacles if o.kind == "virtual"]
        ids = [o.obstacle_id for o in virtual]
        if ids == list(self._obstacle_buttons):
            return
        for button in self._obstacle_buttons.values():
            button.remove()
        self._obstacle_buttons = {}
        lines = [
            f"- `{o.obstacle_id}` at ({o.center_m[0]:.1f}, {o.center_m[1]:.1f}) m, r {o.radius_m:.1f} m"
            for o in virtual
        ]
        self._obstacle_list.content = "\n".join(lines) if lines else "none"
        with self._obstacle_folder:
            for obstacle_id in ids:
                button = self._server.gui.add_button(f"Remove {obstacle_id}", icon=viser.Icon.TRASH)
                button.on_click(
                    self.clicked(
                        lambda oid=obstacle_id: self._actions.remove_obstacle(oid),
                        f"Obstacle {obstacle_id} removed",
                    )
                )
                self._obstacle_buttons[obstacle_id] = button

    def _record(self, view: SceneView) -> None:
        added = self.history.record(view)
        self._refreshes += 1
        if added and (len(self.history) <= 2 or self._refreshes % self._plot_every == 0):
            self.plots.push(self.history)

    # ---- operator input ------------------------------------------------------------------------------------

    def select_vehicle(self, vehicle_id: int, client: viser.ClientHandle | None) -> None:
        """A MAV was clicked in the 3-D view: show its detail in the Team tab."""
        del client
        self.team.select(vehicle_id)

    def _camera_action(self, event: viser.GuiEvent, what: str) -> None:
        client = event.client
        if client is None:
            return
        try:
            if what == "frame":
                self._camera.set_following(client, False, self._view)
                self._camera.frame_formation(client, self._view)
            elif what == "top":
                self._camera.top_down(client, self._view)
            else:
                follow = not self._camera.following(client.client_id)
                self._camera.set_following(client, follow, self._view)
                notify(
                    client,
                    "View",
                    "Following the person" if follow else "Stopped following the person",
                    color="blue",
                )
        except (AssertionError, ValueError) as exc:  # the client has not reported its camera yet
            notify(client, "View", f"the camera is not ready yet, try again ({exc})", color="red")

    def clicked(self, action: Callable[[], object], done: str | None) -> Callable[[viser.GuiEvent], None]:
        """A button callback that runs `action` for the client that clicked (see `_run`)."""

        def on_click(event: viser.GuiEvent) -> None:
            self._run(event.client, action, done)

        return on_click

    def _run(self, client: viser.ClientHandle | None, action: Callable[[], object], done: str | None) -> bool:
        """Run one operator action on behalf of the client's operator; tell the client the outcome. Never
        raises: a GUI callback must not die."""
        if client is None:  # not an operator's click (a programmatic update)
            return False
        try:
            with acting_as(self._access.principal_of(client.client_id).for_command()):
                action()
        except (ValueError, KeyError) as exc:
            notify(client, "Refused", str(exc), color="red")
            return False
        except Exception as exc:  # noqa: BLE001 - a bug in a command must not kill the GUI thread
            log.exception("operator action failed")
            notify(
                client,
                "Error",
                f"the ground station could not do this: {exc}",
                color="red",
            )
            return False
        if done:
            notify(client, "Done", done, color="green")
        return True

    def _announce(self, title: str, body: str, color: NotifyColor) -> None:
        for client in list(self._server.get_clients().values()):
            notify(client, title, body, color=color, seconds=8.0)

    def _on_formation_input(self, event: viser.GuiEvent) -> None:
        if event.client is None:  # our own refresh, not an operator
            return
        d_des, h_des = float(self._d_des.value), float(self._h_des.value)
        ok = self._run(event.client, lambda: self._actions.set_formation(d_des_m=d_des, h_des_m=h_des), None)
        if not ok:
            self._show_formation(self._view)

    def _show_formation(self, view: SceneView) -> None:
        """Show the station's values in the inputs (programmatic updates carry no client: not re-sent)."""
        self._shown_formation = view.formation
        self._d_des.value = view.formation.d_des_m
        self._h_des.value = view.formation.h_des_m

    def _on_start_formation(self, event: viser.GuiEvent) -> None:
        vehicles = self._view.vehicles
        grounded = [v.vehicle_id for v in vehicles if v.phase == "idle" and not v.in_air]
        found = [v.vehicle_id for v in vehicles if v.phase == "idle" and v.in_air]
        landed = [v.vehicle_id for v in vehicles if v.phase == "landed"]
        lines = [
            f"MAVs {', '.join(map(str, grounded))} **take off** and fly the formation."
            if grounded
            else "No MAV is waiting on the ground: the flying ones resume the formation."
        ]
        if found:
            lines.append(f"MAVs {', '.join(map(str, found))}, found flying, join it from where they are.")
        if landed:
            lines.append(f"Landed MAVs ({', '.join(map(str, landed))}) stay down until released.")
        client = event.client
        self._confirm(
            client,
            "Start formation?",
            "  \n".join(lines),
            "Start formation",
            lambda: self._start_formation(client),
            None,
        )

    def _start_formation(self, client: viser.ClientHandle | None) -> None:
        """Start the formation; when the pre-take-off checks refuse it, offer the logged override."""
        if self._run(client, lambda: self._actions.set_formation_enabled(True), "Formation started"):
            return
        held = [v for v in self._view.vehicles if v.takeoff_check and v.phase == "idle"]
        if held:
            self._confirm(
                client,
                "Start anyway?",
                "  \n".join(f"MAV {v.vehicle_id} {v.takeoff_check}" for v in held)
                + "  \nStarting anyway takes them off where they stand; the override is logged.",
                "Start anyway (override)",
                lambda: self._actions.set_formation_enabled(True, override=True),
                "Formation started: pre-take-off checks overridden (logged)",
            )

    def _on_add_obstacle(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        client_id = event.client.client_id
        with self._lock:
            _, stale = self._pending_clicks.get(client_id, (0.0, None))
            self._pending_clicks[client_id] = (float(self._radius.value), None)
            if not self._click_registered:
                self._server.scene.on_click()(self._on_scene_click)
                self._click_registered = True
        remove_notification(stale)
        # The prompt stays until the click arrives (or 60 s), then goes: never two prompts for one placement.
        prompt = notify(
            event.client,
            "Place obstacle",
            "Click on the ground where the obstacle should stand.",
            color="blue",
            seconds=60.0,
        )
        with self._lock:
            waiting = client_id in self._pending_clicks
            if waiting:
                self._pending_clicks[client_id] = (self._pending_clicks[client_id][0], prompt)
        if not waiting:  # the click came before the prompt was shown
            remove_notification(prompt)

    def _on_scene_click(self, event: viser.SceneClickEvent) -> None:
        with self._lock:
            radius, prompt = self._pending_clicks.pop(event.client_id, (None, None))
            if not self._pending_clicks and self._click_registered:
                self._server.scene.remove_click_callback(self._on_scene_click)
                self._click_registered = False
        remove_notification(prompt)
        if radius is None:
            return
        point = ground_point(np.asarray(event.ray_origin), np.asarray(event.ray_direction))
        if point is None:
            notify(
                event.client,
                "Refused",
                "That click did not hit the ground: press Add obstacle again and click on the grid.",
                color="red",
            )
            return
        x, y = float(point[0]), float(point[1])
        self._run(
            event.client,
            lambda: self._actions.add_obstacle(x_m=x, y_m=y, radius_m=radius),
            f"Obstacle of radius {radius:.1f} m added at ({x:.1f}, {y:.1f}) m",
        )

    def _on_land_all(self, event: Any) -> None:
        """The LAND ALL button or its Shift+L shortcut (a viser command event)."""
        self._confirm(
            event.client,
            "LAND ALL?",
            "Every MAV leaves the formation and lands where it is.",
            "Confirm LAND ALL",
            self._actions.land_all,
            "All MAVs landing",
        )

    def _confirm(
        self,
        client: viser.ClientHandle | None,
        title: str,
        body: str,
        confirm_label: str,
        action: Callable[[], object],
        done: str | None,
    ) -> None:
        """Ask the client that clicked to confirm in a modal; run `action` only on its confirm button (then
        notify `done`, unless None: the action tells the outcome itself). One modal per client and question:
        asking again while it is open does not stack another. A client that may not command gets no modal:
        the command goes straight to the ground station, which refuses and audits it."""
        if client is None:
            return
        if not self._access.principal_of(client.client_id).may_command:
            self._run(client, action, done)  # no modal: the ground station refuses and audits it
            return
        key = (client.client_id, title)
        with self._lock:
            if key in self._open_modals:
                return
            with client.gui.add_modal(title) as modal:
                client.gui.add_markdown(body)
                confirm = client.gui.add_button(confirm_label, color="red")
                cancel = client.gui.add_button("Cancel")
            self._open_modals[key] = modal

        def close() -> None:
            with self._lock:
                self._open_modals.pop(key, None)
            modal.close()

        def on_confirm(_: viser.GuiEvent) -> None:
            close()
            self._run(client, action, done)

        confirm.on_click(on_confirm)
        cancel.on_click(lambda _: close())


def _set(handle: Any, content: str) -> None:
    if handle.content != content:
        handle.content = content


def _set_range(slider: Any, low: float, high: float) -> None:
    if slider.min != low:
        slider.min = low
    if slider.max != high:
        slider.max = high
