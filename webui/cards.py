"""What the panels say, as text: the mission header, the team table, a vehicle's detail, the alert list and
summary. Pure functions of the view (HTML for viser's `add_html`, markdown for `add_markdown`), so they are
tested without a browser. Every value from outside is escaped.
"""

from __future__ import annotations

import html
import math
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import UTC, datetime

from webui.view import SEVERITY_RANK, Alert, SceneView, Severity, VehicleView

SEVERITY_COLORS = {Severity.INFO: "#1c7ed6", Severity.WARNING: "#f08c00", Severity.CRITICAL: "#e03131"}
ALERTS_SHOWN = 60  # rows of the alert table (the API has them all)
GROUND_PHASES = ("idle", "landed")
TRANSITION_PHASES = ("takeoff", "landing", "holding")


@dataclass(frozen=True)
class Status:
    """A vehicle's status at a glance: name (ok, moving, ground, warning, critical) and its CSS colour."""

    name: str
    color: str


STATUS_OK = Status("ok", "#2f9e44")
STATUS_MOVING = Status("in transition", "#1c7ed6")
STATUS_GROUND = Status("on the ground", "#868e96")
STATUS_WARNING = Status("warning", SEVERITY_COLORS[Severity.WARNING])
STATUS_CRITICAL = Status("critical", SEVERITY_COLORS[Severity.CRITICAL])
AGENT_LOST_FLAG = "AGENT LOST"
SKEW_FLAG = "CLOCK SKEW"
STALE_FLAG = "STALE"
FAILSAFE_FLAG = "FAILSAFE"  # the autopilot runs its own failsafe (PX4: Land, Hold, Return)
REFUSED_FLAG = "ARMING REFUSED"  # the autopilot refused the take-off; its reason follows
HELD_FLAG = "CANNOT TAKE OFF HERE"  # the pre-take-off checks (person keep-out, d_min) refuse it


def vehicle_status(vehicle: VehicleView, alerts: Iterable[Alert]) -> Status:
    """Critical or warning while one of its alerts is active (the worst wins); otherwise on the ground, in
    transition (taking off, landing, holding) or ok (flying formation)."""
    worst = max(
        (SEVERITY_RANK[a.severity] for a in alerts if a.active and a.vehicle_id == vehicle.vehicle_id),
        default=-1,
    )
    if worst >= SEVERITY_RANK[Severity.CRITICAL] or (vehicle.link_stale and vehicle.in_air):
        return STATUS_CRITICAL
    if worst >= SEVERITY_RANK[Severity.WARNING]:
        return STATUS_WARNING
    if vehicle.phase in GROUND_PHASES and not vehicle.in_air:
        return STATUS_GROUND
    if vehicle.phase in TRANSITION_PHASES or not vehicle.in_formation:
        return STATUS_MOVING
    return STATUS_OK


def utc_text(utc_s: float | None) -> str:
    """HH:MM:SS UTC of a wall time (seconds since the epoch), "-" when unknown."""
    if utc_s is None or not math.isfinite(utc_s):
        return "-"
    return datetime.fromtimestamp(utc_s, tz=UTC).strftime("%H:%M:%S UTC")


def _num(value: float | None, fmt: str, *, scale: float = 1.0) -> str:
    if value is None or not math.isfinite(value):
        return "-"
    return format(value * scale, fmt)


def header_html(view: SceneView) -> str:
    """The line above LAND ALL: mission time, UTC, recording (and the log's path), real-time factor."""
    e = html.escape
    parts = [f"<b>T+ {view.time_s:.1f} s</b>", e(utc_text(view.utc_s))]
    if view.recording_path:
        parts.append(
            '<span style="color:#e03131">&#9679; REC</span> '
            f'<code style="font-size:11px">{e(view.recording_path)}</code>'
        )
    else:
        parts.append('<span style="color:#868e96">not recording</span>')
    pace = view.pace
    if pace is not None:
        if pace.realtime_factor is None:
            rtf = f"real time x? (asked {pace.requested_speed:g}x)"
            color = "#868e96"
        else:
            behind = pace.realtime_factor < 0.8 * pace.requested_speed
            color = SEVERITY_COLORS[Severity.WARNING] if behind else "inherit"
            rtf = f"{pace.realtime_factor:.2f}x real time (asked {pace.requested_speed:g}x)"
        parts.append(f'<span style="color:{color}">{e(rtf)}</span>')
    return f'<div style="font-size:13px;line-height:1.5">{" &middot; ".join(parts)}</div>'


