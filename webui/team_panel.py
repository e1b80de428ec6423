"""The Team tab: every MAV in one compact table, and the chosen MAV's detail with its Hold / Land / Release.

A MAV is chosen in the drop-down or by clicking its body in the 3-D view. Hold stops it where it is (no
confirmation: it keeps it in the air where it is); Land and Release ask for confirmation (Release of a landed
MAV takes it off the ground again; a holding one, or an airborne one skyring does not fly, joins from the
air). A Release the pre-take-off checks refuse (person keep-out, d_min) says so and overrides them (logged).
"""

from __future__ import annotations

from collections.abc import Callable

import viser

from webui.cards import team_table_html, vehicle_detail_markdown
from webui.geometry import vehicle_color
from webui.view import OperatorActions, SceneView, VehicleView

Run = Callable[[viser.ClientHandle | None, Callable[[], object], str | None], bool]
Confirm = Callable[[viser.ClientHandle | None, str, str, str, Callable[[], object], str | None], None]


def option(vehicle_id: int) -> str:
    return f"MAV {vehicle_id}"


def releasable(vehicle: VehicleView) -> bool:
    """Release can give it back to the formation: landed, holding, or airborne and not flown by skyring
    (found flying, or a pilot gave it back) while its autopilot runs no failsafe."""
    if vehicle.phase in ("landed", "holding"):
        return True
    free = vehicle.phase == "idle" or (vehicle.phase in ("takeoff", "formation") and vehicle.released)
    return free and vehicle.in_air and not vehicle.failsafe


class TeamPanel:
    """Built inside the current GUI container from the first view; `refresh` shows later ones."""

    def __init__(
        self, gui: viser.GuiApi, actions: OperatorActions, initial: SceneView, *, run: Run, confirm: Confirm
    ) -> None:
        self._actions = actions
        self._run = run
        self._confirm = confirm
        self._view = initial
        self.colors = {v.vehicle_id: vehicle_color(v.vehicle_id) for v in initial.vehicles}
        self.table = gui.add_html(team_table_html(initial, self.colors))
        options = [option(v.vehicle_id) for v in initial.vehicles] or ["none"]
        self.choice = gui.add_dropdown("Details of", options=options, initial_value=options[0])
        self.detail = gui.add_markdown("")
        self.hold = gui.add_button("Hold", icon=viser.Icon.PLAYER_PAUSE, hint="Stop it where it is")
        self.land = gui.add_button("Land", color="orange", icon=viser.Icon.PLANE_ARRIVAL)
        self.release = gui.add_button("Release", icon=viser.Icon.PLAYER_PLAY, visible=False)
        self.choice.on_update(lambda _: self.refresh(self._view))
        self.hold.on_click(self._on_hold)
        self.land.on_click(self._on_land)
        self.release.on_click(self._on_release)
        self.refresh(initial)

    def select(self, vehicle_id: int) -> None:
        """Show this MAV's detail (a click on it in the 3-D view)."""
        if option(vehicle_id) in self.choice.options:
            self.choice.value = option(vehicle_id)

    def selected(self) -> VehicleView | None:
        for v in self._view.vehicles:
            if option(v.vehicle_id) == self.choice.value:
                return v
        return None

    def refresh(self, view: SceneView) -> None:
        self._view = view
        table = team_table_html(view, self.colors)
        if self.table.content != table:
            self.table.content = table
        vehicle = self.selected()
        if vehicle is None:
            return
        detail = vehicle_detail_markdown(vehicle, view.alerts)
        if self.detail.content != detail:
            self.detail.content = detail
        vid = vehicle.vehicle_id
        labels = (f"Hold MAV {vid}", f"Land MAV {vid}", f"Release MAV {vid}")
        for button, label in zip((self.hold, self.land, self.release), labels, strict=True):
            if button.label != label:
                button.label = label
        can_release = releasable(vehicle)
        if self.release.visible != can_release:
            self.release.visible = can_release
        holdable = vehicle.phase in ("takeoff", "formation") and vehicle.in_air
        if self.hold.disabled == holdable:
            self.hold.disabled = not holdable

    def _chosen_id(self) -> int | None:
        vehicle = self.selected()
        return vehicle.vehicle_id if vehicle is not None else None

    def _on_hold(self, event: viser.GuiEvent) -> None:
        vid = self._chosen_id()
        if vid is not None:
            self._run(event.client, lambda: self._actions.hold(vid), f"MAV {vid} holding where it is")

    def _on_land(self, event: viser.GuiEvent) -> None:
        vid = self._chosen_id()
        if vid is None:
            return
        self._confirm(
            event.client,
            f"Land MAV {vid}?",
            f"MAV {vid} leaves the formation and lands where it is. It stays out of the formation until "
            "you release it; its teammates re-space.",
            f"Land MAV {vid}",
            lambda: self._actions.land(vid),
            f"MAV {vid} landing",
        )

    def _on_release(self, event: viser.GuiEvent) -> None:
        vehicle = self.selected()
        if vehicle is None:
            return
        vid, check = vehicle.vehicle_id, vehicle.takeoff_check
        if vehicle.phase == "holding":
            body = f"MAV {vid} rejoins the formation from where it hovers."
        elif vehicle.in_air:
            body = f"MAV {vid} joins the formation from where it flies."
        else:
            body = f"MAV {vid} **takes off again** and rejoins the formation."
        if check:
            body = f"MAV {vid} {check}.  \nReleasing it overrides the pre-take-off check (logged)."
        self._confirm(
            event.client,
            f"Release MAV {vid}?",
            body,
            f"Release MAV {vid}" + (" (override)" if check else ""),
            lambda: self._actions.release(vid, override=bool(check)),
            f"MAV {vid} released",
        )
