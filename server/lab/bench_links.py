"""`skyring bench links`: the Zenoh links of a 16-MAV team on 127.0.0.1.

Sixteen Zenoh peer sessions in one process (multicast scouting off, each connected to a hub endpoint and
meshed by Zenoh's gossip), each playing one MAV: it publishes its horizon plan (N = 15: 17 states) at 10 Hz
and a detection at 4 Hz, staggered, through the real wire format, and subscribes to every teammate's plans
and detections through the real guard. Latency is receive time minus the header stamp (one clock: one
machine), so it includes encoding, Zenoh, the guard and decoding, and the wait for Python's GIL behind the
other fifteen receivers (a real MAV has a process of its own). Bytes per second are the encoded messages
each MAV publishes; received is what each MAV's session takes in from its 15 teammates.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from controller.messages import Detection, HorizonPlan
from vehicles.net import wire
from vehicles.net.guard import Received
from vehicles.net.keys import agent_key, all_agents_key
from vehicles.net.ports import free_port
from vehicles.net.session import Bus, NetConfig

MAVS = 16
PLAN_HZ = 10.0
DETECTION_HZ = 4.0


def run(*, repeats: int) -> None:
    """Publish for repeats / 20 seconds (200 -> 10 s) and print latency and bandwidth."""
    duration_s = max(repeats / 20.0, 2.0)
    team = f"bench{int(time.time())}"
    hub = f"tcp/127.0.0.1:{free_port()}"
    member = lambda s: 1 <= s <= MAVS  # noqa: E731
    buses = [Bus(NetConfig(team=team, listen=(hub,), multicast_scouting=False), sender=1, is_member=member)]
    for vid in range(2, MAVS + 1):
        own = f"tcp/127.0.0.1:{free_port()}"
        config = NetConfig(team=team, connect=(hub,), listen=(own,), multicast_scouting=False)
        buses.append(Bus(config, sender=vid, is_member=member))
    lock = threading.Lock()
    latencies: dict[str, list[float]] = {"plan": [], "detection": []}
    received_bytes = [0] * MAVS
    recording = threading.Event()

    def receiver(index: int):
        def on(msg: Received) -> None:
            if msg.header.sender == index + 1 or not recording.is_set():
                return
            with lock:
                latencies[msg.header.kind].append(msg.received_s - msg.header.stamp)
                received_bytes[index] += 1

        return on

    for i, bus in enumerate(buses):
        bus.subscribe(all_agents_key(team, "plan"), receiver(i))
        bus.subscribe(all_agents_key(team, "detection"), receiver(i))
    time.sleep(2.0)  # let the mesh and the subscriptions settle
    plans = [
        wire.plan_to_wire(
            HorizonPlan(
                vehicle_id=vid,
                stamp_s=0.0,
                dt_s=0.1,
                positions_m=np.random.default_rng(vid).normal(size=(17, 3)),
                velocities_mps=np.random.default_rng(vid + 100).normal(size=(17, 3)),
            ),
            phase="formation",
        )
        for vid in range(1, MAVS + 1)
    ]
    detection = wire.detection_to_wire(
        Detection(source_id=1, stamp_s=0.0, position_m=np.array([1.0, 2.0, 0.9]), cov_m2=np.eye(3) * 0.2)
    )
    sent_before = [b.sent_bytes for b in buses]
    recording.set()
    start = time.monotonic()
    events = sorted(
        [
            (k / PLAN_HZ + i / (MAVS * PLAN_HZ), i, "plan")
            for i in range(MAVS)
            for k in range(int(duration_s * PLAN_HZ))
        ]
        + [
            (k / DETECTION_HZ + i / (MAVS * DETECTION_HZ), i, "detection")
            for i in range(MAVS)
            for k in range(int(duration_s * DETECTION_HZ))
        ]
    )
    for at, i, kind in events:
        delay = start + at - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        vid = i + 1
        body = plans[i] if kind == "plan" else detection
        buses[i].publish(agent_key(team, vid, kind), body)
    time.sleep(0.5)
    recording.clear()
    elapsed = time.monotonic() - start - 0.5
    sent = [b.sent_bytes - s for b, s in zip(buses, sent_before, strict=True)]
    for bus in buses:
        bus.close()
    print(
        f"links: {MAVS} MAVs on Zenoh over 127.0.0.1 (one process, {MAVS} peer sessions), plans at "
        f"{PLAN_HZ:g} Hz + detections at {DETECTION_HZ:g} Hz each, {elapsed:.1f} s"
    )
    plan_bytes = len(wire.encode(team=team, sender=1, boot=1, seq=1, stamp=1.0, body=plans[0]))
    det_bytes = len(wire.encode(team=team, sender=1, boot=1, seq=1, stamp=1.0, body=detection))
    print(f"  message size: plan {plan_bytes} B, detection {det_bytes} B (bound {wire.MAX_MESSAGE_BYTES} B)")
    expected = {
        "plan": MAVS * (MAVS - 1) * int(duration_s * PLAN_HZ),
        "detection": MAVS * (MAVS - 1) * int(duration_s * DETECTION_HZ),
    }
    print(f"  {'kind':<10} {'delivered':>12} {'latency p50':>12} {'p99':>9}")
    for kind, values in latencies.items():
        arr = np.array(values) * 1e3
        p50, p99 = (np.percentile(arr, 50), np.percentile(arr, 99)) if len(arr) else (float("nan"),) * 2
        print(f"  {kind:<10} {len(arr):>6}/{expected[kind]:<5} {p50:>9.2f} ms {p99:>6.2f} ms")
    per_mav = np.array(sent) / elapsed
    incoming = sum(expected.values()) / MAVS / max(duration_s, 1e-9)
    print(
        f"  published per MAV: {np.mean(per_mav):.0f} B/s mean "
        f"({np.min(per_mav):.0f}-{np.max(per_mav):.0f}); "
        f"received per MAV: {np.mean(per_mav) * (MAVS - 1):.0f} B/s ({incoming:.0f} messages/s)"
    )
