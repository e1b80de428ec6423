"""The `skyring detect` loop: newest camera frame -> detection pipeline -> CameraDetection for the agent,
with a camera report (state, counts, frame rate, thumbnail) about once a second.

The loop takes the newest frame whenever it is free, so a slow detector lowers the detection rate, never
the freshness of what it detects. A failure inside one frame (the pose worker died, a back-end raised) is
counted and reported and the loop goes on with the next frame; a camera that stalls or disconnects is
reported while the reader reconnects. The agent runs in its own process and never waits for any of this.
"""

from __future__ import annotations

import base64
import json
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Protocol

import numpy as np

from vehicles.detect.camera_source import CameraReader, CameraState, CameraStatus
from vehicles.detect.overlay import draw_overlay, thumbnail_jpeg
from vehicles.detect.pipeline import DetectionPipeline
from vehicles.detect.pixels import CameraDetection
from vehicles.detect.preview import MjpegServer, PreviewWriter


@dataclass(frozen=True, eq=False)
class CameraReport:
    """How vehicle_id's camera and detector are doing at stamp_s: camera status, fps (frames processed
    per second over the last report period), detections sent so far, detector errors so far, backend name,
    thumbnail_jpeg (the newest overlaid frame, small; None when none yet)."""

    vehicle_id: int
    stamp_s: float
    camera: CameraStatus
    fps: float
    detections: int
    detector_errors: int
    backend: str
    message: str = ""
    thumbnail_jpeg: bytes | None = None


class DetectionSink(Protocol):
    """Where detections and reports go (Zenoh to the agent, a JSON Lines file, a test's list)."""

    def detection(self, det: CameraDetection) -> None: ...

    def report(self, rep: CameraReport) -> None: ...

    def close(self) -> None: ...


def detection_json(det: CameraDetection) -> dict:
    p = det.person
    return {
        "type": "detection",
        "vehicle_id": det.vehicle_id,
        "stamp_s": det.stamp_s,
        "frame_seq": det.frame_seq,
        "image_size_px": list(det.image_size_px),
        "head_px": p.head_px.tolist(),
        "feet_px": p.feet_px.tolist(),
        "head_conf": p.head_conf,
        "feet_conf": p.feet_conf,
        "box_px": p.box_px.tolist(),
        "score": p.score,
        "method": p.method,
    }


def report_json(rep: CameraReport) -> dict:
    c = rep.camera
    return {
        "type": "report",
        "vehicle_id": rep.vehicle_id,
        "stamp_s": rep.stamp_s,
        "camera_state": str(c.state),
        "frames": c.frames,
        "corrupt": c.corrupt,
        "reconnects": c.reconnects,
        "stalls": c.stalls,
        "frame_age_s": c.frame_age_s if math.isfinite(c.frame_age_s) else None,
        "size_px": list(c.size_px),
        "camera_message": c.message,
        "fps": rep.fps if math.isfinite(rep.fps) else None,
        "detections": rep.detections,
        "detector_errors": rep.detector_errors,
        "backend": rep.backend,
        "message": rep.message,
        "thumbnail_jpeg_b64": None
        if rep.thumbnail_jpeg is None
        else base64.b64encode(rep.thumbnail_jpeg).decode(),
    }


class JsonlSink:
    """Detections and reports as JSON Lines (one object per line, flushed at once) in a file or stdout."""

    def __init__(self, stream: IO[str], *, owns: bool = False) -> None:
        self._stream = stream
        self._owns = owns
        self._lock = threading.Lock()

    @classmethod
    def to_path(cls, path: str | Path) -> JsonlSink:
        return cls(open(path, "a", encoding="utf-8"), owns=True)  # noqa: SIM115 - closed by close()

    def _write(self, obj: dict) -> None:
        with self._lock:
            self._stream.write(json.dumps(obj) + "\n")
            self._stream.flush()

    def detection(self, det: CameraDetection) -> None:
        self._write(detection_json(det))

    def report(self, rep: CameraReport) -> None:
        self._write(report_json(rep))

    def close(self) -> None:
        if self._owns:
            self._stream.close()


@dataclass
class RunnerParams:
    """report_period_s: camera reports (and thumbnails) this often; max_fps: frames processed per second
    at most (0: as fast as the detector goes); wait_s: how long the loop waits for a frame before it checks
    on the camera again."""

    report_period_s: float = 1.0
    max_fps: float = 0.0
    wait_s: float = 0.25


@dataclass
class RunSummary:
    """What one run did: frames processed, detections sent, searches, detector errors, the processing
    times (s) of every frame, and how the camera ended."""

    frames: int = 0
    detections: int = 0
    detector_errors: int = 0
    searches: int = 0
    frame_times_s: list[float] = field(default_factory=list)
    camera: CameraStatus | None = None


