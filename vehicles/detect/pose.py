"""The pose model: MediaPipe's pose landmarks, computed in the pose environment's process (pose_worker.py).

`MediaPipePose` starts `pose_worker.py` under the pose environment's Python (`.venv-pose`, built by `make
pose-env`; or the interpreter named by SKYRING_POSE_PYTHON) and sends it RGB crops. A worker that dies or
does not answer within `timeout_s` is killed and restarted on the next call (counted in `restarts`); the call
that met it raises PoseWorkerError, so one bad crop costs one frame, never the process.

`head_and_feet` turns MediaPipe's 33 landmarks into the two points skyring measures: the feet point is the
midpoint of the two feet's soles (heels and toe tips), the head point the crown, which no landmark marks.
With the person's segmentation mask (the whole-image mode has one) the crown is read from it: the mask's
upper edge straight above the midpoint of the ears. Without one it lies CROWN_ABOVE_EARS times the
ears-to-feet distance above the midpoint of the ears (the skull's centre seen from any side, where the eyes
are off-centre in a side view), along the body's axis (hips to ears); that proportion fails for a crouching
or bent-over person and for a full head of hair, which the mask sees.
Confidences are the landmarks' visibilities: the feet's mean, and for the head the mean of its three most
visible face landmarks (a head seen from behind shows no face, yet the model places it well).
"""

from __future__ import annotations

import json
import os
import select
import struct
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np

WORKER = Path(__file__).with_name("pose_worker.py")
REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_POSE_PYTHON = REPO_ROOT / ".venv-pose" / "bin" / "python"

# MediaPipe pose landmark indices.
LEFT_EAR, RIGHT_EAR, MOUTH_RIGHT = 7, 8, 10
LEFT_HIP, RIGHT_HIP = 23, 24
LEFT_HEEL, RIGHT_HEEL, LEFT_TOE, RIGHT_TOE = 29, 30, 31, 32

ROI_PX = 256
"""Side of the square crop the landmark model takes in "roi" mode."""

MAX_MASK_PIXELS = 4096 * 4096
"""The largest segmentation mask a reply may announce (the whole-image pass sends one of its shrunk image)."""

CROWN_ABOVE_EARS = 0.090
"""Crown above the ears' midpoint, in ears-to-feet distances. Anthropometry gives about 0.08 for a level
view (13 cm over 1.62 m). Fitted (minimum median error) on the 26 people of frames 80-320 of the labelled
vtest.avi frames (tests/vehicles/detect/data/labels.json); on the other 18 the median head error is then
1.4 px and the 90th percentile 4.6 px, against 3.3 and 7.4 px from the eyes."""

MASK_LEVEL = 0.5
"""A pixel belongs to the person where the segmentation mask's probability is at least this."""

MASK_SEARCH = 0.35
"""How far above the ears the mask's edge is looked for, in ears-to-feet distances (about three head
heights); a mask that runs on further has no edge there (hair against a like-coloured background)."""


@dataclass(frozen=True, eq=False)
class PoseEstimate:
    """What the pose model found in one image.

    landmarks: (33, 3) x_px, y_px, visibility in [0, 1], or None when it found nobody; presence in [0, 1]:
    the model's own score that the image holds a person; mask: (H, W) float32 person probability per pixel
    of the image, or None (only the whole-image mode returns one).
    """

    landmarks: np.ndarray | None
    presence: float
    mask: np.ndarray | None = None


class PoseWorkerError(RuntimeError):
    """The pose worker could not be started, died, or did not answer in time."""


def pose_python() -> Path:
    """The pose environment's interpreter: SKYRING_POSE_PYTHON, else the repository's .venv-pose."""
    env = os.environ.get("SKYRING_POSE_PYTHON")
    return Path(env) if env else DEFAULT_POSE_PYTHON


