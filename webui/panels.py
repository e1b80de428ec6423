"""The operator's controls in viser's GUI: formation parameters, virtual obstacles, a card per vehicle with
Land/Release, LAND ALL, start/stop formation, and live plots of the fused covariance trace and tracking error.

Every control calls the same `OperatorActions` the REST API calls; a refusal (ValueError) becomes a
notification to the client that asked, and the control snaps back to the ground station's value. Landing,
LAND ALL and release sit behind a per-client confirmation modal. viser runs these callbacks on its own
threads, so the actions object must be thread-safe (the ground station's is).
"""

from __future__ import annotations

import logging
import math
import threading
from collections import deque
from collections.abc import Callable
from typing import Any, Literal

import numpy as np
import viser
import viser.uplot

from webui.geometry import ground_point
from webui.view import OperatorActions, SceneView, VehicleView

log = logging.getLogger(__name__)

PLOT_WINDOW_S = 120.0  # seconds of history the plots show
STALE_FLAG = "STALE"
FAILSAFE_FLAG = "FAILSAFE"  # the autopilot runs its own failsafe (PX4: Land, Hold, Return)
REFUSED_FLAG = "ARMING REFUSED"  # the autopilot refused the take-off; its reason follows
HELD_FLAG = "CANNOT TAKE OFF HERE"  # the pre-take-off checks (person keep-out, d_min) refuse it


AGENT_LOST_FLAG = "AGENT LOST"
SKEW_FLAG = "CLOCK SKEW"


def agent_line(vehicle: VehicleView) -> str:
    """The card's line about a networked agent: lost, clock skew, the latest command's outcome per vehicle."""
    a = vehicle.agent
    if a is None:
        return ""
    parts = [f"**{AGENT_LOST_FLAG}** ({a.age_s:.1f} s)" if a.lost else "agent ok"]
    if a.station_lost:
        parts.append("it lost the station")
    if a.clock_offset_s is not None:
        skew = f" **{SKEW_FLAG}**" if a.clock_skew else ""
        parts.append(f"clock {a.clock_offset_s * 1e3:+.0f} ms{skew}")
    if a.commands:
        command_id, action, outcome, message = a.commands[-1]
        parts.append(f"cmd {command_id} {action}: {outcome}" + (f" ({message})" if message else ""))
    return " · ".join(parts)


def vehicle_card(vehicle: VehicleView) -> str:
    """Markdown for one vehicle's card: phase, the autopilot's own mode, armed, link age (flagged when
    stale), solver, battery; for an onboard agent its link, clock and last command; then, when there is one,
    the autopilot's failsafe and why, why it refused to arm, and why the ground station would not let it take
    off where it stands."""
    link = f"{vehicle.link_age_s:.1f} s" + (f" **{STALE_FLAG}**" if vehicle.link_stale else "")
    solver = "-" if vehicle.solver_time_s is None else f"{vehicle.solver_time_s * 1e3:.2f} ms"
    battery = "unknown" if vehicle.battery_fraction is None else f"{vehicle.battery_fraction * 100:.0f} %"
    status = f" ({vehicle.solve_status})" if vehicle.solve_status else ""
    mode = vehicle.autopilot_mode or vehicle.mode
    formation = " · in formation" if vehicle.in_formation else ""
    lines = [
        f"**MAV {vehicle.vehicle_id}**: {vehicle.phase}{formation}",
        f"autopilot {mode}, {'armed' if vehicle.armed else 'disarmed'}, "
        f"{'in air' if vehicle.in_air else 'on ground'}",
        f"link {link} · solver {solver}{status} · battery {battery}",
    ]
    if vehicle.agent is not None:
        lines.append(agent_line(vehicle))
    if vehicle.failsafe:
        lines.append(f"**{FAILSAFE_FLAG}**: {vehicle.failsafe_reason or 'the autopilot runs its failsafe'}")
    if vehicle.arming_refusal:
        lines.append(f"**{REFUSED_FLAG}**: {vehicle.arming_refusal}")
    if vehicle.takeoff_check:
        lines.append(f"**{HELD_FLAG}**: {vehicle.takeoff_check}")
    return "  \n".join(lines)


def status_line(view: SceneView) -> str:
    """Markdown summary at the top of the panel: time, formation state and the team's size in formation."""
    flying = sum(v.in_formation for v in view.vehicles)
    state = "running" if view.formation_enabled else "stopped (holding)"
    return (
        f"t = {view.time_s:.1f} s · formation {state} · "
        f"{flying}/{len(view.vehicles)} MAVs flying formation  \n"
        f"d_des {view.formation.d_des_m:.1f} m · h_des {view.formation.h_des_m:.1f} m"
    )


