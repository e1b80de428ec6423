"""Who flies a PX4 vehicle: skyring's engagement state, the set-point watchdog, and respect for a pilot.

MAVSDK re-sends the last offboard set-point at 20 Hz, which would hide a stalled controller from PX4's own
offboard-loss failsafe; so skyring watches the age of the agent's output itself: older than `hold_after_s`
-> Hold, older than `land_after_s` -> Land. A vehicle taken out of offboard by a pilot (RC mode switch) or by
PX4 (a failsafe) is *released*: skyring stops streaming and does not switch back until re-engaged (takeoff);
while a pilot flies it (a manual mode) skyring's land and hold requests are not sent either.

A take-off PX4 refuses (its arming checks fail) is not hammered: it is tried again `refused_retry_s` later,
and only once PX4 reports it can arm. A vehicle PX4 takes over for one of its own failsafes (Land, Hold,
Return) is released at once, before the set-point watchdog would have its say: PX4's decision stands. And
when PX4 ran a failsafe while skyring flew it but is back in offboard by the time skyring looks (the whole
ground station stalled past COM_OF_LOSS_T; on waking, MAVSDK re-sends its last, stale set-point, which ends
PX4's offboard-loss failsafe at once), skyring lands it: the failsafe's landing stands.

Pure and clock-free: the asyncio back-end (vehicles/px4/autopilot.py) reports set-points and telemetry
observations, and executes the one `Command` that `step` returns. Engagement:

    IDLE -takeoff-> TAKING_OFF -in Hold at height-> ENGAGING -pre-streamed-> FOLLOWING
    TAKING_OFF -refused-> TAKING_OFF (again after refused_retry_s, once PX4 can arm)
    FOLLOWING -stale output-> WATCHDOG_HOLD -fresh output-> ENGAGING ; -stale longer-> LANDING
    FOLLOWING -PX4 reported a failsafe, yet shows offboard-> LANDING (failsafe_landing)
    FOLLOWING -the supervisor itself stalled past stall_land_after_s-> LANDING (failsafe_landing)
    holds -the same stall before telemetry showed the Hold-> LANDING (failsafe_landing)
    any -land-> LANDING (latched) -on the ground, disarmed-> IDLE
    FOLLOWING/ENGAGING/holds -mode changed by someone else-> RELEASED -takeoff-> ENGAGING or TAKING_OFF
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

from vehicles.autopilot import FlightMode


class Engagement(StrEnum):
    """skyring's relationship with one vehicle."""

    IDLE = "idle"  # on the ground, or airborne but never engaged by this ground station
    TAKING_OFF = "taking_off"
    ENGAGING = "engaging"  # airborne in Hold, pre-streaming set-points before switching to offboard
    FOLLOWING = "following"  # in offboard, following the agent's set-points
    WATCHDOG_HOLD = "watchdog_hold"  # the agent's output went stale: skyring put the vehicle in Hold
    HOLDING = "holding"  # the operator asked for Hold
    LANDING = "landing"  # landing through PX4 (operator, or the watchdog's longer limit); latched
    RELEASED = "released"  # a pilot or PX4 took it out of offboard: skyring does not fight


class Command(StrEnum):
    """What the back-end must ask PX4 for."""

    TAKEOFF = "takeoff"  # set the takeoff altitude, arm, take off
    START_OFFBOARD = "start_offboard"
    HOLD = "hold"  # stop streaming and switch to Hold
    LAND = "land"


