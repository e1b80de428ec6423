"""The PX4 engagement state machine: takeoff, refused take-offs, pre-streaming, watchdog, release to a pilot
or to PX4's failsafe (vehicles/px4/supervisor.py)."""

from __future__ import annotations

import pytest

from vehicles.autopilot import FlightMode
from vehicles.px4.supervisor import Command, Engagement, Observation, OffboardSupervisor, SupervisorParams

P = SupervisorParams(
    hold_after_s=0.5,
    land_after_s=3.0,
    prestream_s=1.0,
    retry_after_s=1.0,
    mode_grace_s=1.0,
    refused_retry_s=5.0,
)


def obs(t, mode=FlightMode.HOLD, *, armed=True, in_air=True, link_lost=False, failsafe=False, can_arm=None):
    return Observation(
        now_s=t,
        mode=mode,
        armed=armed,
        in_air=in_air,
        link_lost=link_lost,
        failsafe=failsafe,
        can_arm=can_arm,
    )


def run(sup, t0, t1, mode, *, setpoints=True, dt=0.05, **kw):
    """Step from t0 to t1 at dt, feeding a set-point every step when `setpoints`; the commands issued."""
    commands = []
    n = round((t1 - t0) / dt)
    for i in range(n):
        t = t0 + i * dt
        if setpoints:
            sup.note_setpoint(t)
        c = sup.step(obs(t, mode, **kw))
        if c is not None:
            commands.append((round(t, 3), c))
    return commands


def following(t=0.0):
    """A supervisor that took off and entered offboard; returns it and the time reached."""
    sup = OffboardSupervisor(P)
    sup.request_takeoff(5.0)
    assert sup.step(obs(t, FlightMode.READY, armed=False, in_air=False)) is Command.TAKEOFF
    run(sup, t + 0.05, t + 1.5, FlightMode.HOLD, setpoints=False)
    assert sup.engagement is Engagement.ENGAGING
    cmds = run(sup, t + 1.5, t + 3.0, FlightMode.HOLD)
    assert [c for _, c in cmds] == [Command.START_OFFBOARD]
    run(sup, t + 3.0, t + 3.5, FlightMode.OFFBOARD)
    assert sup.engagement is Engagement.FOLLOWING
    return sup, t + 3.5


def test_takeoff_request_on_the_ground_issues_one_takeoff():
    sup = OffboardSupervisor(P)
    sup.request_takeoff(6.0)
    sup.request_takeoff(6.0)  # the mission re-sends it while telemetry catches up
    assert sup.step(obs(0.0, FlightMode.READY, armed=False, in_air=False)) is Command.TAKEOFF
    sup.request_takeoff(6.0)
    assert run(sup, 0.05, 2.0, FlightMode.TAKEOFF, setpoints=False) == []
    assert sup.takeoff_height_m == 6.0


def test_offboard_starts_only_after_prestreaming_for_prestream_s():
    sup = OffboardSupervisor(P)
    sup.request_takeoff(5.0)
    sup.step(obs(0.0, FlightMode.READY, armed=False, in_air=False))
    run(sup, 0.05, 1.5, FlightMode.HOLD, setpoints=False)  # takeoff done: PX4 holds
    cmds = run(sup, 1.5, 3.0, FlightMode.HOLD)
    assert cmds == [(2.5, Command.START_OFFBOARD)]


def test_setpoints_are_forwarded_while_engaging_and_following_only():
    sup = OffboardSupervisor(P)
    assert not sup.note_setpoint(0.0)  # on the ground: ignored and counted
    assert sup.ignored_setpoints == 1
    assert not sup.forwarding
    sup, _ = following()
    assert sup.forwarding


def test_stale_agent_output_holds_after_hold_after_s():
    sup, t = following()
    cmds = run(sup, t, t + 1.0, FlightMode.OFFBOARD, setpoints=False)  # last set-point at t - 0.05
    assert cmds == [(pytest.approx(t + 0.5), Command.HOLD)]
    assert sup.engagement is Engagement.WATCHDOG_HOLD
    assert sup.watchdog_holds == 1


def test_stale_agent_output_lands_after_land_after_s():
    sup, t = following()
    cmds = run(sup, t, t + 0.6, FlightMode.OFFBOARD, setpoints=False)
    cmds += run(sup, t + 0.6, t + 4.0, FlightMode.HOLD, setpoints=False)
    assert [c for _, c in cmds] == [Command.HOLD, Command.LAND]
    assert cmds[1][0] == pytest.approx(t + 3.0)
    assert sup.engagement is Engagement.LANDING
    assert sup.watchdog_landings == 1


