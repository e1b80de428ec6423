"""Camera sources on real video: capture stamps, file end, corrupt data, and a network camera that stalls
and disconnects (an MJPEG-over-HTTP server on 127.0.0.1, as many IP cameras serve)."""

from __future__ import annotations

import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
import pytest
from detect_footage import footage

from vehicles.detect.camera_source import (
    CameraReader,
    CameraState,
    ReaderParams,
    SourceKind,
    parse_source,
)


def test_sources_are_recognised_by_their_form(tmp_path):
    video = tmp_path / "a.avi"
    video.write_bytes(b"x")
    assert parse_source("0").kind == SourceKind.DEVICE
    assert parse_source("/dev/video2").kind == SourceKind.DEVICE
    assert parse_source("rtsp://10.0.0.5:8554/cam").kind == SourceKind.URL
    assert parse_source("udpsrc port=5000 ! decodebin ! appsink").kind == SourceKind.GSTREAMER
    assert parse_source(str(video)).kind == SourceKind.FILE
    with pytest.raises(ValueError, match="no such video file"):
        parse_source(str(tmp_path / "missing.avi"))


def test_a_file_plays_at_its_frame_rate_with_capture_stamps():
    clock_start = time.time()
    with CameraReader(parse_source(str(footage("vtest.avi"))), ReaderParams(realtime=True)) as reader:
        stamps, seqs = [], []
        seq = -1
        while len(stamps) < 12:
            frame = reader.wait(seq, 2.0)
            assert frame is not None
            assert frame.image.shape == (576, 768, 3)
            stamps.append(frame.stamp_s)
            seqs.append(frame.seq)
            seq = frame.seq
        status = reader.status()
    assert stamps[0] >= clock_start
    assert np.all(np.diff(stamps) > 0)
    # vtest.avi is 10 frames per second: 0.1 s of capture time per frame, however many frames the (possibly
    # slow) test skipped.
    period = (stamps[-1] - stamps[0]) / (seqs[-1] - seqs[0])
    assert period == pytest.approx(0.1, abs=0.02)
    assert status.state == CameraState.STREAMING and status.size_px == (768, 576)


def test_a_file_ends_and_is_reported_ended():
    params = ReaderParams(realtime=False)
    with CameraReader(parse_source(str(footage("vtest.avi"))), params) as reader:
        deadline = time.time() + 60
        while reader.status().state != CameraState.ENDED and time.time() < deadline:
            time.sleep(0.05)
        status = reader.status()
    assert status.state == CameraState.ENDED
    assert status.frames == 795 and status.corrupt == 0


