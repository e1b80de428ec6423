"""A simulated multirotor and its autopilot, implementing `vehicles.autopilot.Autopilot`.

Physics: a double integrator whose acceleration follows the commanded one through a first-order lag (the
attitude loop), with PX4-like velocity and acceleration limits. Autopilot: PX4's cascaded position controller
(position P -> velocity set-point with feed-forward -> velocity P -> acceleration, plus the set-point's
acceleration feed-forward, as PX4's trajectory set-points have it), with its modes (takeoff,
hold, offboard, land), the offboard-loss failsafe (no set-point for 0.5 s -> hold), a rate-limited yaw that
follows the command, armed/in-air flags and a slowly draining battery with PX4's kind of battery failsafe
(at `battery_land_fraction` it lands where it is, out of skyring's control, and refuses to arm again). The
autopilot only knows the GPS position, which drifts (`GpsDrift`): it flies the drifted frame, so true and
reported positions differ.

Gains are PX4's defaults (MPC_XY_P 0.95, MPC_XY_VEL_P_ACC 1.8, MPC_Z_P 1, MPC_Z_VEL_P_ACC 4); with the
attitude lag and no acceleration feed-forward they give the way-point tracking error of about 1 m the paper
reports (e_max) when the set-point accelerates at the MPC's input bound; the feed-forward takes most of it
away (tests/vehicles/sim/test_sim_autopilot.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from controller.angles import wrap_angle
from controller.messages import frozen_array, read_only
from vehicles.autopilot import AutopilotState, FlightMode, Setpoint
from vehicles.sim.gps_drift import GpsDrift
from vehicles.world import BodyPose


@dataclass(frozen=True)
class AirframeParams:
    """Gains (1/s), limits (m/s, m/s^2, rad/s), lags and timings (s) of the simulated vehicle and its
    autopilot."""

    position_gain_xy: float = 0.95
    position_gain_z: float = 1.0
    velocity_gain_xy: float = 1.8
    velocity_gain_z: float = 4.0
    max_speed_xy_mps: float = 6.0
    max_climb_mps: float = 3.0
    max_descent_mps: float = 1.5
    max_accel_xy_mps2: float = 4.0
    max_accel_up_mps2: float = 4.0
    max_accel_down_mps2: float = 3.0
    attitude_lag_s: float = 0.15
    yaw_gain: float = 3.0
    max_yaw_rate_radps: float = math.radians(60.0)
    takeoff_speed_mps: float = 1.5
    land_speed_mps: float = 0.7
    setpoint_timeout_s: float = 0.5
    battery_flight_s: float = 1200.0  # a full battery lasts 20 min in the air
    battery_ground_s: float = 12000.0  # armed on the ground
    battery_land_fraction: float = 0.15  # the battery failsafe: land at or below this state of charge
    physics_step_s: float = 0.01
    gravity_mps2: float = 9.81
    position_std_m: tuple[float, float, float] = (0.5, 0.5, 1.0)  # reported self-localisation std


# a cut link is flagged lost after this long (as the PX4 back-end's Px4Config.link_lost_after_s)
LINK_LOST_AFTER_S = 1.0


def _with_link_lost(state: AutopilotState) -> AutopilotState:
    return AutopilotState(
        **{f.name: getattr(state, f.name) for f in fields(AutopilotState) if f.name != "link_lost"},
        link_lost=True,
    )


# The modes the physics step tests, as module constants: reading an enum member through its class costs
# about 70 ns (the metaclass), and the step runs 100 times a second per vehicle.
_OFFBOARD, _TAKEOFF = FlightMode.OFFBOARD, FlightMode.TAKEOFF
_LAND, _READY = FlightMode.LAND, FlightMode.READY
_TO_TARGET = (FlightMode.HOLD, FlightMode.TAKEOFF, FlightMode.LAND)  # fly to the hold/takeoff/land target
_NO_FEED_FORWARD = (0.0, 0.0, 0.0)


def _clip_norm2(x: float, y: float, limit: float) -> tuple[float, float]:
    n = math.hypot(x, y)
    if n > limit:
        return x * limit / n, y * limit / n
    return x, y


def _clamp(x: float, lo: float, hi: float) -> float:
    """max(lo, min(hi, x)), with the builtins' exact semantics (the same comparisons, in the same order)
    at a third of their cost."""
    below = x if x < hi else hi
    return below if below > lo else lo


class SimAutopilot:
    """One simulated vehicle on the ground at `start_position_m` (3,), facing `start_yaw_rad`.

    `advance(now_s)` integrates the physics to now_s in fixed steps; commands take effect from the next step.
    Counters: `refused_commands` (set-points while disarmed or landing, bad takeoff heights, arming on a
    battery at or below the failsafe level), `failsafe_holds` (offboard set-point stream lost),
    `failsafe_landings` (battery failsafe).

    Fault injection (for tests and drills; a real vehicle has no such methods): `set_battery` sets the state
    of charge, `place_at` moves the vehicle, `cut_link` / `restore_link` make its telemetry freeze and its
    commands vanish as over a lost radio link (the vehicle's own offboard-loss failsafe then holds it); the
    frozen telemetry is flagged `link_lost` once it is `LINK_LOST_AFTER_S` old, as the PX4 back-end flags it.
    """

    def __init__(
        self,
        *,
        vehicle_id: int,
        start_position_m,
        start_yaw_rad: float = 0.0,
        drift: GpsDrift,
        params: AirframeParams = AirframeParams(),
    ) -> None:
        self.vehicle_id = int(vehicle_id)
        start = np.asarray(start_position_m, dtype=float)
        if start.shape != (3,) or not np.all(np.isfinite(start)):
            raise ValueError("start_position_m must be three finite numbers")
        self._p = params
        self._drift = drift
        self._pos = [float(start[0]), float(start[1]), max(float(start[2]), 0.0)]
        self._vel = [0.0, 0.0, 0.0]
        self._acc = [0.0, 0.0, 0.0]
        self._yaw = float(start_yaw_rad)
        self._yaw_cmd = self._yaw
        self._t = 0.0
        self._armed = False
        self._in_air = False
        self._mode = FlightMode.READY
        self._battery = 1.0
        self._target = list(self._pos)  # believed-frame position target of hold/takeoff/land
        self._sp_pos = list(self._pos)
        self._sp_vel = [0.0, 0.0, 0.0]
        self._sp_acc = [0.0, 0.0, 0.0]
        self._sp_time = -math.inf
        self._state: AutopilotState | None = None
        self._cov = frozen_array(np.diag(np.square(params.position_std_m)), (3, 3), "position_cov_m2")
        self._failsafe = ""
        self._arming_refused = ""
        self._released = False
        self._cut_state: AutopilotState | None = None
        self.refused_commands = 0
        self.failsafe_holds = 0
        self.failsafe_landings = 0

    # ---- Autopilot protocol -------------------------------------------------------------------------------
    def state(self) -> AutopilotState:
        if self._cut_state is not None:
            if self._t - self._cut_state.stamp_s > LINK_LOST_AFTER_S and not self._cut_state.link_lost:
                self._cut_state = _with_link_lost(self._cut_state)
            return self._cut_state
        if self._state is None:
            off, dv = self._drift.offset, self._drift.velocity
            roll, pitch = self._attitude()
            self._state = AutopilotState(
                vehicle_id=self.vehicle_id,
                stamp_s=self._t,
                position_m=read_only(
                    np.array([self._pos[0] + off[0], self._pos[1] + off[1], self._pos[2] + off[2]])
                ),
                velocity_mps=read_only(
                    np.array([self._vel[0] + dv[0], self._vel[1] + dv[1], self._vel[2] + dv[2]])
                ),
                yaw_rad=self._yaw,
                armed=self._armed,
                in_air=self._in_air,
                mode=self._mode,
                roll_rad=roll,
                pitch_rad=pitch,
                battery_fraction=self._battery,
                healthy=True,
                position_cov_m2=self._cov,
                released=self._released,
                failsafe=bool(self._failsafe),
                failsafe_reason=self._failsafe or None,
                arming_refusal=self._arming_refused or None,
            )
        return self._state

    def send_setpoint(self, setpoint: Setpoint) -> None:
        if self._cut_state is not None:
            return
        if self._released:  # the failsafe has it: set-points are ignored until it is re-engaged by a takeoff
            self.refused_commands += 1
            return
        if not (self._armed and self._in_air) or self._mode in (FlightMode.LAND, FlightMode.TAKEOFF):
            self.refused_commands += 1
            return
        self._sp_pos = setpoint.position_m.tolist()  # Python floats, as float(v) of each would give
        self._sp_vel = setpoint.velocity_mps.tolist()
        self._sp_acc = setpoint.acceleration_mps2.tolist()
        self._yaw_cmd = float(setpoint.yaw_rad)
        self._sp_time = self._t
        self._set_mode(FlightMode.OFFBOARD)

    def takeoff(self, height_m: float) -> None:
        if self._cut_state is not None:
            return
        if not (math.isfinite(height_m) and 0.5 <= height_m <= 100.0) or self._mode == FlightMode.LAND:
            self.refused_commands += 1
            return
        if not self._armed and self._battery <= self._p.battery_land_fraction:
            self.refused_commands += 1
            self._arming_refused = (
                f"battery {self._battery * 100:.0f} % at or below the failsafe level "
                f"{self._p.battery_land_fraction * 100:.0f} %"
            )
            self._state = None
            return
        believed = self._believed()
        self._arming_refused = ""
        self._released = False
        self._failsafe = ""
        self._armed = True
        self._target = [believed[0], believed[1], float(height_m)]
        self._yaw_cmd = self._yaw
        self._set_mode(FlightMode.TAKEOFF)

    def hold(self) -> None:
        if self._cut_state is not None or not self._in_air or self._released:
            return
        self._target = self._believed()
        self._yaw_cmd = self._yaw
        self._set_mode(FlightMode.HOLD)

    def land(self) -> None:
        if self._cut_state is not None:
            return
        if not self._in_air:
            self._armed = False
            self._set_mode(FlightMode.READY)
            return
        self._target = self._believed()
        self._yaw_cmd = self._yaw
        self._set_mode(FlightMode.LAND)

    # ---- fault injection ----------------------------------------------------------------------------------
    def set_battery(self, fraction: float) -> None:
        """Set the state of charge (0..1) at once, as a sagging or mis-reported battery would."""
        if not (math.isfinite(fraction) and 0.0 <= fraction <= 1.0):
            raise ValueError(f"battery fraction must be in [0, 1], got {fraction}")
        self._battery = float(fraction)
        self._state = None

    def place_at(self, position_m) -> None:
        """Move the vehicle's true position to position_m (3,) ENU, at rest (a gust, or a test's set-up)."""
        p = np.asarray(position_m, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)) or p[2] < 0.0:
            raise ValueError("position_m must be three finite numbers with z >= 0")
        self._pos = [float(p[0]), float(p[1]), float(p[2])]
        self._vel = [0.0, 0.0, 0.0]
        self._acc = [0.0, 0.0, 0.0]
        self._state = None

    def cut_link(self) -> None:
        """Lose the radio link: telemetry freezes at its last reading (flagged `link_lost`) and commands no
        longer arrive; the vehicle flies on, and its offboard-loss failsafe holds it."""
        if self._cut_state is None:
            self._cut_state = self.state()

    def restore_link(self) -> None:
        """Get the radio link back: fresh telemetry, commands arrive again."""
        self._cut_state = None
        self._state = None

    # ---- simulation side ----------------------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        return self._t

    def pose(self) -> BodyPose:
        """The true pose now (for cameras and metrics)."""
        roll, pitch = self._attitude()
        return BodyPose(
            vehicle_id=self.vehicle_id,
            stamp_s=self._t,
            position_m=read_only(np.array(self._pos)),
            believed_offset_m=self._drift.offset_m,
            yaw_rad=self._yaw,
            roll_rad=roll,
            pitch_rad=pitch,
            in_air=self._in_air,
            position_cov_m2=self._cov,
        )

    @property
    def true_position_m(self) -> np.ndarray:
        return np.array(self._pos)

    @property
    def in_air(self) -> bool:
        return self._in_air

    def advance(self, now_s: float) -> None:
        """Integrate to now_s in steps of at most physics_step_s."""
        dt_max = self._p.physics_step_s
        while self._t < now_s - 1e-12:
            rest = now_s - self._t
            dt = rest if rest < dt_max else dt_max  # min(dt_max, rest)
            self._step(dt)
            self._t += dt
        self._drift.advance_to(self._t)
        self._state = None

    # ---- internals ----------------------------------------------------------------------------------------
    def _set_mode(self, mode: FlightMode) -> None:
        self._mode = mode
        self._state = None

    def _battery_failsafe(self) -> None:
        """Land where it is, out of skyring's control (PX4's low-battery action): released until re-armed."""
        self.failsafe_landings += 1
        level = self._p.battery_land_fraction * 100
        self._failsafe = f"battery {self._battery * 100:.0f} % at or below {level:.0f} %: landing"
        self._released = True
        self._target = self._believed()
        self._yaw_cmd = self._yaw
        self._set_mode(FlightMode.LAND)

    def _believed(self) -> list[float]:
        """The position the GPS reports. Python floats, not numpy scalars: the same sums, and what the
        physics step computes from them stays in (faster) plain float arithmetic, rounded alike."""
        off = self._drift.offset
        return [self._pos[0] + off[0], self._pos[1] + off[1], self._pos[2] + off[2]]

    def _attitude(self) -> tuple[float, float]:
        if not self._in_air:
            return 0.0, 0.0
        g = self._p.gravity_mps2
        nx, ny, nz = self._acc[0], self._acc[1], self._acc[2] + g
        norm = math.sqrt(nx * nx + ny * ny + nz * nz)
        if norm < 1e-6:
            return 0.0, 0.0
        c, s = math.cos(self._yaw), math.sin(self._yaw)
        forward = (c * nx + s * ny) / norm
        left = (-s * nx + c * ny) / norm
        return -math.asin(max(-1.0, min(1.0, left))), -math.atan2(forward, nz / norm)

    def _velocity_command(self) -> tuple[float, float, float] | None:
        """The velocity set-point of the current mode (believed frame), or None on the ground."""
        p = self._p
        b = self._believed()
        mode = self._mode
        if mode is _OFFBOARD and self._t - self._sp_time > p.setpoint_timeout_s:
            self.failsafe_holds += 1
            self.hold()
            mode = self._mode
        if mode is _OFFBOARD:
            tgt, ff = self._sp_pos, self._sp_vel
        elif mode in _TO_TARGET:
            tgt, ff = self._target, _NO_FEED_FORWARD
        else:
            return None
        vx = ff[0] + p.position_gain_xy * (tgt[0] - b[0])
        vy = ff[1] + p.position_gain_xy * (tgt[1] - b[1])
        vz = ff[2] + p.position_gain_z * (tgt[2] - b[2])
        vx, vy = _clip_norm2(vx, vy, p.max_speed_xy_mps)
        if mode is _TAKEOFF:
            vz = min(vz, p.takeoff_speed_mps)
        elif mode is _LAND:
            vz = -p.land_speed_mps
        return vx, vy, _clamp(vz, -p.max_descent_mps, p.max_climb_mps)

    def _step(self, dt: float) -> None:
        p = self._p
        if self._armed:
            self._battery = max(
                0.0, self._battery - dt / (p.battery_flight_s if self._in_air else p.battery_ground_s)
            )
            if self._in_air and self._battery <= p.battery_land_fraction and not self._failsafe:
                self._battery_failsafe()
        vcmd = self._velocity_command() if self._armed else None
        if vcmd is None:
            self._acc = [0.0, 0.0, 0.0]
            self._vel = [0.0, 0.0, 0.0]
            return
        aff = self._sp_acc if self._mode is _OFFBOARD else _NO_FEED_FORWARD
        acc, vel, pos = self._acc, self._vel, self._pos
        ax = aff[0] + p.velocity_gain_xy * (vcmd[0] - vel[0])
        ay = aff[1] + p.velocity_gain_xy * (vcmd[1] - vel[1])
        az = aff[2] + p.velocity_gain_z * (vcmd[2] - vel[2])
        ax, ay = _clip_norm2(ax, ay, p.max_accel_xy_mps2)
        az = _clamp(az, -p.max_accel_down_mps2, p.max_accel_up_mps2)
        k = min(dt / p.attitude_lag_s, 1.0)
        acc[0] += (ax - acc[0]) * k
        acc[1] += (ay - acc[1]) * k
        acc[2] += (az - acc[2]) * k
        vel[0] += acc[0] * dt
        pos[0] += vel[0] * dt
        vel[1] += acc[1] * dt
        pos[1] += vel[1] * dt
        vel[2] += acc[2] * dt
        pos[2] += vel[2] * dt
        if pos[2] > 0.05:
            self._in_air = True
        if pos[2] <= 0.0:
            pos[2] = 0.0
            vel[2] = max(vel[2], 0.0)
            acc[2] = max(acc[2], 0.0)
            if self._mode is _LAND and self._in_air:
                self._in_air = False
                self._armed = False
                self._vel = [0.0, 0.0, 0.0]
                self._acc = [0.0, 0.0, 0.0]
                self._mode = _READY
                self._failsafe = ""  # the failsafe's landing is done; arming stays refused on a low battery
        if self._mode is _TAKEOFF and abs(self._target[2] - self._believed()[2]) < 0.2:
            b = self._believed()
            self._target = [b[0], b[1], self._target[2]]
            self._mode = FlightMode.HOLD
        err = wrap_angle(self._yaw_cmd - self._yaw)
        rate = _clamp(p.yaw_gain * err, -p.max_yaw_rate_radps, p.max_yaw_rate_radps)
        self._yaw = wrap_angle(self._yaw + rate * dt)