def test_fresh_output_after_a_watchdog_hold_reengages_after_prestreaming():
    sup, t = following()
    run(sup, t, t + 0.6, FlightMode.OFFBOARD, setpoints=False)
    run(sup, t + 0.6, t + 1.0, FlightMode.HOLD, setpoints=False)
    cmds = run(sup, t + 1.0, t + 2.5, FlightMode.HOLD)
    assert [c for _, c in cmds] == [Command.START_OFFBOARD]
    assert cmds[0][0] == pytest.approx(t + 2.0)


def test_pilot_mode_change_releases_without_fighting():
    sup, t = following()
    cmds = run(sup, t, t + 5.0, FlightMode.MANUAL)
    assert cmds == []
    assert sup.engagement is Engagement.RELEASED
    assert sup.released_reason is not None
    assert "manual" in sup.released_reason
    assert not sup.forwarding
    assert not sup.note_setpoint(t + 5.0)


def test_px4_failsafe_hold_releases_too():
    sup, t = following()
    assert run(sup, t, t + 1.0, FlightMode.HOLD) == []
    assert sup.released


def test_mode_lagging_behind_a_command_is_not_read_as_a_takeover():
    sup = OffboardSupervisor(P)
    sup.request_takeoff(5.0)
    sup.step(obs(0.0, FlightMode.READY, armed=False, in_air=False))
    run(sup, 0.05, 1.5, FlightMode.HOLD, setpoints=False)
    run(sup, 1.5, 2.55, FlightMode.HOLD)  # START_OFFBOARD at 2.5
    run(sup, 2.55, 3.3, FlightMode.HOLD)  # heartbeat still says Hold for < mode_grace_s
    assert sup.engagement is Engagement.ENGAGING


def test_a_slow_takeoff_command_gets_its_grace_from_when_it_went_through():
    # The take-off (Hold, PX4's arming checks, arm, take off) took 2.5 s, past mode_grace_s; telemetry still
    # shows the Hold it asked for first while the vehicle climbs in Takeoff: not the end of the take-off.
    sup = OffboardSupervisor(P)
    sup.request_takeoff(5.0)
    assert sup.step(obs(0.0, FlightMode.OFFBOARD, armed=False, in_air=False)) is Command.TAKEOFF
    sup.command_done(2.5)
    run(sup, 2.5, 3.45, FlightMode.HOLD, setpoints=False)  # stale Hold for < mode_grace_s after 2.5 s
    assert sup.engagement is Engagement.TAKING_OFF
    run(sup, 3.45, 6.0, FlightMode.TAKEOFF, setpoints=False)
    assert sup.engagement is Engagement.TAKING_OFF and not sup.released
    run(sup, 6.0, 6.5, FlightMode.HOLD, setpoints=False)  # PX4 holds at height: now engage
    assert sup.engagement is Engagement.ENGAGING


def test_released_vehicle_reengages_on_takeoff_request_in_the_air():
    sup, t = following()
    run(sup, t, t + 2.0, FlightMode.MANUAL)
    sup.request_takeoff(5.0)
    assert sup.step(obs(t + 2.0, FlightMode.MANUAL)) is None
    assert sup.engagement is Engagement.ENGAGING
    assert sup.released_reason is None


def test_land_request_is_latched_and_ignores_setpoints():
    sup, t = following()
    sup.request_land()
    assert sup.step(obs(t, FlightMode.OFFBOARD)) is Command.LAND
    assert not sup.note_setpoint(t + 0.1)
    sup.request_takeoff(5.0)  # no takeoff while landing in the air
    assert run(sup, t + 0.05, t + 1.0, FlightMode.LAND, setpoints=False) == []
    assert sup.engagement is Engagement.LANDING


def test_lost_land_command_is_sent_again():
    sup, t = following()
    sup.request_land()
    sup.step(obs(t, FlightMode.OFFBOARD))
    cmds = run(sup, t + 0.05, t + 2.5, FlightMode.OFFBOARD, setpoints=False)
    assert [c for _, c in cmds] == [Command.LAND]
    assert cmds[0][0] == pytest.approx(t + 2.0)


def test_landing_ends_idle_once_down_and_disarmed():
    sup, t = following()
    sup.request_land()
    sup.step(obs(t, FlightMode.OFFBOARD))
    sup.step(obs(t + 5.0, FlightMode.READY, armed=False, in_air=False))
    assert sup.engagement is Engagement.IDLE