def alert_summary_html(alerts: Iterable[Alert]) -> str:
    """One line under the header: how many alerts need attention, and the most urgent one."""
    pending = [a for a in alerts if a.active and not a.acknowledged]
    active = [a for a in alerts if a.active]
    if not active:
        return '<div style="font-size:13px;color:#2f9e44">&#10003; no active alerts</div>'
    shown = pending or active
    top = min(shown, key=lambda a: (-SEVERITY_RANK[a.severity], -a.last_s))
    color = SEVERITY_COLORS[top.severity]
    critical = sum(a.severity == Severity.CRITICAL for a in active)
    count = f"{len(active)} active alert{'s' if len(active) != 1 else ''}"
    if critical:
        count += f" ({critical} critical)"
    if pending:
        count += f", {len(pending)} not acknowledged"
    return (
        f'<div style="font-size:13px;border-left:4px solid {color};padding-left:6px">'
        f'<b style="color:{color}">{html.escape(count)}</b><br>{html.escape(top.message)}</div>'
    )


def _swatch(color: tuple[int, int, int]) -> str:
    r, g, b = color
    return (
        f'<span style="display:inline-block;width:9px;height:9px;background:rgb({r},{g},{b});'
        'border-radius:2px;margin-right:3px"></span>'
    )


def _dot(color: str, title: str) -> str:
    return f'<span title="{html.escape(title)}" style="color:{color};font-size:14px">&#9679;</span>'


TEAM_COLUMNS = ("", "MAV", "phase", "mode", "alt m", "v m/s", "d m", "link s", "batt", "solver")


def team_table_html(view: SceneView, colors: dict[int, tuple[int, int, int]]) -> str:
    """The team at a glance, one compact row per MAV (fits 16): status colour, its own colour and number,
    phase, the autopilot's own mode, altitude, speed, horizontal distance to the person, link age (STALE
    when stale), battery, solver time (or its status when it did not solve)."""
    head = "".join(f'<th style="text-align:left;padding:1px 3px">{html.escape(c)}</th>' for c in TEAM_COLUMNS)
    rows = []
    for v in view.vehicles:
        status = vehicle_status(v, view.alerts)
        link = STALE_FLAG if v.link_stale else _num(v.link_age_s, ".1f")
        link_style = ' style="color:#e03131;font-weight:bold"' if v.link_stale else ""
        battery = _num(v.battery_fraction, ".0f", scale=100.0)
        battery = battery + "%" if battery != "-" else battery
        solver = _num(v.solver_time_s, ".1f", scale=1e3)
        if v.solve_status and v.solve_status != "solved":
            solver = v.solve_status.replace("_", " ")
        cells = [
            _dot(status.color, status.name),
            _swatch(colors.get(v.vehicle_id, (0, 0, 0))) + f"<b>{v.vehicle_id}</b>",
            html.escape(v.phase),
            html.escape(v.autopilot_mode or v.mode),
            _num(v.altitude_m, ".1f"),
            _num(v.speed_mps, ".1f"),
            _num(v.distance_to_person_m, ".1f"),
            f"<span{link_style}>{link}</span>",
            battery,
            html.escape(solver),
        ]
        tds = "".join(f'<td style="padding:1px 3px;white-space:nowrap">{c}</td>' for c in cells)
        rows.append(f'<tr data-vehicle="{v.vehicle_id}">{tds}</tr>')
    return (
        '<table class="skyring-team" style="font-size:12px;border-collapse:collapse;width:100%">'
        f"<thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>"
    )


def agent_line(vehicle: VehicleView) -> str:
    """A networked agent's line: lost, clock skew, its latest command's outcome ("" for an in-process one)."""
    a = vehicle.agent
    if a is None:
        return ""
    parts = [f"**{AGENT_LOST_FLAG}** ({a.age_s:.1f} s)" if a.lost else "agent ok"]
    if a.station_lost:
        parts.append("it lost the station")
    if a.scheduler:
        parts.append(f"control loop: {a.scheduler}")
    if a.clock_offset_s is not None:
        skew = f" **{SKEW_FLAG}**" if a.clock_skew else ""
        parts.append(f"clock {a.clock_offset_s * 1e3:+.0f} ms{skew}")
    if a.commands:
        last = a.commands[-1]
        parts.append(
            f"cmd {last.command_id} {last.action}: {last.outcome}"
            + (f" ({last.message})" if last.message else "")
        )
    return " · ".join(parts)


def separation_line(vehicle: VehicleView) -> str:
    """How close the MAV is to its nearest airborne teammate (and which) and to the nearest trunk or obstacle
    surface, e.g. "sep 3.2 m (MAV 2) / tree 4.1 m"; "-" where not applicable (on the ground, alone, none)."""
    v = vehicle
    mate = f" (MAV {v.nearest_teammate_id})" if v.nearest_teammate_id is not None else ""
    teammate, tree = (
        "-" if d is None or not math.isfinite(d) else f"{d:.1f} m"
        for d in (v.nearest_teammate_m, v.nearest_obstacle_m)
    )
    return f"sep {teammate}{mate} / tree {tree}"


