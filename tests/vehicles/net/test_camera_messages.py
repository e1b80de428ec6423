"""The camera's messages on the wire: pixel detections and camera reports, admitted or refused by the guard,
and carried over real Zenoh (two sessions on 127.0.0.1) to the agent's links and the station's page."""

from __future__ import annotations

import math
import time

import numpy as np

from vehicles.detect.camera_source import CameraState, CameraStatus
from vehicles.detect.pixels import CameraDetection, PersonPixels
from vehicles.detect.runner import CameraReport
from vehicles.net import wire
from vehicles.net.guard import MessageGuard, Reason
from vehicles.net.keys import agent_key

TEAM = "alpha"


def _camera(vid: int = 2, head_conf: float = 0.9) -> CameraDetection:
    person = PersonPixels(
        head_px=np.array([100.5, 40.25]),
        feet_px=np.array([104.0, 190.0]),
        head_conf=head_conf,
        feet_conf=0.7,
        box_px=np.array([60.0, 15.0, 145.0, 215.0]),
        score=0.8,
        method="pose",
    )
    return CameraDetection(
        vehicle_id=vid, stamp_s=1000.5, frame_seq=42, image_size_px=(2040, 1086), person=person
    )


def _report(thumb: bytes | None) -> CameraReport:
    status = CameraStatus(CameraState.STALLED, 120, 3, 1, 2, math.inf, (2040, 1086), "no frame for 1.2 s")
    return CameraReport(
        vehicle_id=2, stamp_s=1001.0, camera=status, fps=7.5, detections=90, detector_errors=0, backend="hog",
        thumbnail_jpeg=thumb,
    )  # fmt: skip


def _guard() -> MessageGuard:
    return MessageGuard(team=TEAM, is_member=lambda s: 0 <= s <= 3, clock=lambda: 5.0)


def test_a_camera_detection_round_trips_exactly():
    original = _camera()
    back = wire.camera_from_wire(wire.camera_to_wire(original), vehicle_id=2)
    assert np.array_equal(back.person.head_px, original.person.head_px)
    assert np.array_equal(back.person.feet_px, original.person.feet_px)
    assert back.stamp_s == original.stamp_s and back.frame_seq == 42 and back.image_size_px == (2040, 1086)
    assert back.person.head_conf == 0.9 and back.person.method == "pose"


def test_the_guard_admits_a_camera_message_on_its_own_key():
    payload = wire.encode(team=TEAM, sender=2, boot=1, seq=1, stamp=1.0, body=wire.camera_to_wire(_camera()))
    got = _guard().admit(agent_key(TEAM, 2, "camera"), payload)
    assert got is not None and isinstance(got.body, wire.CameraBody)


def test_a_camera_message_for_another_mav_or_with_a_confidence_above_one_is_refused():
    guard = _guard()
    payload = wire.encode(team=TEAM, sender=2, boot=1, seq=1, stamp=1.0, body=wire.camera_to_wire(_camera()))
    assert guard.admit(agent_key(TEAM, 3, "camera"), payload) is None
    bad = wire.camera_to_wire(_camera())
    forged = wire.encode(
        team=TEAM,
        sender=2,
        boot=1,
        seq=2,
        stamp=1.0,
        body=wire.CameraBody(**{**_fields(bad), "head_conf": 1.5}),
    )
    assert guard.admit(agent_key(TEAM, 2, "camera"), forged) is None
    counts = guard.counts()
    assert counts[Reason.MISMATCHED] == 1 and counts[Reason.MALFORMED] == 1


def _fields(body) -> dict:
    return {f: getattr(body, f) for f in body.__struct_fields__}


def test_a_camera_report_with_its_thumbnail_fits_one_message():
    jpeg = bytes(range(256)) * 46  # 11 776 bytes, under THUMBNAIL_BYTES
    body = wire.camera_report_to_wire(_report(jpeg))
    payload = wire.encode(team=TEAM, sender=2, boot=1, seq=1, stamp=1.0, body=body)
    assert len(payload) <= wire.MAX_MESSAGE_BYTES
    got = _guard().admit(agent_key(TEAM, 2, "camera_report"), payload)
    assert got is not None and isinstance(got.body, wire.CameraReportBody)
    report = got.body
    assert report.thumbnail_jpeg == jpeg
    assert report.state == "stalled" and report.frame_age_s is None and report.message == "no frame for 1.2 s"


def test_a_thumbnail_too_large_for_a_message_is_left_out_not_sent_oversized():
    body = wire.camera_report_to_wire(_report(b"x" * (wire.THUMBNAIL_BYTES + 1)))
    assert body.thumbnail_jpeg is None and body.frames == 120


def test_camera_messages_reach_the_agents_links_and_the_stations_page_over_zenoh():

    import viser

    from server.station.camera_reports import show_camera_reports
    from vehicles.net.camera_publisher import ZenohCameraSink
    from vehicles.net.ports import free_port
    from vehicles.net.session import Bus, NetConfig
    from vehicles.net.zenoh_links import ZenohLinks

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    team = f"cam{int(time.time() * 1000) % 1_000_000}"
    agent_bus = Bus(NetConfig(team=team, listen=(endpoint,), multicast_scouting=False), sender=2,
                    is_member=lambda s: 0 <= s <= 3)  # fmt: skip
    station_bus = Bus(NetConfig(team=team, connect=(endpoint,), multicast_scouting=False), sender=0,
                      is_member=lambda s: 0 <= s <= 3)  # fmt: skip
    sink = ZenohCameraSink(NetConfig(team=team, connect=(endpoint,), multicast_scouting=False), vehicle_id=2)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    thumbs = None
    try:
        links = ZenohLinks(agent_bus, vehicle_id=2)
        thumbs = show_camera_reports(station_bus, server)
        got: list[CameraDetection] = []
        deadline = time.time() + 20
        while time.time() < deadline and (not got or 2 not in thumbs._entries):
            sink.detection(_camera())
            sink.report(_report(b"\xff\xd8jpeg"))
            time.sleep(0.2)
            got.extend(links.own_camera())
        assert got and got[0].vehicle_id == 2 and np.array_equal(got[0].person.head_px, [100.5, 40.25])
        assert 2 in thumbs._entries and "camera stalled" in thumbs._entries[2].content
    finally:
        if thumbs is not None:
            thumbs.close()
        server.stop()
        sink.close()
        station_bus.close()
        agent_bus.close()
