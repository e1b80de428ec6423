"""The rehearsal's simulated vehicles over Zenoh: the world process serves them, each agent flies its own.

`SimWorldServer` (world process) steps the embedded `SimWorld` in real time on its own thread, publishes each
vehicle's telemetry on `sim/<id>/telemetry` and each camera's detections on `agent/<id>/detection` (as the
onboard detector would: the same key and message), and applies the autopilot requests it receives on
`sim/<id>/autopilot`. `RemoteAutopilot` (agent process) is the `Autopilot` the agent flies: its state is the
latest telemetry (flagged link_lost after `link_lost_after_s` of silence, as the PX4 back-end does), its
commands are messages. World time t maps to UTC as epoch + t, so every stamp on the network is UTC.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import replace

from vehicles.autopilot import AutopilotState, Setpoint
from vehicles.net import wire
from vehicles.net.guard import Reason, Received
from vehicles.net.keys import agent_key, all_sim_key, sim_key
from vehicles.net.session import Bus
from vehicles.sim.autopilot import SimAutopilot
from vehicles.sim.world import SimWorld
from vehicles.world import PersonTruth

log = logging.getLogger(__name__)


def _vec3(values) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in values)
    return x, y, z


class RemoteAutopilot:
    """A simulated vehicle served by a world process, behind the `Autopilot` protocol."""

    def __init__(
        self,
        bus: Bus,
        *,
        vehicle_id: int,
        link_lost_after_s: float = 1.0,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.vehicle_id = int(vehicle_id)
        self._bus = bus
        self._clock = clock
        self._lost_after = link_lost_after_s
        self._lock = threading.Lock()
        self._state: AutopilotState | None = None
        self._received_s = -math.inf
        self._key = sim_key(bus.team, self.vehicle_id, "autopilot")
        bus.subscribe(sim_key(bus.team, self.vehicle_id, "telemetry"), self._on_telemetry)

    def _on_telemetry(self, msg: Received) -> None:
        assert isinstance(msg.body, wire.TelemetryBody)
        try:
            state = wire.telemetry_from_wire(msg.body, vehicle_id=self.vehicle_id)
        except ValueError:
            self._bus.guard.count(Reason.INVALID)
            return
        with self._lock:
            if self._state is None or state.stamp_s >= self._state.stamp_s:
                self._state, self._received_s = state, msg.received_s

    def state(self) -> AutopilotState | None:
        with self._lock:
            state, received = self._state, self._received_s
        if state is None:
            return None
        if self._clock() - received > self._lost_after:
            return replace(state, link_lost=True)
        return state

    def send_setpoint(self, setpoint: Setpoint) -> None:
        self._bus.publish(self._key, wire.setpoint_command(setpoint))

    def takeoff(self, height_m: float) -> None:
        self._bus.publish(self._key, wire.AutopilotCommandBody(action="takeoff", height_m=float(height_m)))

    def hold(self) -> None:
        self._bus.publish(self._key, wire.AutopilotCommandBody(action="hold"))

    def land(self) -> None:
        self._bus.publish(self._key, wire.AutopilotCommandBody(action="land"))


class SimWorldServer:
    """Serves `world`'s vehicles (`autopilots` by id) on `bus` in real time from `start()` until `stop()`.

    epoch_utc: the UTC time of world time 0; rate_hz: world steps (and telemetry messages) per second.
    """

    def __init__(
        self,
        *,
        bus: Bus,
        world: SimWorld,
        autopilots: Mapping[int, SimAutopilot],
        rate_hz: float = 50.0,
        epoch_utc: float | None = None,
    ) -> None:
        self._bus = bus
        self.world = world
        self._autopilots = dict(autopilots)
        self._period = 1.0 / rate_hz
        self.epoch_utc = time.time() if epoch_utc is None else epoch_utc
        self._requests: deque[Received] = deque(maxlen=4096)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._truth: PersonTruth | None = None
        self.refused_requests = 0
        self.step_errors = 0
        bus.subscribe(all_sim_key(bus.team, "autopilot"), self._on_request)

    def person_truth(self) -> PersonTruth | None:
        """The person's true state, stamped in UTC (for the station's display and metrics)."""
        with self._lock:
            return self._truth

    def true_positions(self) -> dict[int, tuple[float, float, float]]:
        """Each vehicle's true position now, by id (for tests and metrics)."""
        with self._lock:
            return {vid: _vec3(a.true_position_m) for vid, a in self._autopilots.items()}

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="sim-world", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)

    def _on_request(self, msg: Received) -> None:
        if msg.header.sender in self._autopilots:
            with self._lock:
                self._requests.append(msg)

    def _run(self) -> None:
        start = time.monotonic()
        next_step = start
        while not self._stop.is_set():
            try:
                self.step(time.monotonic() - start)
            except Exception:  # noqa: BLE001 - the world must go on for the other vehicles
                self.step_errors += 1
                log.exception("world step failed")
            next_step += self._period
            delay = next_step - time.monotonic()
            if delay < -1.0:
                next_step = time.monotonic()
            elif delay > 0:
                self._stop.wait(delay)

    def step(self, t_s: float) -> None:
        """Apply the requests received, advance the world to t_s, publish telemetry and detections."""
        with self._lock:
            requests = list(self._requests)
            self._requests.clear()
            for msg in requests:
                self._apply(msg)
            if t_s > self.world.time_s:
                self.world.advance(t_s)
            truth = self.world.person_truth()
            self._truth = replace(truth, stamp_s=truth.stamp_s + self.epoch_utc)
            states = {vid: a.state() for vid, a in self._autopilots.items()}
            detections = {vid: self.world.detections(vid) for vid in self._autopilots}
        team = self._bus.team
        for vid, state in states.items():
            body = wire.telemetry_to_wire(state, stamp_s=state.stamp_s + self.epoch_utc)
            self._bus.publish(sim_key(team, vid, "telemetry"), body, sender=vid)
            for det in detections[vid]:
                moved = replace(det, stamp_s=det.stamp_s + self.epoch_utc)
                self._bus.publish(
                    agent_key(team, vid, "detection"), wire.detection_to_wire(moved), sender=vid
                )

    def _apply(self, msg: Received) -> None:
        body = msg.body
        assert isinstance(body, wire.AutopilotCommandBody)
        autopilot = self._autopilots[msg.header.sender]
        if body.action == "setpoint":
            try:
                autopilot.send_setpoint(wire.setpoint_from_wire(body, stamp_s=autopilot.time_s))
            except ValueError:
                self.refused_requests += 1
        elif body.action == "takeoff":
            autopilot.takeoff(body.height_m)
        elif body.action == "hold":
            autopilot.hold()
        elif body.action == "land":
            autopilot.land()
        else:
            self.refused_requests += 1