@dataclass(frozen=True)
class SupervisorParams:
    """hold_after_s / land_after_s: agent output age (s) that triggers Hold / Land; prestream_s: set-points
    streamed before switching to offboard (PX4 >= 1.14 wants > 1 s at > 2 Hz); retry_after_s: a command whose
    effect does not show is sent again after this; mode_grace_s: how long a mode change may take to appear in
    telemetry (PX4 sends its heartbeat at 1 Hz), during which the old mode is not read as someone else's;
    refused_retry_s: a take-off PX4 refused (or that failed) is tried again after this, once PX4 can arm;
    stall_land_after_s: the supervisor itself did not run for this long while following (the whole ground
    station stalled, MAVSDK's threads with it): PX4 has been without set-points past its offboard-loss
    timeout (COM_OF_LOSS_T, 1 s) and runs its failsafe, which MAVSDK's stale set-point is about to end: land
    at once."""

    hold_after_s: float = 0.5
    land_after_s: float = 5.0
    prestream_s: float = 1.2
    retry_after_s: float = 1.0
    mode_grace_s: float = 2.0
    refused_retry_s: float = 10.0
    stall_land_after_s: float = 2.0

    def __post_init__(self) -> None:
        if not (0.0 < self.hold_after_s < self.land_after_s and math.isfinite(self.land_after_s)):
            raise ValueError(
                f"need 0 < hold_after_s < land_after_s, got {self.hold_after_s} and {self.land_after_s}"
            )
        for name in ("prestream_s", "retry_after_s", "mode_grace_s", "refused_retry_s", "stall_land_after_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be a non-negative number of seconds, got {value}")


@dataclass(frozen=True)
class Observation:
    """The vehicle as telemetry shows it at now_s (seconds, the back-end's clock). failsafe: PX4 runs one of
    its own failsafes; failsafe_reported: PX4 reported running one (a critical heartbeat, or its Land) since
    the previous observation, even if it no longer does; can_arm: PX4's pre-arm checks pass in its current
    mode (None: not known); stalled_s: seconds since the supervisor's previous step (its loop's own gap)."""

    now_s: float
    mode: FlightMode
    armed: bool
    in_air: bool
    link_lost: bool = False
    failsafe: bool = False
    failsafe_reported: bool = False
    can_arm: bool | None = None
    stalled_s: float = 0.0


_OFFBOARD = (Engagement.FOLLOWING, Engagement.ENGAGING)  # skyring streams set-points to PX4
_HOLDS = (Engagement.WATCHDOG_HOLD, Engagement.HOLDING)  # skyring asked PX4 for Hold

# What each command should make the flight mode show.
_EXPECTED_MODE = {
    Command.START_OFFBOARD: FlightMode.OFFBOARD,
    Command.HOLD: FlightMode.HOLD,
    Command.LAND: FlightMode.LAND,
    Command.TAKEOFF: FlightMode.TAKEOFF,
}