class DetectorRunner:
    """One camera, one pipeline, any number of sinks and previews."""

    def __init__(
        self,
        *,
        vehicle_id: int,
        reader: CameraReader,
        pipeline: DetectionPipeline,
        sinks: Sequence[DetectionSink] = (),
        preview: PreviewWriter | None = None,
        mjpeg: MjpegServer | None = None,
        params: RunnerParams | None = None,
        clock: Callable[[], float] = time.time,
        log: Callable[[str], None] = lambda _msg: None,
    ) -> None:
        self.vehicle_id = int(vehicle_id)
        self._reader = reader
        self._pipeline = pipeline
        self._sinks = tuple(sinks)
        self._preview = preview
        self._mjpeg = mjpeg
        self._p = params or RunnerParams()
        self._clock = clock
        self._log = log
        self._stop = threading.Event()
        self._done: deque[float] = deque()  # clock() of frames processed in the last report period
        self._thumb: bytes | None = None
        self._last_message = ""

    def stop(self) -> None:
        self._stop.set()

    def run(self, *, max_frames: int | None = None, duration_s: float | None = None) -> RunSummary:
        """Process frames until stopped, the file ends, max_frames were processed or duration_s passed."""
        summary = RunSummary()
        last_seq = -1
        started = self._clock()
        last_report = -math.inf
        last_frame_t = -math.inf
        while not self._stop.is_set():
            now = self._clock()
            if duration_s is not None and now - started >= duration_s:
                break
            if max_frames is not None and summary.frames >= max_frames:
                break
            if now - last_report >= self._p.report_period_s:
                self._report(summary)
                last_report = now
            if self._p.max_fps > 0 and now - last_frame_t < 1.0 / self._p.max_fps:
                self._stop.wait(1.0 / self._p.max_fps - (now - last_frame_t))
                continue
            frame = self._reader.wait(last_seq, self._p.wait_s)
            if frame is None:
                if self._reader.status().state in (CameraState.ENDED, CameraState.STOPPED):
                    break
                continue
            last_seq = frame.seq
            last_frame_t = self._clock()
            self._process(frame.image, frame.stamp_s, frame.seq, summary, want_image=now - last_report >= 0.5)
        summary.camera = self._reader.status()
        self._report(summary)
        summary.searches = self._pipeline.searches
        return summary

    def _process(
        self, image: np.ndarray, stamp_s: float, seq: int, summary: RunSummary, *, want_image: bool
    ) -> None:
        t0 = time.perf_counter()
        result = None
        try:
            result = self._pipeline.process(image, stamp_s)
        except Exception as exc:  # one bad frame (a dead pose worker, a back-end bug) must not stop the loop
            summary.detector_errors += 1
            self._last_message = f"detector error: {type(exc).__name__}: {exc}"
            self._log(self._last_message)
        summary.frame_times_s.append(time.perf_counter() - t0)
        summary.frames += 1
        self._done.append(self._clock())
        person = result.person if result is not None else None
        if person is not None:
            det = CameraDetection(
                vehicle_id=self.vehicle_id,
                stamp_s=stamp_s,
                frame_seq=seq,
                image_size_px=(int(image.shape[1]), int(image.shape[0])),
                person=person,
            )
            summary.detections += 1
            for sink in self._sinks:
                sink.detection(det)
        if self._preview is not None or self._mjpeg is not None or want_image or self._thumb is None:
            drawn = draw_overlay(
                image,
                person=person,
                others=result.everyone if result is not None else (),
                status=self._reader.status(),
                fps=self._fps(),
                label=f"MAV {self.vehicle_id}",
            )
            if self._preview is not None:
                self._preview.write(drawn)
            if self._mjpeg is not None:
                self._mjpeg.publish(drawn)
            self._thumb = thumbnail_jpeg(drawn)

    def _fps(self) -> float:
        now = self._clock()
        while self._done and now - self._done[0] > max(self._p.report_period_s, 1.0):
            self._done.popleft()
        window = max(self._p.report_period_s, 1.0)
        return len(self._done) / window if self._done else 0.0

    def _report(self, summary: RunSummary) -> None:
        status = self._reader.status()
        rep = CameraReport(
            vehicle_id=self.vehicle_id,
            stamp_s=self._clock(),
            camera=status,
            fps=self._fps(),
            detections=summary.detections,
            detector_errors=summary.detector_errors,
            backend=getattr(self._pipeline.backend, "name", "?"),
            message=self._last_message,
            thumbnail_jpeg=self._thumb,
        )
        for sink in self._sinks:
            sink.report(rep)
