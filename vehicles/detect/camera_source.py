"""Camera sources: a V4L2 device, a network stream (RTSP/HTTP/UDP), a GStreamer pipeline or a video file,
read by OpenCV in a thread of their own, stamped at capture, and watched for stalls, disconnects and
corrupt frames.

The reader thread grabs frames as fast as the camera gives them and keeps only the newest: the detector
takes the latest frame when it is ready for one (never a queue of stale frames), and nothing that reads a
frame ever blocks on the camera. Each frame is stamped with `clock()` (wall time, the clock the MAV's
telemetry uses on the same computer) right after `grab()` returns, minus `capture_latency_s` (what the
camera and its transport add before that; measure it for your camera, 0 by default).

Failures, all reported in `status()` and counted:
- STALLED: no frame for `stall_s` while streaming (a frozen stream; a read that blocks).
- DISCONNECTED: the source could not be opened or a read failed (unplugged, network gone, stream ended
  without being a file). The reader reopens it after `retry_s` (doubling up to `max_retry_s`). A read that
  hangs longer than `reopen_after_s` is abandoned (its thread is left to finish) and the source reopened.
- corrupt frames: empty, of the wrong type, or of another size than the stream's first frame (or the
  expected size) are dropped and counted; a stream whose frames are all corrupt for `reopen_after_s` is
  reopened.
- ENDED: a video file reached its end (with `loop`, it starts again instead).
Video files are played at their own frame rate (`realtime`, the default for `skyring detect`: a camera
stand-in) or as fast as they decode (`realtime=False`, for benchmarks).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import numpy as np

URL_SCHEMES = (
    "rtsp://",
    "rtsps://",
    "rtmp://",
    "http://",
    "https://",
    "udp://",
    "tcp://",
    "rtp://",
    "srt://",
)


class SourceKind(StrEnum):
    DEVICE = "device"
    URL = "url"
    GSTREAMER = "gstreamer"
    FILE = "file"


@dataclass(frozen=True)
class SourceSpec:
    """kind and target: a device index or path, a URL, a GStreamer pipeline or a file path."""

    kind: SourceKind
    target: str

    @property
    def label(self) -> str:
        return f"{self.kind} {self.target}"


def parse_source(text: str) -> SourceSpec:
    """A --camera argument as a source: "0" or "/dev/video0" (V4L2), "rtsp://..." and other URLs,
    "... ! appsink" (GStreamer), else a video file, which must exist. ValueError says what is wrong."""
    s = text.strip()
    if not s:
        raise ValueError("the camera source is empty")
    if s.isdigit() or s.startswith("/dev/video"):
        return SourceSpec(SourceKind.DEVICE, s)
    if s.lower().startswith(URL_SCHEMES):
        return SourceSpec(SourceKind.URL, s)
    if " ! " in s or s.endswith("appsink"):
        return SourceSpec(SourceKind.GSTREAMER, s)
    if not Path(s).is_file():
        raise ValueError(f"{s}: no such video file (nor a device, URL or GStreamer pipeline)")
    return SourceSpec(SourceKind.FILE, s)


class CameraState(StrEnum):
    CONNECTING = "connecting"
    STREAMING = "streaming"
    STALLED = "stalled"
    DISCONNECTED = "disconnected"
    ENDED = "ended"
    STOPPED = "stopped"


@dataclass(frozen=True, eq=False)
class Frame:
    """One captured frame: seq counts frames from 0 over the reader's life; stamp_s: capture time (clock()
    seconds); image: (H, W, 3) uint8 BGR (read-only)."""

    seq: int
    stamp_s: float
    image: np.ndarray


@dataclass(frozen=True)
class CameraStatus:
    """state; frames: good frames read; corrupt: frames dropped as corrupt; reconnects: reopenings;
    stalls: times the stream stalled; frame_age_s: since the newest good frame (inf before the first);
    size_px: (width, height) of the stream (0, 0 before the first frame); message: the last problem."""

    state: CameraState
    frames: int
    corrupt: int
    reconnects: int
    stalls: int
    frame_age_s: float
    size_px: tuple[int, int]
    message: str = ""

    @property
    def healthy(self) -> bool:
        return self.state == CameraState.STREAMING


@dataclass(frozen=True)
class ReaderParams:
    """stall_s: no frame for this long is a stall; reopen_after_s: a read hanging (or a run of corrupt
    frames) this long gets the source reopened; retry_s/max_retry_s: reopening back-off; open_timeout_s,
    read_timeout_s: OpenCV's FFmpeg time-outs for network sources; realtime: play files at their frame rate;
    loop: restart a file at its end; capture_latency_s: subtracted from every stamp; expected_size_px:
    (width, height) frames must have (None: the first frame's size)."""

    stall_s: float = 1.0
    reopen_after_s: float = 8.0
    retry_s: float = 0.5
    max_retry_s: float = 5.0
    open_timeout_s: float = 5.0
    read_timeout_s: float = 2.0
    realtime: bool = True
    loop: bool = False
    capture_latency_s: float = 0.0
    expected_size_px: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        for name in (
            "stall_s",
            "reopen_after_s",
            "retry_s",
            "max_retry_s",
            "open_timeout_s",
            "read_timeout_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number of seconds, got {value}")


def open_capture(spec: SourceSpec, params: ReaderParams):
    """An opened cv2.VideoCapture for spec, or raise OSError saying why not."""
    import cv2

    if (
        spec.kind == SourceKind.GSTREAMER
        and "GStreamer:                   YES" not in cv2.getBuildInformation()
    ):
        raise OSError(
            "this OpenCV was built without GStreamer (the PyPI wheels are): use an rtsp:// or http:// URL, "
            "or an OpenCV with GStreamer (Debian's python3-opencv)"
        )
    timeouts = [
        cv2.CAP_PROP_OPEN_TIMEOUT_MSEC,
        int(params.open_timeout_s * 1000),
        cv2.CAP_PROP_READ_TIMEOUT_MSEC,
        int(params.read_timeout_s * 1000),
    ]
    if spec.kind == SourceKind.DEVICE:
        target: int | str = int(spec.target) if spec.target.isdigit() else spec.target
        cap = cv2.VideoCapture(target, cv2.CAP_V4L2)
    elif spec.kind == SourceKind.GSTREAMER:
        cap = cv2.VideoCapture(spec.target, cv2.CAP_GSTREAMER)
    elif spec.kind == SourceKind.URL:
        cap = cv2.VideoCapture(spec.target, cv2.CAP_FFMPEG, timeouts)
    else:
        cap = cv2.VideoCapture(spec.target, cv2.CAP_FFMPEG)
    if not cap.isOpened():
        cap.release()
        raise OSError(f"cannot open {spec.label}")
    return cap


class CameraReader:
    """Reads spec in a daemon thread; `latest()` and `wait()` hand out the newest frame, `status()` says how
    the camera is doing. Start with `start()`, stop with `stop()` (or use it as a context manager)."""

    def __init__(
        self,
        spec: SourceSpec,
        params: ReaderParams | None = None,
        *,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.spec = spec
        self._p = params or ReaderParams()
        self._clock = clock
        self._cond = threading.Condition()
        self._frame: Frame | None = None
        self._seq = 0
        self._state = CameraState.CONNECTING
        self._message = ""
        self._counts = {"frames": 0, "corrupt": 0, "reconnects": 0, "stalls": 0}
        self._last_good = -math.inf  # clock() of the newest good frame
        self._last_attempt = -math.inf  # clock() when the current read started
        self._size: tuple[int, int] = (0, 0)
        self._generation = 0
        self._stalled = False
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._watchdog: threading.Thread | None = None

    # -- public -----------------------------------------------------------------------------------------
    def start(self) -> CameraReader:
        self._spawn()
        self._watchdog = threading.Thread(target=self._watch, name="camera-watchdog", daemon=True)
        self._watchdog.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        with self._cond:
            self._state = CameraState.STOPPED
            self._cond.notify_all()
        for t in self._threads:
            t.join(timeout=max(self._p.read_timeout_s, 1.0) + 1.0)

    def __enter__(self) -> CameraReader:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def latest(self, after_seq: int = -1) -> Frame | None:
        """The newest frame if it is newer than after_seq, else None. Never blocks on the camera."""
        with self._cond:
            f = self._frame
            return f if f is not None and f.seq > after_seq else None

    def wait(self, after_seq: int, timeout_s: float) -> Frame | None:
        """The newest frame newer than after_seq, waiting at most timeout_s for one."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while True:
                f = self._frame
                if f is not None and f.seq > after_seq:
                    return f
                left = deadline - time.monotonic()
                if left <= 0 or self._state in (CameraState.ENDED, CameraState.STOPPED):
                    return None
                self._cond.wait(left)

    def status(self) -> CameraStatus:
        now = self._clock()
        with self._cond:
            state = self._state
            age = now - self._last_good if math.isfinite(self._last_good) else math.inf
            if state == CameraState.STREAMING and age > self._p.stall_s:
                state = CameraState.STALLED
            return CameraStatus(
                state=state,
                frames=self._counts["frames"],
                corrupt=self._counts["corrupt"],
                reconnects=self._counts["reconnects"],
                stalls=self._counts["stalls"],
                frame_age_s=age,
                size_px=self._size,
                message=self._message,
            )

    # -- reader thread -----------------------------------------------------------------------------------
    def _spawn(self) -> None:
        with self._cond:
            self._generation += 1
            gen = self._generation
        t = threading.Thread(target=self._run, args=(gen,), name=f"camera-{gen}", daemon=True)
        self._threads = [x for x in self._threads if x.is_alive()] + [t]
        t.start()

    def _current(self, gen: int) -> bool:
        return gen == self._generation and not self._stop.is_set()

    def _set(self, gen: int, state: CameraState, message: str | None = None) -> None:
        with self._cond:
            if gen != self._generation or self._state == CameraState.STOPPED:
                return
            self._state = state
            if message is not None:
                self._message = message
            self._cond.notify_all()

    def _run(self, gen: int) -> None:
        backoff = self._p.retry_s
        first = True
        while self._current(gen):
            if not first:
                with self._cond:
                    self._counts["reconnects"] += 1
            first = False
            self._set(gen, CameraState.CONNECTING)
            self._last_attempt = self._clock()
            try:
                cap = open_capture(self.spec, self._p)
            except OSError as exc:
                self._set(gen, CameraState.DISCONNECTED, str(exc))
                if self._stop.wait(backoff):
                    return
                backoff = min(2 * backoff, self._p.max_retry_s)
                continue
            try:
                outcome = self._stream(gen, cap)
            finally:
                cap.release()
            if outcome == "ended":
                self._set(gen, CameraState.ENDED, f"{self.spec.target}: end of file")
                return
            if outcome == "stopped":
                return
            backoff = self._p.retry_s if outcome == "had_frames" else min(2 * backoff, self._p.max_retry_s)
            if self._stop.wait(backoff):
                return

    def _stream(self, gen: int, cap) -> str:
        """Read until the source fails: 'ended' (file end), 'stopped', 'had_frames' or 'failed'."""
        import cv2

        is_file = self.spec.kind == SourceKind.FILE
        fps = float(cap.get(cv2.CAP_PROP_FPS)) if is_file else 0.0
        period = 1.0 / fps if (self._p.realtime and is_file and 0 < fps < 1000) else 0.0
        count = float(cap.get(cv2.CAP_PROP_FRAME_COUNT)) if is_file else 0.0
        t_play = time.monotonic()
        index = 0
        got_any = False
        bad_since: float | None = None
        failed_reads = 0
        while self._current(gen):
            if period > 0:
                delay = t_play + index * period - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    return "stopped"
            self._last_attempt = self._clock()
            ok = cap.grab()
            stamp = self._clock() - self._p.capture_latency_s
            index += 1
            if not ok:
                if is_file and (count <= 0 or index >= count):
                    if self._p.loop and got_any:
                        cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
                        t_play, index = time.monotonic(), 0
                        continue
                    return "ended"
                failed_reads += 1
                if is_file and failed_reads < 25:  # a damaged packet inside a file: skip it
                    self._corrupt(gen, f"frame {index - 1} could not be read")
                    continue
                self._set(gen, CameraState.DISCONNECTED, f"{self.spec.label}: read failed")
                return "had_frames" if got_any else "failed"
            ok, image = cap.retrieve()
            problem = "could not be decoded" if not ok else self._problem(image)
            if problem is not None:
                self._corrupt(gen, f"frame {index - 1} {problem}")
                now = self._clock()
                bad_since = now if bad_since is None else bad_since
                if now - bad_since > self._p.reopen_after_s:
                    self._set(gen, CameraState.DISCONNECTED, f"{self.spec.label}: only corrupt frames")
                    return "had_frames"
                continue
            bad_since = None
            failed_reads = 0
            got_any = True
            self._publish(gen, stamp, image)
        return "stopped"

    def _problem(self, image: np.ndarray | None) -> str | None:
        """Why a decoded frame cannot be used, or None."""
        if image is None or not isinstance(image, np.ndarray) or image.dtype != np.uint8:
            return "is empty or not 8-bit"
        if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] < 8 or image.shape[1] < 8:
            return f"has shape {image.shape}, not (H, W, 3)"
        size = (int(image.shape[1]), int(image.shape[0]))
        expected = self._p.expected_size_px or (self._size if self._size != (0, 0) else None)
        if expected is not None and size != tuple(expected):
            return f"is {size[0]} x {size[1]} px, expected {expected[0]} x {expected[1]} (the calibration's)"
        return None

    def _corrupt(self, gen: int, message: str) -> None:
        with self._cond:
            if gen == self._generation:
                self._counts["corrupt"] += 1
                self._message = message

    def _publish(self, gen: int, stamp: float, image: np.ndarray) -> None:
        image.setflags(write=False)
        with self._cond:
            if gen != self._generation:
                return
            self._frame = Frame(seq=self._seq, stamp_s=stamp, image=image)
            self._seq += 1
            self._counts["frames"] += 1
            self._last_good = self._clock()
            self._size = (int(image.shape[1]), int(image.shape[0]))
            self._state = CameraState.STREAMING
            self._stalled = False
            self._cond.notify_all()

    # -- watchdog ----------------------------------------------------------------------------------------
    def _watch(self) -> None:
        """Counts stalls, and abandons a read that hangs longer than reopen_after_s for a fresh reader."""
        while not self._stop.wait(0.1):
            now = self._clock()
            with self._cond:
                streaming = self._state == CameraState.STREAMING
                age = now - self._last_good if math.isfinite(self._last_good) else math.inf
                if streaming and age > self._p.stall_s and not self._stalled:
                    self._stalled = True
                    self._counts["stalls"] += 1
                    self._message = f"no frame for {age:.1f} s"
                hung = now - self._last_attempt > self._p.reopen_after_s and self._state in (
                    CameraState.STREAMING,
                    CameraState.CONNECTING,
                )
            if hung and age > self._p.reopen_after_s:
                with self._cond:
                    self._counts["reconnects"] += 1
                    self._message = f"read hung for {now - self._last_attempt:.1f} s: reopening"
                self._last_attempt = now
                self._spawn()
