"""An emulated onboard camera and detector for one MAV flying a real (or PX4 SITL) autopilot.

Until a real detector runs beside the agent, `skyring agent --emulate-camera PERSON` runs this: the embedded
person model and the camera/detector model (`vehicles.sim.world`) looking from the vehicle's own telemetry
pose, on its own thread at the detector's rate, publishing each detection on the MAV's detection key exactly
as an onboard detector process would (another process may publish there instead: see docs/agents.md).
World time t is UTC minus `epoch_utc`, so every MAV whose emulator shares the epoch sees the same person.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import replace

import numpy as np

from vehicles.autopilot import Autopilot
from vehicles.net import wire
from vehicles.net.keys import agent_key
from vehicles.net.session import Bus
from vehicles.sim.scenario import SeedStreams, make_person
from vehicles.sim.world import SimWorld, TelemetryBody

log = logging.getLogger(__name__)


class EmulatedCamera:
    """Detections of the `person` model ("still", "paper" or "random") from `autopilot`'s pose."""

    def __init__(
        self,
        *,
        bus: Bus,
        autopilot: Autopilot,
        person: str,
        epoch_utc: float,
        seed: int = 0,
        rate_hz: float = 20.0,
    ) -> None:
        streams = SeedStreams.from_seed(seed)
        vid = autopilot.vehicle_id
        rng = np.random.default_rng(np.random.SeedSequence([seed, vid]))
        self._world = SimWorld(
            person=make_person(person, streams),
            obstacles=(),
            bodies=[TelemetryBody(autopilot)],
            rngs={vid: rng},
            start_s=max(0.0, time.time() - epoch_utc),
        )
        self._bus = bus
        self._vid = vid
        self._key = agent_key(bus.team, vid, "detection")
        self.epoch_utc = epoch_utc
        self._period = 1.0 / rate_hz
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.published = 0

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name=f"camera-{self._vid}", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)

    def step(self, now_utc: float) -> None:
        t = now_utc - self.epoch_utc
        if t <= self._world.time_s:
            return
        self._world.advance(t)
        for det in self._world.detections(self._vid):
            moved = replace(det, stamp_s=det.stamp_s + self.epoch_utc)
            self._bus.publish(self._key, wire.detection_to_wire(moved))
            self.published += 1

    def _run(self) -> None:
        while not self._stop.wait(self._period):
            try:
                self.step(time.time())
            except Exception:  # noqa: BLE001 - a camera fault must not stop anything else
                log.exception("emulated camera of MAV %d failed", self._vid)
