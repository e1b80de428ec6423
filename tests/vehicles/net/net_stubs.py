"""Test doubles for the networked-agent tests."""

from __future__ import annotations

import threading
import time

import numpy as np

from vehicles.autopilot import AutopilotState, FlightMode, Setpoint


class StubAutopilot:
    """A vehicle that obeys at once: takeoff puts it in Hold at the height, land puts it on the ground."""

    def __init__(self, vehicle_id: int = 1) -> None:
        self.vehicle_id = vehicle_id
        self.height = 0.0
        self.mode = FlightMode.READY
        self.setpoints: list[Setpoint] = []
        self.landings = 0
        self.lock = threading.Lock()

    def state(self) -> AutopilotState:
        with self.lock:
            flying = self.height > 0
            return AutopilotState(
                vehicle_id=self.vehicle_id,
                stamp_s=time.time(),
                position_m=np.array([8.0, 0.0, self.height]),
                velocity_mps=np.zeros(3),
                yaw_rad=np.pi,
                armed=flying,
                in_air=flying,
                mode=self.mode,
            )

    def send_setpoint(self, setpoint: Setpoint) -> None:
        with self.lock:
            self.setpoints.append(setpoint)

    def takeoff(self, height_m: float) -> None:
        with self.lock:
            self.height, self.mode = height_m, FlightMode.HOLD

    def hold(self) -> None:
        pass

    def land(self) -> None:
        with self.lock:
            self.height, self.mode = 0.0, FlightMode.READY
            self.landings += 1