def vehicle_detail_markdown(vehicle: VehicleView, alerts: Iterable[Alert]) -> str:
    """Everything about one MAV, for the detail under the team table: phase (in formation or not), the
    autopilot's own mode, pose, battery, link, solver, separation to teammates and trees; then, when there is
    one, the autopilot's failsafe and why, why it refused to arm, why the ground station would not let it take
    off where it stands, and its onboard agent's link, clock and last command when it runs on the vehicle."""
    v = vehicle
    p, vel = v.position_m, v.velocity_mps
    status = vehicle_status(v, alerts)
    formation = " · in formation" if v.in_formation else ""
    lines = [
        f"**MAV {v.vehicle_id}**: {v.phase}{formation}, autopilot {v.autopilot_mode or v.mode}, "
        f"{'armed' if v.armed else 'disarmed'}, {'in air' if v.in_air else 'on ground'} ({status.name})",
        f"position ({p[0]:.1f}, {p[1]:.1f}, {p[2]:.1f}) m · velocity ({vel[0]:.1f}, {vel[1]:.1f}, "
        f"{vel[2]:.1f}) m/s · yaw {math.degrees(v.yaw_rad):.0f} deg",
        f"distance to person {_num(v.distance_to_person_m, '.1f')} m · battery "
        f"{_num(v.battery_fraction, '.0f', scale=100.0)} % · link age {_num(v.link_age_s, '.1f')} s"
        + (f" **{STALE_FLAG}**" if v.link_stale else ""),
        f"solver {v.solve_status or '-'} {_num(v.solver_time_s, '.2f', scale=1e3)} ms · plan age "
        f"{_num(v.plan_age_s, '.1f')} s",
        separation_line(v),
    ]
    if v.failsafe:
        lines.append(f"**{FAILSAFE_FLAG}**: {v.failsafe_reason or 'the autopilot runs its failsafe'}")
    if v.arming_refusal:
        lines.append(f"**{REFUSED_FLAG}**: {v.arming_refusal}")
    if v.takeoff_check:
        lines.append(f"**{HELD_FLAG}**: {v.takeoff_check}")
    if v.released:
        lines.append("released: the autopilot or a pilot has it, skyring does not steer it")
    if v.fault:
        lines.append(f"last fault: {v.fault}")
    if v.agent is not None:
        lines.append(agent_line(v))
    mine = [a for a in alerts if a.active and a.vehicle_id == v.vehicle_id]
    lines += [f"- {a.severity.value}: {a.message}" for a in mine]
    return "  \n".join(_md_escape(line) for line in lines)


def _md_escape(text: str) -> str:
    return text.replace("<", "&lt;").replace(">", "&gt;")


def alert_table_html(alerts: Iterable[Alert], *, limit: int = ALERTS_SHOWN) -> str:
    """The alert list: severity, id, when first raised (mission time and UTC) and last seen, the MAV, the
    message, and its state (active or cleared, acknowledged, times raised)."""
    alerts = list(alerts)
    if not alerts:
        return '<div style="font-size:13px;color:#868e96">No alerts so far.</div>'
    rows = []
    for a in alerts[:limit]:
        color = SEVERITY_COLORS[a.severity]
        state = "ACTIVE" if a.active else "cleared"
        if a.acknowledged:
            state += ", ack"
        if a.count > 1:
            state += f", x{a.count}"
        when = f"{a.first_s:.1f} s"
        if a.first_utc_s is not None:
            when += f" ({utc_text(a.first_utc_s)})"
        weight = "bold" if a.active and not a.acknowledged else "normal"
        opacity = "1" if a.active else "0.6"
        rows.append(
            f'<tr data-alert="{html.escape(a.alert_id)}" style="opacity:{opacity};font-weight:{weight}">'
            f'<td style="border-left:4px solid {color};padding:1px 4px;color:{color}">'
            f"{html.escape(a.severity.value)}</td>"
            f'<td style="padding:1px 4px">{html.escape(a.alert_id)}</td>'
            f'<td style="padding:1px 4px;white-space:nowrap">{html.escape(when)}</td>'
            f'<td style="padding:1px 4px">{html.escape(a.message)}</td>'
            f'<td style="padding:1px 4px;white-space:nowrap">{html.escape(state)}</td></tr>'
        )
    more = len(alerts) - limit
    tail = (
        f'<div style="font-size:11px;color:#868e96">{more} older alerts in /api/alerts</div>'
        if more > 0
        else ""
    )
    return (
        '<table class="skyring-alerts" style="font-size:12px;border-collapse:collapse;width:100%">'
        '<thead><tr><th style="text-align:left">severity</th><th style="text-align:left">id</th>'
        '<th style="text-align:left">first raised</th><th style="text-align:left">condition</th>'
        '<th style="text-align:left">state</th></tr></thead>'
        f"<tbody>{''.join(rows)}</tbody></table>{tail}"
    )


def legend_html(entries: Iterable[tuple[str, tuple[int, int, int]]]) -> str:
    """Colour legend of the 3-D view: a swatch and a name per entry."""
    items = "".join(f'<div style="white-space:nowrap">{_swatch(c)}{html.escape(n)}</div>' for n, c in entries)
    return f'<div style="font-size:12px;display:flex;flex-wrap:wrap;gap:2px 12px">{items}</div>'