def crown_from_mask(ears_px: np.ndarray, mask: np.ndarray, search_px: float) -> np.ndarray | None:
    """(2,) the mask's upper edge straight above ears_px (2,), to half a pixel; None when the ears are not on
    the mask (H, W), or no edge lies within search_px above them inside the image."""
    x = float(ears_px[0])
    ys = float(ears_px[1]) - np.arange(0.0, max(search_px, 0.0), 0.5)
    h, w = mask.shape
    ys = ys[ys >= 0.0]
    if not (0.0 <= x <= w - 1 and ys.size and ys[0] <= h - 1):
        return None
    x0, y0 = min(int(x), w - 2), np.minimum(ys.astype(int), h - 2)
    fx, fy = x - x0, ys - y0
    top = mask[y0, x0] * (1 - fx) + mask[y0, x0 + 1] * fx
    bottom = mask[y0 + 1, x0] * (1 - fx) + mask[y0 + 1, x0 + 1] * fx
    values = top * (1 - fy) + bottom * fy
    outside = np.flatnonzero(values < MASK_LEVEL)
    if values[0] < MASK_LEVEL or outside.size == 0:
        return None
    return np.array([x, ys[outside[0] - 1]])


def head_and_feet(
    landmarks: np.ndarray, mask: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """(head_px (2,), feet_px (2,), head_conf, feet_conf) from MediaPipe landmarks (33, 3) of x_px, y_px,
    visibility, and the person's segmentation mask (H, W) in the same pixels when there is one."""
    xy, vis = landmarks[:, :2], landmarks[:, 2]
    ears = 0.5 * (xy[LEFT_EAR] + xy[RIGHT_EAR])
    hips = 0.5 * (xy[LEFT_HIP] + xy[RIGHT_HIP])
    up = ears - hips
    norm = float(np.hypot(*up))
    up = up / norm if norm > 1e-6 else np.array([0.0, -1.0])
    feet = xy[[LEFT_HEEL, RIGHT_HEEL, LEFT_TOE, RIGHT_TOE]].mean(axis=0)
    ears_to_feet = float(np.hypot(*(feet - ears)))
    head = None if mask is None else crown_from_mask(ears, mask, MASK_SEARCH * ears_to_feet)
    if head is None:
        head = ears + CROWN_ABOVE_EARS * ears_to_feet * up
    head_conf = float(np.mean(np.sort(vis[: MOUTH_RIGHT + 1])[-3:]))
    feet_conf = float(np.mean(vis[[LEFT_HEEL, RIGHT_HEEL, LEFT_TOE, RIGHT_TOE]]))
    return head, feet, min(max(head_conf, 0.0), 1.0), min(max(feet_conf, 0.0), 1.0)


class MediaPipePose:
    """A pose-landmark estimator in a child process: `estimate(image)` -> PoseEstimate."""

    def __init__(
        self, *, python: Path | None = None, timeout_s: float = 5.0, start_timeout_s: float = 60.0
    ) -> None:
        self._python = Path(python) if python is not None else pose_python()
        self._timeout_s = float(timeout_s)
        self._start_timeout_s = float(start_timeout_s)
        self._proc: subprocess.Popen[bytes] | None = None
        self._log: IO[bytes] | None = None
        self.restarts = 0
        self.version = ""
        self.last_ms = float("nan")

    def start(self) -> None:
        """Start the worker (done by the first estimate otherwise); PoseWorkerError when it cannot."""
        if self._proc is not None:
            return
        if not self._python.exists():
            raise PoseWorkerError(
                f"the pose environment's python {self._python} does not exist: run `make pose-env` in the "
                "skyring checkout, or set SKYRING_POSE_PYTHON to a Python with mediapipe==0.10.21"
            )
        self._log = tempfile.TemporaryFile()
        env = dict(os.environ, GLOG_minloglevel="2", TF_CPP_MIN_LOG_LEVEL="2", PYTHONNOUSERSITE="1")
        env.pop("PYTHONPATH", None)
        self._proc = subprocess.Popen(
            [str(self._python), "-u", str(WORKER)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self._log,
            env=env,
            cwd=str(WORKER.parent),
        )
        hello, _ = self._reply(self._start_timeout_s)
        if not hello.get("ready"):
            self._fail("the pose worker did not report ready")
        self.version = str(hello.get("mediapipe", ""))

    def estimate(self, crop_rgb: np.ndarray, *, mode: str = "roi") -> PoseEstimate:
        """The person in crop_rgb, (H, W, 3) uint8 RGB, landmarks in its pixels.

        mode "roi": the landmark model on this crop as its region of interest (it must be ROI_PX square; the
        person centred, about 3/4 of its height); "full": MediaPipe's person detector first, on any image
        (presence is then 1 or 0), with the person's segmentation mask.
        """
        image = np.ascontiguousarray(crop_rgb, dtype=np.uint8)
        if image.ndim != 3 or image.shape[2] != 3:
            raise ValueError(f"crop must be (H, W, 3) uint8, got {image.shape}")
        if mode == "roi" and image.shape[:2] != (ROI_PX, ROI_PX):
            raise ValueError(f"a roi crop must be {ROI_PX} x {ROI_PX}, got {image.shape[:2]}")
        if mode not in ("roi", "full"):
            raise ValueError(f"mode must be 'roi' or 'full', got {mode!r}")
        if self._proc is None:
            self.start()
        proc = self._proc
        assert proc is not None and proc.stdin is not None
        header = json.dumps({"w": image.shape[1], "h": image.shape[0], "mode": mode}).encode()
        try:
            proc.stdin.write(struct.pack("<I", len(header)) + header + image.tobytes())
            proc.stdin.flush()
        except (BrokenPipeError, OSError):
            self._fail("the pose worker's input closed")
        reply, mask = self._reply(self._timeout_s)
        if "error" in reply:
            raise ValueError(f"the pose worker refused the request: {reply['error']}")
        self.last_ms = float(reply.get("ms", float("nan")))
        marks = reply.get("landmarks")
        return PoseEstimate(
            landmarks=None if marks is None else np.asarray(marks, dtype=float).reshape(33, 3),
            presence=float(reply.get("presence", 0.0)),
            mask=mask,
        )

    def _reply(self, timeout_s: float) -> tuple[dict, np.ndarray | None]:
        """The worker's next reply, and the mask (H, W) in [0, 1] that follows when it says "mask": [H, W]."""
        (length,) = struct.unpack("<I", self._read(4, timeout_s))
        data = self._read(length, timeout_s)
        try:
            reply = json.loads(data)
            shape = tuple(int(n) for n in reply.get("mask", ()))
        except (json.JSONDecodeError, AttributeError, TypeError, ValueError):
            self._fail("the pose worker sent a malformed reply")
            raise  # unreachable: _fail raises
        if not shape:
            return reply, None
        if len(shape) != 2 or not 0 < shape[0] * shape[1] <= MAX_MASK_PIXELS or min(shape) <= 0:
            self._fail(f"the pose worker announced a mask of shape {shape}")
        raw = self._read(shape[0] * shape[1], timeout_s)
        return reply, np.frombuffer(raw, dtype=np.uint8).reshape(shape).astype(np.float32) / 255.0

    def _read(self, n: int, timeout_s: float) -> bytes:
        proc = self._proc
        assert proc is not None and proc.stdout is not None
        fd = proc.stdout.fileno()
        chunks: list[bytes] = []
        missing = n
        while missing > 0:
            ready, _, _ = select.select([fd], [], [], timeout_s)
            if not ready:
                self._fail(f"the pose worker did not answer within {timeout_s:.1f} s")
            chunk = os.read(fd, missing)
            if not chunk:
                self._fail("the pose worker exited")
            chunks.append(chunk)
            missing -= len(chunk)
        return b"".join(chunks)

    def _fail(self, why: str) -> None:
        tail = self._log_tail()
        self._kill()
        self.restarts += 1
        raise PoseWorkerError(why + (f"; its last words: {tail}" if tail else ""))

    def _log_tail(self) -> str:
        if self._log is None:
            return ""
        try:
            self._log.seek(0)
            lines = [ln for ln in self._log.read().decode(errors="replace").splitlines() if ln.strip()]
        except OSError:
            return ""
        return " | ".join(lines[-3:])[-400:]

    def _kill(self) -> None:
        proc, self._proc = self._proc, None
        if proc is not None:
            proc.kill()
            proc.wait(timeout=5)
            for stream in (proc.stdin, proc.stdout):
                if stream is not None:
                    stream.close()
        if self._log is not None:
            self._log.close()
            self._log = None

    def close(self) -> None:
        """Stop the worker politely (a zero-size request), then for good."""
        proc = self._proc
        if proc is not None and proc.stdin is not None and proc.poll() is None:
            try:
                header = json.dumps({"w": 0, "h": 0}).encode()
                proc.stdin.write(struct.pack("<I", len(header)) + header)
                proc.stdin.flush()
                proc.wait(timeout=2)
            except (OSError, subprocess.TimeoutExpired):
                pass
        self._kill()

    def __enter__(self) -> MediaPipePose:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