class OperatorPanel:
    """Builds the GUI once from the first view and refreshes it from every later one (`refresh`)."""

    def __init__(
        self, server: viser.ViserServer, actions: OperatorActions, initial: SceneView, *, plot_every: int = 5
    ) -> None:
        self._server = server
        self._actions = actions
        self._lock = threading.Lock()
        self._pending_clicks: dict[int, float] = {}  # client id -> radius of the obstacle to place
        self._click_registered = False
        self._view = initial
        self._shown_formation = initial.formation
        self._plot_every = plot_every
        self._refreshes = 0
        self._history: deque[tuple[float, float, float]] = deque()
        gui = server.gui
        self._status = gui.add_markdown(status_line(initial))
        with gui.add_folder("Formation"):
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
            start.on_click(self._on_start)
            stop.on_click(
                lambda e: self._do(
                    e.client,
                    lambda: actions.set_formation_enabled(False),
                    "Formation stopped: MAVs hold position",
                )
            )
        self._land_all = gui.add_button("LAND ALL", color="red", icon=viser.Icon.PLANE_ARRIVAL)
        self._land_all.on_click(self._on_land_all)
        self._vehicle_folder = gui.add_folder("Vehicles")
        self._cards: dict[int, dict[str, Any]] = {}
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
        with gui.add_folder("Plots"):
            self.trace_plot = gui.add_uplot(
                *_plot_args("fused covariance trace (m^2)", (200, 140, 0)),
                title="Fused position covariance trace",
                aspect=2.0,
            )
            self.error_plot = gui.add_uplot(
                *_plot_args("tracking error (m)", (200, 40, 40)),
                title="Tracking error (simulation)",
                aspect=2.0,
            )
        self.refresh(initial)

    # ---- refresh from the ground station -------------------------------------------------------------------

    def refresh(self, view: SceneView) -> None:
        """Show `view`: status, slider values and ranges, vehicle cards, obstacle list, plots."""
        self._view = view
        self._status.content = status_line(view)
        _set_range(self._d_des, view.d_des_range_m.low, view.d_des_range_m.high)
        _set_range(self._h_des, view.h_des_range_m.low, view.h_des_range_m.high)
        if view.formation != self._shown_formation:  # changed elsewhere (the API, another client)
            self._show_formation(view)
        for vehicle in view.vehicles:
            self._refresh_card(vehicle)
        self._refresh_obstacles(view)
        self._record(view)

    def _refresh_card(self, vehicle: VehicleView) -> None:
        card = self._cards.get(vehicle.vehicle_id)
        if card is None:
            gui = self._server.gui
            with self._vehicle_folder:
                card = {
                    "text": gui.add_markdown(vehicle_card(vehicle)),
                    "land": gui.add_button(f"Land MAV {vehicle.vehicle_id}", color="orange"),
                    "release": gui.add_button(f"Release MAV {vehicle.vehicle_id} to formation"),
                }
            vid = vehicle.vehicle_id
            card["land"].on_click(lambda e: self._on_land(e, vid))
            card["release"].on_click(lambda e: self._on_release(e, vid))
            self._cards[vid] = card
        text = vehicle_card(vehicle)
        if card["text"].content != text:
            card["text"].content = text
        adopted = vehicle.phase.lower() == "idle" and vehicle.in_air and not vehicle.failsafe
        releasable = vehicle.phase.lower() == "landed" or adopted
        if card["release"].visible != releasable:
            card["release"].visible = releasable

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
                    lambda e, oid=obstacle_id: self._do(
                        e.client, lambda: self._actions.remove_obstacle(oid), f"Obstacle {oid} removed"
                    )
                )
                self._obstacle_buttons[obstacle_id] = button

    def _record(self, view: SceneView) -> None:
        if self._history and self._history[-1][0] >= view.time_s:  # the same instant again: nothing new
            return
        estimate = view.person_estimate
        trace = estimate.position_cov_trace_m2 if estimate is not None else math.nan
        error = view.tracking_error_m if view.tracking_error_m is not None else math.nan
        self._history.append((view.time_s, trace, error))
        while self._history and self._history[0][0] < view.time_s - PLOT_WINDOW_S:
            self._history.popleft()
        self._refreshes += 1
        if self._refreshes % self._plot_every:
            return
        t, tr, err = (np.array(c, dtype=float) for c in zip(*self._history, strict=True))
        self.trace_plot.data = (t, tr)
        self.error_plot.data = (t, err)

    # ---- operator input ------------------------------------------------------------------------------------

    def _do(self, client: viser.ClientHandle | None, action: Callable[[], object], done: str | None) -> None:
        """`_run` for a button callback, which must return None."""
        self._run(client, action, done)

    def _run(self, client: viser.ClientHandle | None, action: Callable[[], object], done: str | None) -> bool:
        """Run one operator action; tell the client the outcome. Never raises: a GUI callback must not die."""
        try:
            action()
        except ValueError as exc:
            _notify(client, "Refused", str(exc), color="red")
            return False
        except Exception as exc:  # noqa: BLE001 - a bug in a command must not kill the GUI thread
            log.exception("operator action failed")
            _notify(client, "Error", f"the ground station could not do this: {exc}", color="red")
            return False
        if done:
            _notify(client, "Done", done, color="green")
        return True

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

    def _on_add_obstacle(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        with self._lock:
            self._pending_clicks[event.client.client_id] = float(self._radius.value)
            if not self._click_registered:
                self._server.scene.on_click()(self._on_scene_click)
                self._click_registered = True
        _notify(
            event.client,
            "Place obstacle",
            "Click on the ground where the obstacle should stand.",
            color="blue",
        )

    def _on_scene_click(self, event: viser.SceneClickEvent) -> None:
        with self._lock:
            radius = self._pending_clicks.pop(event.client_id, None)
            if not self._pending_clicks and self._click_registered:
                self._server.scene.remove_click_callback(self._on_scene_click)
                self._click_registered = False
        if radius is None:
            return
        point = ground_point(np.asarray(event.ray_origin), np.asarray(event.ray_direction))
        if point is None:
            _notify(
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

    def _on_land(self, event: viser.GuiEvent, vehicle_id: int) -> None:
        self._confirm(
            event.client,
            f"Land MAV {vehicle_id}?",
            f"MAV {vehicle_id} leaves the formation and lands where it is. It stays out of the "
            "formation until you release it; its teammates re-space.",
            f"Land MAV {vehicle_id}",
            lambda: self._actions.land(vehicle_id),
            f"MAV {vehicle_id} landing",
        )

    def _on_land_all(self, event: viser.GuiEvent) -> None:
        self._confirm(
            event.client,
            "LAND ALL?",
            "Every MAV leaves the formation and lands where it is.",
            "Confirm LAND ALL",
            self._actions.land_all,
            "All MAVs landing",
        )

    def _on_start(self, event: viser.GuiEvent) -> None:
        """Start the formation; when the pre-take-off checks refuse it, offer the logged override."""
        if self._run(event.client, lambda: self._actions.set_formation_enabled(True), "Formation started"):
            return
        held = [v for v in self._view.vehicles if v.takeoff_check and v.phase == "idle"]
        if held:
            self._confirm(
                event.client,
                "Start anyway?",
                "  \n".join(f"MAV {v.vehicle_id} {v.takeoff_check}" for v in held)
                + "  \nStarting anyway takes them off where they stand; the override is logged.",
                "Start anyway (override)",
                lambda: self._actions.set_formation_enabled(True, override=True),
                "Formation started: pre-take-off checks overridden (logged)",
            )

    def _on_release(self, event: viser.GuiEvent, vehicle_id: int) -> None:
        vehicle = next((v for v in self._view.vehicles if v.vehicle_id == vehicle_id), None)
        check = vehicle.takeoff_check if vehicle is not None else None
        body = f"MAV {vehicle_id} takes off again and rejoins the formation."
        if check:
            body = f"MAV {vehicle_id} {check}.  \nReleasing it overrides the pre-take-off check (logged)."
        self._confirm(
            event.client,
            f"Release MAV {vehicle_id}?",
            body,
            f"Release MAV {vehicle_id}" + (" (override)" if check else ""),
            lambda: self._actions.release(vehicle_id, override=bool(check)),
            f"MAV {vehicle_id} released",
        )

    def _confirm(
        self,
        client: viser.ClientHandle | None,
        title: str,
        body: str,
        confirm_label: str,
        action: Callable[[], object],
        done: str,
    ) -> None:
        """Ask the client that clicked to confirm in a modal; run `action` only on its confirm button."""
        if client is None:
            return
        with client.gui.add_modal(title) as modal:
            client.gui.add_markdown(body)
            confirm = client.gui.add_button(confirm_label, color="red")
            cancel = client.gui.add_button("Cancel")

        def on_confirm(_: viser.GuiEvent) -> None:
            modal.close()
            self._run(client, action, done)

        confirm.on_click(on_confirm)
        cancel.on_click(lambda _: modal.close())


def _plot_args(label: str, color: tuple[int, int, int]) -> tuple[tuple[np.ndarray, ...], tuple[Any, ...]]:
    data = (np.zeros(0), np.zeros(0))
    series = (
        viser.uplot.Series(label="t (s)"),
        viser.uplot.Series(label=label, stroke="rgb({},{},{})".format(*color), width=2),
    )
    return data, series


def _set_range(slider: Any, low: float, high: float) -> None:
    if slider.min != low:
        slider.min = low
    if slider.max != high:
        slider.max = high


def _notify(
    client: viser.ClientHandle | None, title: str, body: str, *, color: Literal["red", "green", "blue"]
) -> None:
    if client is None:
        return
    try:
        client.add_notification(title, body, auto_close_seconds=6.0, color=color)
    except Exception:  # noqa: BLE001 - the client may have gone away
        log.debug("could not notify client", exc_info=True)
