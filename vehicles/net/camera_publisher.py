"""`skyring detect`'s side of the network: its pixel detections and camera reports on the MAV's keys.

    skyring/<team>/agent/<id>/camera         CameraBody        every detection, to the MAV's agent
    skyring/<team>/agent/<id>/camera_report  CameraReportBody  about once a second, to the station

The detector publishes as sender <id> (the MAV it is on) with its own boot stamp; its kinds are its own, so
its sequence numbers never mix with the agent's. It subscribes to nothing.
"""

from __future__ import annotations

from vehicles.detect.pixels import CameraDetection
from vehicles.detect.runner import CameraReport
from vehicles.net import wire
from vehicles.net.keys import agent_key
from vehicles.net.session import Bus, NetConfig


class ZenohCameraSink:
    """A `vehicles.detect.runner.DetectionSink` that publishes over Zenoh as MAV vehicle_id."""

    def __init__(self, config: NetConfig, *, vehicle_id: int, bus: Bus | None = None) -> None:
        self.vehicle_id = int(vehicle_id)
        self._bus = bus or Bus(config, sender=self.vehicle_id, is_member=lambda s: s == self.vehicle_id)
        self._camera_key = agent_key(self._bus.team, self.vehicle_id, "camera")
        self._report_key = agent_key(self._bus.team, self.vehicle_id, "camera_report")
        self.published = 0

    @property
    def bus(self) -> Bus:
        return self._bus

    def detection(self, det: CameraDetection) -> None:
        self._bus.publish(self._camera_key, wire.camera_to_wire(det))
        self.published += 1

    def report(self, rep: CameraReport) -> None:
        self._bus.publish(self._report_key, wire.camera_report_to_wire(rep))

    def close(self) -> None:
        self._bus.close()