def test_operator_hold_then_new_setpoints_follow_again():
    sup, t = following()
    sup.request_hold()
    assert sup.step(obs(t, FlightMode.OFFBOARD)) is Command.HOLD
    assert sup.engagement is Engagement.HOLDING
    cmds = run(sup, t + 0.05, t + 1.5, FlightMode.HOLD)
    assert [c for _, c in cmds] == [Command.START_OFFBOARD]


def test_refused_takeoff_is_tried_again_after_refused_retry_s_not_every_request():
    sup = OffboardSupervisor(P)
    sup.request_takeoff(5.0)
    sup.step(obs(0.0, FlightMode.READY, armed=False, in_air=False, can_arm=True))
    sup.command_failed(Command.TAKEOFF, 0.1)
    assert sup.takeoff_failed and sup.takeoff_failures == 1
    sup.request_takeoff(5.0)  # the mission keeps asking: no new attempt before refused_retry_s
    cmds = run(sup, 0.2, 6.0, FlightMode.READY, setpoints=False, armed=False, in_air=False, can_arm=True)
    assert [c for _, c in cmds] == [Command.TAKEOFF]
    assert cmds[0][0] == pytest.approx(5.1, abs=0.06)


def test_refused_takeoff_waits_while_px4_says_it_cannot_arm_then_tries_once_it_can():
    sup = OffboardSupervisor(P)
    sup.request_takeoff(5.0)
    sup.step(obs(0.0, FlightMode.READY, armed=False, in_air=False))
    sup.command_failed(Command.TAKEOFF, 0.0)
    ground = {"armed": False, "in_air": False, "setpoints": False}
    assert run(sup, 0.05, 20.0, FlightMode.READY, can_arm=False, **ground) == []
    assert run(sup, 20.0, 20.2, FlightMode.READY, can_arm=True, **ground) == [(20.0, Command.TAKEOFF)]


def test_a_successful_takeoff_clears_the_refusal():
    sup = OffboardSupervisor(P)
    sup.request_takeoff(5.0)
    sup.step(obs(0.0, FlightMode.READY, armed=False, in_air=False))
    sup.command_failed(Command.TAKEOFF, 0.0)
    run(sup, 5.0, 5.2, FlightMode.READY, setpoints=False, armed=False, in_air=False, can_arm=True)
    run(sup, 5.2, 8.0, FlightMode.TAKEOFF, setpoints=False)
    assert not sup.takeoff_failed
    run(sup, 8.0, 9.5, FlightMode.HOLD, setpoints=False)
    assert sup.engagement is Engagement.ENGAGING


def test_px4_failsafe_releases_before_the_watchdog_would_hold():
    sup, t = following()
    # the ground station stalled: its set-points are stale AND PX4 went to Land on its own
    cmd = sup.step(obs(t + 2.0, FlightMode.LAND, failsafe=True))
    assert cmd is None
    assert sup.released and sup.released_reason is not None and "PX4 failsafe" in sup.released_reason
    assert sup.watchdog_holds == 0 and sup.watchdog_landings == 0


def test_no_offboard_start_while_the_link_is_lost():
    sup = OffboardSupervisor(P)
    sup.request_takeoff(5.0)
    sup.step(obs(0.0, FlightMode.READY, armed=False, in_air=False))
    run(sup, 0.05, 1.5, FlightMode.HOLD, setpoints=False)
    assert run(sup, 1.5, 4.0, FlightMode.HOLD, link_lost=True) == []


@pytest.mark.parametrize(
    "kw", [{"hold_after_s": 0.0}, {"hold_after_s": 2.0, "land_after_s": 1.0}, {"prestream_s": -1.0}]
)
def test_params_reject_inconsistent_limits(kw):
    with pytest.raises(ValueError):
        SupervisorParams(**kw)


def test_setpoints_held_back_during_takeoff_do_not_count_as_prestreaming():
    sup = OffboardSupervisor(P)
    sup.request_takeoff(5.0)
    sup.step(obs(0.0, FlightMode.READY, armed=False, in_air=False))
    run(sup, 0.05, 1.0, FlightMode.TAKEOFF)  # the agent starts early; nothing is forwarded while climbing
    cmds = run(sup, 1.0, 3.0, FlightMode.HOLD)  # engaged at 1.0 (after the mode grace): pre-stream from there
    assert cmds == [(2.0, Command.START_OFFBOARD)]


def test_land_request_is_not_sent_while_a_pilot_flies_the_released_vehicle():
    sup, t = following()
    run(sup, t, t + 2.0, FlightMode.MANUAL)
    sup.request_land()  # e.g. the mission re-sending its landing
    assert sup.step(obs(t + 2.0, FlightMode.MANUAL)) is None
    assert sup.ignored_requests == 1 and sup.released


