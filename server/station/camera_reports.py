"""The station's view of each MAV's camera: `skyring detect`'s reports shown as thumbnails in the page."""

from __future__ import annotations

import threading

import viser

from vehicles.net import wire
from vehicles.net.guard import Received
from vehicles.net.keys import all_agents_key
from vehicles.net.session import Bus
from webui.detection_thumbnails import DetectionThumbnails


def caption(body: wire.CameraReportBody) -> str:
    """One line: camera state, frame rate, detections, and the last problem if the camera is not well."""
    text = f"camera {body.state} · {body.fps:.1f} fps · {body.detections} detections"
    if body.state != "streaming" or body.detector_errors:
        text += f" · {body.message}" if body.message else ""
    return text


def show_camera_reports(
    bus: Bus, server: viser.ViserServer, *, stale_after_s: float = 3.0
) -> DetectionThumbnails:
    """Subscribe to every MAV's camera report and keep its thumbnail in the operator page (1 Hz at most); a
    daemon thread flags, once a second, the MAVs whose reports stopped for stale_after_s (until
    `thumbs.close()`)."""
    thumbs = DetectionThumbnails(server)

    def watch() -> None:
        while not thumbs.closed.wait(1.0):
            thumbs.mark_stale(max_age_s=stale_after_s)

    threading.Thread(target=watch, name="camera-reports", daemon=True).start()

    def on_report(msg: Received) -> None:
        body = msg.body
        assert isinstance(body, wire.CameraReportBody)
        thumbs.update(msg.header.sender, body.thumbnail_jpeg, caption(body))

    bus.subscribe(all_agents_key(bus.team, "camera_report"), on_report)
    return thumbs