def test_a_damaged_file_is_read_past_its_damage(tmp_path):
    data = bytearray(footage("vtest.avi").read_bytes())
    rng = np.random.default_rng(1)
    for start in (len(data) // 3, len(data) // 2):  # two stretches of garbage inside the stream
        data[start : start + 40_000] = rng.integers(0, 256, 40_000, dtype=np.uint8).tobytes()
    bad = tmp_path / "damaged.avi"
    bad.write_bytes(bytes(data))
    with CameraReader(parse_source(str(bad)), ReaderParams(realtime=False)) as reader:
        deadline = time.time() + 60
        while reader.status().state not in (CameraState.ENDED,) and time.time() < deadline:
            time.sleep(0.05)
        status = reader.status()
    assert status.state == CameraState.ENDED
    assert status.frames > 600  # frames after the damage were read


def test_frames_of_another_size_than_expected_are_dropped_as_corrupt():
    params = ReaderParams(realtime=True, expected_size_px=(2040, 1086))
    with CameraReader(parse_source(str(footage("vtest.avi"))), params) as reader:
        time.sleep(1.0)
        status = reader.status()
    assert status.frames == 0 and status.corrupt > 0
    assert "expected 2040 x 1086" in status.message


class _Camera:
    """An MJPEG-over-HTTP camera on 127.0.0.1 that can be told to freeze and to drop its clients."""

    def __init__(self, jpegs: list[bytes]) -> None:
        self.jpegs = jpegs
        self.frozen = threading.Event()
        self.cut = threading.Event()
        self.connections = 0
        owner = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802
                owner.connections += 1
                self.send_response(200)
                self.send_header("Content-Type", "multipart/x-mixed-replace; boundary=frame")
                self.end_headers()
                i = 0
                while not owner.cut.is_set():
                    if owner.frozen.is_set():
                        time.sleep(0.02)
                        continue
                    jpg = owner.jpegs[i % len(owner.jpegs)]
                    head = b"--frame\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n\r\n" % len(jpg)
                    try:
                        self.wfile.write(head + jpg + b"\r\n")
                    except OSError:
                        return
                    i += 1
                    time.sleep(0.05)

            def log_message(self, format: str, *args: object) -> None:  # noqa: A002 - http.server's name
                return None

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server.server_address[1]}/video.mjpg"

    def close(self) -> None:
        self.cut.set()
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def ip_camera():
    import cv2

    cap = cv2.VideoCapture(str(footage("vtest.avi")))
    jpegs = []
    for _ in range(20):
        ok, img = cap.read()
        jpegs.append(cv2.imencode(".jpg", img)[1].tobytes())
    cap.release()
    cam = _Camera(jpegs)
    yield cam
    cam.close()


def _wait_for(reader: CameraReader, state: CameraState, timeout_s: float) -> bool:
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        if reader.status().state == state:
            return True
        time.sleep(0.02)
    return False


def test_a_network_camera_that_stalls_is_reported_and_reopened(ip_camera):
    params = ReaderParams(stall_s=0.5, read_timeout_s=1.0, retry_s=0.2)
    with CameraReader(parse_source(ip_camera.url), params) as reader:
        assert _wait_for(reader, CameraState.STREAMING, 10)
        ip_camera.frozen.set()
        assert _wait_for(reader, CameraState.STALLED, 5)
        t_stalled = time.time()
        assert reader.latest() is not None  # the last good frame stays available: nobody waits
        time.sleep(1.5)  # frozen beyond the read time-out
        ip_camera.frozen.clear()
        assert _wait_for(reader, CameraState.STREAMING, 10)
        status = reader.status()
    assert status.stalls >= 1
    assert status.reconnects >= 1  # FFmpeg's read time-out ended the frozen connection; the reader reopened
    assert time.time() - t_stalled < 10


def test_a_network_camera_that_disconnects_is_retried_until_it_returns(ip_camera):
    params = ReaderParams(stall_s=0.5, read_timeout_s=1.0, retry_s=0.2, max_retry_s=0.5)
    with CameraReader(parse_source(ip_camera.url), params) as reader:
        assert _wait_for(reader, CameraState.STREAMING, 10)
        before = reader.status().frames
        ip_camera.cut.set()  # every connection is dropped, new ones are refused until cleared
        assert (
            _wait_for(reader, CameraState.DISCONNECTED, 10) or reader.status().state != CameraState.STREAMING
        )
        time.sleep(0.5)
        ip_camera.cut.clear()
        assert _wait_for(reader, CameraState.STREAMING, 15)
        time.sleep(0.3)
        status = reader.status()
    assert status.frames > before
    assert status.reconnects >= 1
    assert ip_camera.connections >= 2


def test_a_camera_that_cannot_be_opened_is_reported_disconnected_and_retried():
    params = ReaderParams(retry_s=0.1, max_retry_s=0.2, open_timeout_s=0.5)
    with CameraReader(parse_source("http://127.0.0.1:9/none.mjpg"), params) as reader:
        assert _wait_for(reader, CameraState.DISCONNECTED, 10)
        time.sleep(1.0)
        status = reader.status()
        assert reader.latest() is None
    assert status.reconnects >= 2 and "cannot open" in status.message