def test_land_request_lands_a_vehicle_released_to_a_px4_failsafe():
    sup, t = following()
    run(sup, t, t + 2.0, FlightMode.RETURN)
    sup.request_land()
    assert sup.step(obs(t + 2.0, FlightMode.RETURN)) is Command.LAND


def test_offboard_read_before_skyring_asked_for_it_is_not_taken_as_engaged():
    sup = OffboardSupervisor(P)
    sup.request_takeoff(5.0)
    sup.step(obs(0.0, FlightMode.READY, armed=False, in_air=False))
    run(sup, 0.05, 1.5, FlightMode.HOLD, setpoints=False)
    assert sup.engagement is Engagement.ENGAGING
    # a stale Offboard reading (e.g. from before a watchdog Hold) while pre-streaming: still engaging
    run(sup, 1.5, 1.7, FlightMode.OFFBOARD)
    assert sup.engagement is Engagement.ENGAGING


def assert_a_6_s_stall_lands_it_as_px4s_failsafe(sup, t):
    """The first step after the whole station stood still 6 s, with telemetry still showing Offboard."""
    cmd = sup.step(
        Observation(now_s=t + 6.0, mode=FlightMode.OFFBOARD, armed=True, in_air=True, stalled_s=6.0)
    )
    assert cmd is Command.LAND
    assert sup.engagement is Engagement.LANDING and sup.failsafe_landing and sup.stall_s == 6.0
    assert sup.watchdog_landings == 0


def test_a_stall_of_the_whole_station_while_following_lands_the_vehicle_as_px4s_failsafe():
    sup, t = following()
    sup.note_setpoint(t + 6.0)  # the agent's first set-point after the stall came in before this step
    assert_a_6_s_stall_lands_it_as_px4s_failsafe(sup, t)


def watchdog_holding():
    """A following supervisor whose agent went quiet: it asked for Hold; returns it and the time reached."""
    sup, t = following()
    sup.note_setpoint(t)
    cmds = run(sup, t + 0.05, t + 0.7, FlightMode.OFFBOARD, setpoints=False)
    assert [c for _, c in cmds] == [Command.HOLD] and sup.engagement is Engagement.WATCHDOG_HOLD
    return sup, t + 0.7


def test_a_stall_before_telemetry_showed_the_watchdogs_hold_lands_the_vehicle_as_px4s_failsafe():
    sup, t = watchdog_holding()
    # the Hold may not have reached PX4 before the whole station stalled: PX4 lost its set-points in Offboard
    assert_a_6_s_stall_lands_it_as_px4s_failsafe(sup, t)


def test_a_stall_in_a_hold_telemetry_shows_is_no_failsafe():
    sup, t = watchdog_holding()
    run(sup, t, t + 1.0, FlightMode.HOLD, setpoints=False)  # PX4 holds: it needs no set-points
    cmd = sup.step(Observation(now_s=t + 1.5, mode=FlightMode.HOLD, armed=True, in_air=True, stalled_s=2.5))
    assert cmd is None and sup.engagement is Engagement.WATCHDOG_HOLD and not sup.failsafe_landing


def test_a_short_gap_in_the_supervisor_is_no_stall():
    sup, t = following()
    sup.note_setpoint(t + 1.0)
    cmd = sup.step(
        Observation(now_s=t + 1.0, mode=FlightMode.OFFBOARD, armed=True, in_air=True, stalled_s=1.0)
    )
    assert cmd is None and sup.engagement is Engagement.FOLLOWING


def test_a_failsafe_px4_reported_but_already_left_lands_the_vehicle():
    sup, t = following()
    sup.note_setpoint(t)
    # PX4 landed it, then MAVSDK's stale set-point took it back to Offboard before skyring looked
    cmd = sup.step(
        Observation(now_s=t, mode=FlightMode.OFFBOARD, armed=True, in_air=True, failsafe_reported=True)
    )
    assert cmd is Command.LAND and sup.failsafe_landing
    run(sup, t + 0.05, t + 3.0, FlightMode.LAND)
    sup.step(obs(t + 3.0, FlightMode.READY, armed=False, in_air=False))
    assert sup.engagement is Engagement.IDLE and not sup.failsafe_landing


def test_a_failsafe_px4_still_runs_is_left_to_px4():
    sup, t = following()
    sup.note_setpoint(t)
    cmd = sup.step(
        Observation(
            now_s=t, mode=FlightMode.LAND, armed=True, in_air=True, failsafe=True, failsafe_reported=True
        )
    )
    assert cmd is None and sup.released and not sup.failsafe_landing
