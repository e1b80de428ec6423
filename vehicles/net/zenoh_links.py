"""The networked `Links` back-end: horizon plans and detections between teammates over Zenoh.

One `ZenohLinks` per agent process. `send` publishes this MAV's plan on its plan key (with its mission phase,
for the teammates' rosters). A detector that publishes world-frame detections on the MAV's detection key
(`vehicles.net.keys`; the emulated camera) is heard there by teammates and this agent alike, so those are
not re-sent; the pixel detections of `skyring detect` arrive on the MAV's camera key (`own_camera`), the
agent converts them with its pose, and `send` publishes the resulting detections on the detection key for
the teammates. Received messages
are queued by Zenoh's threads (bounded: the oldest are dropped and counted when a tick is late) and drained by
the control tick: teammates' plans and detections through `receive`, the own camera's through
`own_detections`. Values the domain types refuse (non-finite, wrong shapes) are counted as invalid.
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass

from controller.messages import Detection, HorizonPlan
from vehicles.detect.pixels import CameraDetection
from vehicles.links import Message
from vehicles.net import wire
from vehicles.net.guard import Reason, Received
from vehicles.net.keys import agent_key, all_agents_key
from vehicles.net.session import Bus

QUEUE_LIMIT = 1024


@dataclass(frozen=True, eq=False)
class Heard:
    """A teammate's last plan: when it arrived (receiver's UTC), the teammate's phase, the plan."""

    received_s: float
    phase: str
    plan: HorizonPlan


class ZenohLinks:
    """Broadcast between the agents of one team over the Zenoh `bus`, as MAV `vehicle_id`."""

    def __init__(self, bus: Bus, *, vehicle_id: int, queue_limit: int = QUEUE_LIMIT) -> None:
        self._bus = bus
        self.vehicle_id = int(vehicle_id)
        self.phase = ""
        self._lock = threading.Lock()
        self._received: deque[Message] = deque()
        self._own: deque[Detection] = deque()
        self._camera: deque[CameraDetection] = deque()
        self._heard_own: set[Detection] = set()  # own detections drained last: heard on the key, not re-sent
        self._heard: dict[int, Heard] = {}
        self._limit = queue_limit
        self.sent_plans = 0
        self.skipped_detections = 0
        self.sent_detections = 0
        bus.subscribe(all_agents_key(bus.team, "plan"), self._on_plan)
        bus.subscribe(all_agents_key(bus.team, "detection"), self._on_detection)
        bus.subscribe(agent_key(bus.team, self.vehicle_id, "camera"), self._on_camera)

    # ---- the Links protocol -------------------------------------------------------------------------------
    def send(self, now_s: float, sender_id: int, message: Message) -> None:
        if isinstance(message, HorizonPlan) and sender_id == self.vehicle_id:
            self._bus.publish(
                agent_key(self._bus.team, self.vehicle_id, "plan"),
                wire.plan_to_wire(message, phase=self.phase),
            )
            self.sent_plans += 1
        elif (
            isinstance(message, Detection) and sender_id == self.vehicle_id and message not in self._heard_own
        ):
            self._bus.publish(
                agent_key(self._bus.team, self.vehicle_id, "detection"), wire.detection_to_wire(message)
            )
            self.sent_detections += 1  # made here from the camera's pixels
        else:
            self.skipped_detections += 1  # the detector published it itself

    def receive(self, now_s: float, receiver_id: int) -> tuple[Message, ...]:
        with self._lock:
            out = tuple(self._received)
            self._received.clear()
        return out

    # ---- beyond the protocol ------------------------------------------------------------------------------
    def own_detections(self) -> tuple[Detection, ...]:
        """This MAV's own camera detections received since the last call, oldest first."""
        with self._lock:
            out = tuple(self._own)
            self._own.clear()
        self._heard_own = set(out)
        return out

    def own_camera(self) -> tuple[CameraDetection, ...]:
        """The pixel detections of this MAV's `skyring detect` received since the last call, oldest first."""
        with self._lock:
            out = tuple(self._camera)
            self._camera.clear()
        return out

    def heard(self) -> dict[int, Heard]:
        """Every teammate heard so far, by id, with its last plan."""
        with self._lock:
            return dict(self._heard)

    def _on_plan(self, msg: Received) -> None:
        sender = msg.header.sender
        if sender == self.vehicle_id:
            return  # our own plan, echoed by Zenoh
        assert isinstance(msg.body, wire.PlanBody)
        try:
            plan = wire.plan_from_wire(msg.body, vehicle_id=sender)
        except ValueError:
            self._bus.guard.count(Reason.INVALID)
            return
        with self._lock:
            self._heard[sender] = Heard(received_s=msg.received_s, phase=msg.body.phase, plan=plan)
            self._push(self._received, plan)

    def _on_detection(self, msg: Received) -> None:
        assert isinstance(msg.body, wire.DetectionBody)
        try:
            detection = wire.detection_from_wire(msg.body, source_id=msg.header.sender)
        except ValueError:
            self._bus.guard.count(Reason.INVALID)
            return
        with self._lock:
            self._push(self._own if detection.source_id == self.vehicle_id else self._received, detection)

    def _on_camera(self, msg: Received) -> None:
        assert isinstance(msg.body, wire.CameraBody)
        try:
            detection = wire.camera_from_wire(msg.body, vehicle_id=msg.header.sender)
        except ValueError:
            self._bus.guard.count(Reason.INVALID)
            return
        with self._lock:
            self._push(self._camera, detection)

    def _push(self, queue: deque, item: object) -> None:
        if len(queue) >= self._limit:
            queue.popleft()
            self._bus.guard.count(Reason.OVERFLOW)
        queue.append(item)