class OffboardSupervisor:
    """One vehicle's engagement state machine; requests are recorded at once and acted on at the next step."""

    def __init__(self, params: SupervisorParams = SupervisorParams()) -> None:
        self.params = params
        self.engagement = Engagement.IDLE
        self.released_reason: str | None = None
        self.takeoff_height_m: float | None = None
        self.ignored_setpoints = 0
        self.ignored_requests = 0
        self.watchdog_holds = 0
        self.watchdog_landings = 0
        self.takeoff_failures = 0
        self.failsafe_landing = False  # landing because PX4 ran a failsafe while skyring flew it
        self.stall_s: float | None = None  # how long the ground station stalled, if that began the landing
        self._takeoff_failed_s: float | None = None  # a take-off that failed and waits to be tried again
        self._last_setpoint_s: float | None = None
        self._stream_start_s = -math.inf  # when the current uninterrupted set-point stream began
        self._streamed_since_engaged = False
        self._requests: list[tuple[str, float | None]] = []
        self._last_command: Command | None = None
        self._last_command_s = -math.inf
        self._engaged_from = FlightMode.HOLD  # the mode a (re-)engagement started from: not a takeover
        self._engaged_at_s = -math.inf  # set-points reach the vehicle from then on (pre-streaming counts)

    # ---- inputs ------------------------------------------------------------------------------------------
    def request_takeoff(self, height_m: float) -> None:
        self._requests.append(("takeoff", height_m))

    def request_hold(self) -> None:
        self._requests.append(("hold", None))

    def request_land(self) -> None:
        self._requests.append(("land", None))

    def note_setpoint(self, now_s: float) -> bool:
        """An agent set-point arrived at now_s. False if it is ignored (landing, released, on the ground)."""
        if self.engagement in (Engagement.IDLE, Engagement.LANDING, Engagement.RELEASED):
            self.ignored_setpoints += 1
            return False
        if self._last_setpoint_s is None or now_s - self._last_setpoint_s > self.params.hold_after_s:
            self._stream_start_s = now_s  # a new uninterrupted stream starts
        self._last_setpoint_s = now_s
        if self.engagement in (Engagement.ENGAGING, Engagement.FOLLOWING):
            self._streamed_since_engaged = True
        return True

    def command_failed(self, command: Command, now_s: float) -> None:
        """The back-end could not get `command` through at now_s (PX4 denied it, or it timed out). A take-off
        is tried again after refused_retry_s, once PX4 reports it can arm; other commands are retried by the
        state they belong to."""
        if command is Command.TAKEOFF and self.engagement is Engagement.TAKING_OFF:
            self._takeoff_failed_s = now_s
            self.takeoff_failures += 1

    def command_done(self, now_s: float) -> None:
        """The back-end got the last command through at now_s: the grace for its mode to show in telemetry
        starts again from here (a take-off asks for Hold, waits for PX4's arming checks, arms and takes off:
        seconds on a busy machine, during which telemetry may still show the Hold it asked for first)."""
        self._last_command_s = max(self._last_command_s, now_s)

    @property
    def takeoff_failed(self) -> bool:
        """The last take-off failed and waits to be tried again."""
        return self._takeoff_failed_s is not None and self.engagement is Engagement.TAKING_OFF

    # ---- outputs -----------------------------------------------------------------------------------------
    @property
    def forwarding(self) -> bool:
        """Whether the agent's set-points go to the vehicle now (pre-streaming or following)."""
        return self.engagement in (Engagement.ENGAGING, Engagement.FOLLOWING)

    @property
    def released(self) -> bool:
        return self.engagement is Engagement.RELEASED

    @property
    def pending(self) -> bool:
        """Requests recorded but not yet acted on (the next `step` will)."""
        return bool(self._requests)

    def setpoint_age_s(self, now_s: float) -> float:
        """Seconds since the last agent set-point (inf before the first)."""
        return math.inf if self._last_setpoint_s is None else now_s - self._last_setpoint_s

    def step(self, obs: Observation) -> Command | None:
        """Advance the state machine with one observation; the command to issue now, if any."""
        command = self._apply_requests(obs)
        if command is not None:
            return self._issue(command, obs.now_s)
        command = self._px4_failsafe_while_engaged(obs)
        if command is not None:
            return self._issue(command, obs.now_s)
        handler = {
            Engagement.IDLE: self._idle,
            Engagement.TAKING_OFF: self._taking_off,
            Engagement.ENGAGING: self._engaging,
            Engagement.FOLLOWING: self._following,
            Engagement.WATCHDOG_HOLD: self._watchdog_hold,
            Engagement.HOLDING: self._holding,
            Engagement.LANDING: self._landing,
            Engagement.RELEASED: self._released,
        }[self.engagement]
        command = handler(obs)
        return self._issue(command, obs.now_s) if command is not None else None

    # ---- internals ---------------------------------------------------------------------------------------
    def _issue(self, command: Command, now_s: float) -> Command:
        self._last_command, self._last_command_s = command, now_s
        return command

    def _in_grace(self, now_s: float) -> bool:
        return now_s - self._last_command_s < self.params.mode_grace_s

    def _retry_time(self, now_s: float) -> bool:
        return now_s - self._last_command_s >= self.params.retry_after_s + self.params.mode_grace_s

    def _due_retry(self, command: Command, obs: Observation) -> bool:
        """The mode `command` asks for has not shown after the grace and the retry delay: send it again."""
        return obs.mode is not _EXPECTED_MODE[command] and not obs.link_lost and self._retry_time(obs.now_s)

    def _apply_requests(self, obs: Observation) -> Command | None:
        command = None
        requests, self._requests = self._requests, []
        for kind, value in requests:
            if kind in ("land", "hold") and self.released and obs.mode is FlightMode.MANUAL:
                self.ignored_requests += 1  # a pilot flies it: landing or holding is the pilot's call
                continue
            if kind == "land":
                if self.engagement is Engagement.LANDING:
                    continue  # already landing: the retry logic handles a lost command
                if not obs.in_air and not obs.armed:
                    self.engagement = Engagement.IDLE
                    continue
                self.engagement = Engagement.LANDING
                command = Command.LAND
            elif kind == "hold":
                if (
                    self.engagement
                    in (
                        Engagement.ENGAGING,
                        Engagement.FOLLOWING,
                        Engagement.WATCHDOG_HOLD,
                        Engagement.TAKING_OFF,
                    )
                    and obs.in_air
                ):
                    self.engagement = Engagement.HOLDING
                    command = Command.HOLD
            elif kind == "takeoff":
                if self.engagement in (Engagement.TAKING_OFF, Engagement.FOLLOWING, Engagement.ENGAGING):
                    continue  # already on its way (the mission re-sends takeoff while telemetry catches up)
                if self.engagement is Engagement.LANDING and obs.in_air:
                    continue  # the landing override is latched until the vehicle is down
                self.takeoff_height_m = value
                self.released_reason = None
                if obs.in_air and obs.armed:
                    self._engage(obs, from_mode=obs.mode)  # re-engage an airborne vehicle
                    self._streamed_since_engaged = False
                else:
                    self.engagement = Engagement.TAKING_OFF
                    self._streamed_since_engaged = False
                    self._takeoff_failed_s = None
                    command = Command.TAKEOFF
        return command

    def _foreign_mode(self, obs: Observation, allowed: tuple[FlightMode, ...]) -> bool:
        """The vehicle is in a mode skyring did not ask for (after the grace for telemetry to catch up)."""
        return (
            obs.mode not in allowed
            and obs.mode is not FlightMode.UNKNOWN
            and not obs.link_lost
            and not self._in_grace(obs.now_s)
        )

    def _engage(self, obs: Observation, *, from_mode: FlightMode = FlightMode.HOLD) -> None:
        """Start forwarding set-points (pre-streaming); offboard follows after prestream_s of them."""
        self.engagement = Engagement.ENGAGING
        self._engaged_from = from_mode
        self._engaged_at_s = obs.now_s

    def _release(self, obs: Observation) -> None:
        self.engagement = Engagement.RELEASED
        self._takeoff_failed_s = None
        self.failsafe_landing = False
        if obs.failsafe:
            self.released_reason = f"PX4 failsafe ({obs.mode.value}): skyring released control"
        else:
            self.released_reason = f"left offboard for {obs.mode.value}: skyring released control"

    def _fresh(self, now_s: float) -> bool:
        return self.setpoint_age_s(now_s) <= self.params.hold_after_s

    def _idle(self, obs: Observation) -> Command | None:
        return None

    def _taking_off(self, obs: Observation) -> Command | None:
        if obs.in_air and obs.mode is FlightMode.HOLD and not self._in_grace(obs.now_s):
            self._takeoff_failed_s = None
            self._engage(obs)  # PX4 finished the takeoff and holds
            return None
        if self._foreign_mode(obs, (FlightMode.TAKEOFF, FlightMode.HOLD, FlightMode.READY)):
            self._release(obs)
            return None
        if obs.in_air or obs.armed:
            self._takeoff_failed_s = None
            return None
        if self._takeoff_failed_s is not None:
            # PX4 refused (or never answered): again once it can arm, and not before refused_retry_s.
            if obs.can_arm is False or obs.link_lost:
                return None
            if obs.now_s - self._takeoff_failed_s < self.params.refused_retry_s:
                return None
            self._takeoff_failed_s = None
            return Command.TAKEOFF
        if self._due_retry(Command.TAKEOFF, obs):
            return Command.TAKEOFF  # the takeoff did not happen (lost command, or disarmed again)
        return None

    def _engaging(self, obs: Observation) -> Command | None:
        if obs.mode is FlightMode.OFFBOARD and self._last_command is Command.START_OFFBOARD:
            self.engagement = Engagement.FOLLOWING  # (an Offboard read before skyring asked for it is stale)
            return None
        if self._foreign_mode(obs, (FlightMode.HOLD, FlightMode.OFFBOARD, self._engaged_from)):
            self._release(obs)
            return None
        if self._streamed_since_engaged and self.setpoint_age_s(obs.now_s) > self.params.land_after_s:
            return self._watchdog_land()
        if (
            self._fresh(obs.now_s)
            and not obs.link_lost
            and obs.now_s - max(self._stream_start_s, self._engaged_at_s) >= self.params.prestream_s
            and (self._last_command is not Command.START_OFFBOARD or self._retry_time(obs.now_s))
        ):
            return Command.START_OFFBOARD
        return None

    def _following(self, obs: Observation) -> Command | None:
        if self._foreign_mode(obs, (FlightMode.OFFBOARD,)):
            self._release(obs)  # PX4 (a failsafe) or a pilot took it: their decision stands
            return None
        age = self.setpoint_age_s(obs.now_s)
        if age > self.params.land_after_s:
            return self._watchdog_land()
        if age > self.params.hold_after_s:
            self.engagement = Engagement.WATCHDOG_HOLD
            self.watchdog_holds += 1
            return Command.HOLD
        return None

    def _watchdog_hold(self, obs: Observation) -> Command | None:
        if self.setpoint_age_s(obs.now_s) > self.params.land_after_s:
            return self._watchdog_land()
        if self._foreign_mode(obs, (FlightMode.HOLD, FlightMode.OFFBOARD)):
            self._release(obs)
            return None
        if self._fresh(obs.now_s):
            self._engage(obs)  # the agent is back: pre-stream, then offboard again
            return None
        if self._due_retry(Command.HOLD, obs):
            return Command.HOLD
        return None

    def _holding(self, obs: Observation) -> Command | None:
        if self._foreign_mode(obs, (FlightMode.HOLD, FlightMode.OFFBOARD)):
            self._release(obs)
            return None
        last_setpoint_s = self._last_setpoint_s
        if self._fresh(obs.now_s) and last_setpoint_s is not None and last_setpoint_s > self._last_command_s:
            self._engage(obs)  # set-points after the hold: follow them again
            return None
        if self._due_retry(Command.HOLD, obs):
            return Command.HOLD
        return None

    def _landing(self, obs: Observation) -> Command | None:
        if not obs.in_air and not obs.armed:
            self.engagement = Engagement.IDLE
            self.failsafe_landing = False
            return None
        if self._foreign_mode(obs, (FlightMode.LAND, FlightMode.HOLD, FlightMode.OFFBOARD, FlightMode.READY)):
            self._release(obs)  # a pilot took over during the landing
            return None
        if obs.in_air and self._due_retry(Command.LAND, obs):
            return Command.LAND
        return None

    def _released(self, obs: Observation) -> Command | None:
        if not obs.in_air and not obs.armed:
            self.engagement = Engagement.IDLE
            self.released_reason = None
        return None

    def _px4_failsafe_while_engaged(self, obs: Observation) -> Command | None:
        """Land a vehicle PX4 ran a failsafe on while skyring flew it, whatever its mode reads now: after a
        stall of the whole ground station (PX4 lost the set-points past its timeout, and what telemetry shows
        now may be from before), or when PX4 reported a failsafe it has already left (MAVSDK's stale set-point
        ends its offboard-loss failsafe at once). A failsafe PX4 still runs is left to it (`_foreign_mode`).
        """
        if self.stall_lands(obs.mode, obs.stalled_s):
            return self._failsafe_land(stall_s=obs.stalled_s)
        held = (*_OFFBOARD, *_HOLDS)
        if (
            self.engagement in held
            and obs.failsafe_reported
            and not obs.link_lost
            and obs.mode in (FlightMode.OFFBOARD, FlightMode.HOLD)
        ):
            return self._failsafe_land(stall_s=None)
        return None

    def stall_lands(self, mode: FlightMode, stalled_s: float) -> bool:
        """Whether a stall of stalled_s seconds, with telemetry showing `mode`, has set off PX4's
        offboard-loss failsafe: past stall_land_after_s while skyring streamed set-points, or in a Hold that
        telemetry has not shown yet (it may never have reached PX4, then still in Offboard without
        set-points)."""
        if stalled_s <= self.params.stall_land_after_s:
            return False
        return self.engagement in _OFFBOARD or (self.engagement in _HOLDS and mode is not FlightMode.HOLD)

    def _failsafe_land(self, *, stall_s: float | None) -> Command:
        self.engagement = Engagement.LANDING
        self.failsafe_landing = True
        self.stall_s = stall_s
        return Command.LAND

    def _watchdog_land(self) -> Command:
        self.engagement = Engagement.LANDING
        self.watchdog_landings += 1
        return Command.LAND
