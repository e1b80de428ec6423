"""What PX4 says about itself, turned into the two reasons an operator must read: why it refused to arm, and
why it is running a failsafe.

PX4 speaks through two channels. STATUSTEXT lines reach every ground station ("Arming denied: Resolve system
health failures first", "Failsafe activated"); they are short and often generic. The events protocol (MAVSDK's
events plugin, when the vehicle serves its event metadata) carries the detail: the failing arming checks of
the current mode ("Vehicle is in safety configuration", "No offboard signal") and failsafe events that name
the cause and the action ("Failsafe activated: switching to Land - No offboard signal"). `Px4Notices` keeps
the recent messages of both and answers from whichever arrived. Pure: times are the caller's clock (seconds).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

# MAV_SEVERITY: 0 emergency, 1 alert, 2 critical, 3 error, 4 warning, 5 notice, 6 info, 7 debug.
SEVERITY_CRITICAL = 2
SEVERITY_ERROR = 3

ARMING_PREFIXES = ("Arming denied", "Preflight Fail", "Takeoff denied", "Arming refused")
FAILSAFE_PREFIX = "Failsafe activated"
# PX4 v1.16's events for a failsafe that acts (switches mode); the other commander_failsafe_enter_* events
# are warnings only (e.g. "Low battery level, return advised").
FAILSAFE_ACTION_EVENTS = frozenset(
    {
        "commander_failsafe_enter",
        "commander_failsafe_enter_generic",
        "commander_failsafe_enter_hold",
        "commander_failsafe_enter_generic_hold",
        "commander_failsafe_enter_autopilot_disengaged",
    }
)


@dataclass(frozen=True)
class Px4Message:
    """One message from PX4: t_s when it arrived; severity (MAV_SEVERITY, 0 worst); source "statustext" or
    "event"; name: the event's name (PX4 events protocol), "" for STATUSTEXT."""

    t_s: float
    text: str
    severity: int
    source: str = "statustext"
    name: str = ""


def clean_text(text: str) -> str:
    """PX4's text on one line: the tab PX4 ends evented lines with dropped, list lines joined by "; "."""
    lines = [line.strip().removeprefix("- ").strip() for line in str(text).replace("\t", " ").splitlines()]
    return "; ".join(line for line in lines if line)


def statustext_severity(mavsdk_type_value: int) -> int:
    """MAV_SEVERITY of a MAVSDK StatusTextType value (MAVSDK numbers them the other way: DEBUG 0 ... EMERGENCY
    7)."""
    return min(max(7 - int(mavsdk_type_value), 0), 7)


class Px4Notices:
    """PX4's recent messages and its latest arming-check problems; answers `arming_refusal` and
    `failsafe_reason`. keep: how many messages are remembered (the oldest are dropped)."""

    def __init__(self, *, keep: int = 64) -> None:
        self._messages: deque[Px4Message] = deque(maxlen=keep)
        self._problems: tuple[str, ...] = ()
        self._problems_t_s = -1e18

    def add(self, message: Px4Message) -> None:
        text = clean_text(message.text)
        if text:
            self._messages.append(
                Px4Message(
                    t_s=message.t_s,
                    text=text,
                    severity=message.severity,
                    source=message.source,
                    name=message.name,
                )
            )

    def set_arming_problems(self, t_s: float, problems: tuple[str, ...]) -> None:
        """The errors of PX4's latest health-and-arming-check report for its current mode (empty: none)."""
        self._problems = tuple(clean_text(p) for p in problems if clean_text(p))
        self._problems_t_s = t_s

    @property
    def arming_problems(self) -> tuple[str, ...]:
        return self._problems

    def messages(self) -> tuple[Px4Message, ...]:
        return tuple(self._messages)

    def arming_refusal(self, *, refused_at_s: float, fallback: str, window_s: float = 2.0) -> str:
        """PX4's words for an arming or takeoff refused at refused_at_s: its refusal lines from `window_s`
        around that moment, then the failing checks of its mode; `fallback` when it said nothing."""
        lines = [
            m.text
            for m in self._messages
            if abs(m.t_s - refused_at_s) <= window_s and m.text.startswith(ARMING_PREFIXES)
        ]
        text = "; ".join(dict.fromkeys(lines)) or fallback
        if self._problems:
            text += " (" + "; ".join(self._problems) + ")"
        return text

    def failsafe_reason(self, *, since_s: float, margin_s: float = 3.0) -> str:
        """Why PX4 is in the failsafe that began at since_s: its failsafe event when the events protocol gave
        one, else its "Failsafe activated" line with the critical lines sent beside it."""
        recent = [m for m in self._messages if m.t_s >= since_s - margin_s]
        events = [m for m in recent if m.name in FAILSAFE_ACTION_EVENTS]
        if events:
            return events[-1].text
        lines = [m for m in recent if m.source == "statustext" and m.text.startswith(FAILSAFE_PREFIX)]
        if not lines:
            return "PX4 failsafe (PX4 gave no reason)"
        last = lines[-1]
        causes = [
            m.text
            for m in recent
            if m.source == "statustext"
            and m.severity <= SEVERITY_CRITICAL
            and not m.text.startswith(FAILSAFE_PREFIX)
            and abs(m.t_s - last.t_s) <= 1.0
        ]
        return "; ".join(dict.fromkeys([*causes, last.text]))
