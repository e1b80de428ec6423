"""The operator page's detection thumbnails in a real viser page in Debian's chromium."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

FOOTAGE = Path("/usr/share/doc/opencv-doc/examples/data/vtest.avi")
SHOTS = Path(__file__).resolve().parents[2] / "test-artifacts"
IMG = "document.querySelector('img.skyring-thumb')"


def _jpeg() -> bytes:
    import cv2

    if not FOOTAGE.is_file():
        pytest.fail(f"{FOOTAGE} is missing: `make footage` installs Debian's opencv-doc", pytrace=False)
    cap = cv2.VideoCapture(str(FOOTAGE))
    ok, frame = cap.read()
    cap.release()
    assert ok
    from vehicles.detect.overlay import thumbnail_jpeg

    return thumbnail_jpeg(frame)


def test_updates_faster_than_once_a_second_are_dropped():
    import viser

    from webui.detection_thumbnails import DetectionThumbnails

    now = [0.0]
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        thumbs = DetectionThumbnails(server, clock=lambda: now[0])
        assert thumbs.update(1, b"\xff\xd8", "streaming")
        now[0] = 0.4
        assert not thumbs.update(1, b"\xff\xd8", "streaming")
        assert thumbs.update(2, b"\xff\xd8", "streaming")  # per MAV
        now[0] = 1.1
        assert thumbs.update(1, b"\xff\xd8", "stalled")
        assert thumbs.dropped == 1
    finally:
        server.stop()


def test_a_mav_whose_reports_stop_is_flagged_with_the_age_of_its_picture():
    import viser

    from webui.detection_thumbnails import DetectionThumbnails

    now = [0.0]
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        thumbs = DetectionThumbnails(server, clock=lambda: now[0])
        thumbs.update(1, b"\xff\xd8", "camera streaming")
        thumbs.update(2, b"\xff\xd8", "camera streaming")
        now[0] = 2.0
        thumbs.update(2, b"\xff\xd8", "camera streaming")
        now[0] = 4.5
        assert thumbs.mark_stale(max_age_s=3.0) == [1]
        assert "NO REPORT for 4 s" in thumbs._entries[1].content
        assert "NO REPORT" not in thumbs._entries[2].content
        thumbs.update(1, b"\xff\xd8", "camera streaming")  # it is back
        assert "NO REPORT" not in thumbs._entries[1].content
    finally:
        server.stop()


def test_caption_is_escaped():
    from webui.detection_thumbnails import thumbnail_html

    html = thumbnail_html(3, None, "<script>x</script>")
    assert "<script>" not in html and "&lt;script&gt;" in html and "no picture yet" in html


@pytest.mark.browser
def test_each_mavs_thumbnail_shows_in_the_page(browser):
    import viser

    from webui.detection_thumbnails import DetectionThumbnails

    jpeg = _jpeg()
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        thumbs = DetectionThumbnails(server)
        thumbs.update(1, jpeg, "camera streaming · 9.8 fps · person")
        thumbs.update(2, None, "camera disconnected: cannot open rtsp://…")
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.goto(f"http://127.0.0.1:{server.get_port()}/")
        img = page.locator('img.skyring-thumb[data-vehicle="1"]')
        img.wait_for(state="visible", timeout=30_000)
        page.wait_for_function(
            f"() => {{ const i = {IMG}; return i && i.naturalWidth > 0; }}", timeout=30_000
        )
        size = page.evaluate(f"() => {{ const i = {IMG}; return [i.naturalWidth, i.naturalHeight]; }}")
        assert size == [320, 240]
        assert page.get_by_text("camera disconnected").is_visible()
        SHOTS.mkdir(exist_ok=True)
        page.screenshot(path=str(SHOTS / "detection-thumbnails.png"))
        # A newer picture replaces the old one in place.
        black = np.zeros((10, 10), np.uint8)
        import cv2

        thumbs._shown_at.clear()  # the test's own second update, not a flood
        thumbs.update(1, cv2.imencode(".jpg", cv2.resize(black, (320, 100)))[1].tobytes(), "camera stalled")
        page.wait_for_function(
            f"() => {{ const i = {IMG}; return i && i.naturalHeight === 100; }}", timeout=30_000
        )
        assert page.get_by_text("camera stalled").is_visible()
        page.close()
    finally:
        server.stop()
