"""The overlay and the thumbnail that travels to the operator page."""

from __future__ import annotations

import numpy as np

from vehicles.detect.camera_source import CameraState, CameraStatus
from vehicles.detect.overlay import draw_overlay, thumbnail_jpeg
from vehicles.detect.pixels import PersonPixels


def test_thumbnail_is_320_px_wide_and_fits_one_message_even_for_noise():
    import cv2

    noise = np.random.default_rng(0).integers(0, 256, (1086, 2040, 3), dtype=np.uint8)
    jpeg = thumbnail_jpeg(noise, max_bytes=12_000)
    assert len(jpeg) <= 12_000
    image = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert image is not None and image.shape == (170, 320, 3)


def test_overlay_marks_head_and_feet_and_leaves_the_frame_alone():
    frame = np.full((200, 300, 3), 100, np.uint8)
    person = PersonPixels(
        head_px=np.array([150.0, 40.0]),
        feet_px=np.array([150.0, 160.0]),
        head_conf=0.9,
        feet_conf=0.4,
        box_px=np.array([110.0, 20.0, 190.0, 180.0]),
    )
    status = CameraStatus(CameraState.STALLED, 10, 2, 1, 1, 1.5, (300, 200))
    out = draw_overlay(frame, person=person, status=status, fps=4.0, label="MAV 2")
    assert np.all(frame == 100)  # a copy is drawn on
    assert tuple(out[40, 150]) == (40, 40, 230)  # the red head marker
    assert tuple(out[160, 150]) == (40, 40, 230)  # the red feet marker
    assert np.any(out[5:40, 10:200] != 100)  # the status line
