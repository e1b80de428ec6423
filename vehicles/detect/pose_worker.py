"""MediaPipe pose landmarks as a child process: run by the pose environment's Python, not skyring's.

MediaPipe 0.10.21 is the last release whose wheel carries its pose models, and it needs numpy < 2 and
protobuf < 5, so it cannot share skyring's environment: `make pose-env` builds `.venv-pose` for it, and
vehicles/detect/pose.py starts this file there and talks to it over stdin/stdout. This file imports nothing
from skyring.

Two modes per request:
- "roi": MediaPipe's full pose landmark model (pose_landmark_full.tflite, from the mediapipe wheel) run
  directly on the given square crop by the LiteRT interpreter: the crop is the region of interest, as
  MediaPipe's own tracking feeds it. No person detector is involved, so a person seen from behind (no face)
  is found too. Input 256 x 256 RGB in [0, 1]; output 39 landmarks of (x, y, z, visibility logit, presence
  logit) in crop pixels, the first 33 the body's, and a pose-presence score.
- "full": MediaPipe's pose solution (its face-anchored person detector, then the same landmark model) on a
  whole image, for a large person that no box was found for; with the person's segmentation mask, from
  which skyring reads the crown (vehicles/detect/pose.py).

Protocol (binary, little-endian), one request at a time:
  request:  u32 header length, header JSON {"w": int, "h": int, "mode": "roi"|"full"}, then w * h * 3 bytes
            of RGB pixels ("roi" needs w = h = 256)
  reply:    u32 length, JSON {"landmarks": [[x_px, y_px, visibility] * 33] or null, "presence": float,
            "ms": float} (or {"error": text}); in "full" mode with a person, the JSON also holds
            "mask": [h, w] and h * w bytes follow it: the person's segmentation, probability x 255
At start the worker replies once with {"ready": true, "mediapipe": version}. A header with "w": 0 ends it.
"""

import json
import math
import os
import struct
import sys
import time

ROI_PX = 256


def _send(out, obj: dict, tail: bytes = b"") -> None:
    data = json.dumps(obj).encode()
    out.write(struct.pack("<I", len(data)) + data + tail)
    out.flush()


def _read_exact(inp, n: int) -> bytes:
    chunks = []
    while n > 0:
        chunk = inp.read(n)
        if not chunk:
            raise EOFError
        chunks.append(chunk)
        n -= len(chunk)
    return b"".join(chunks)


def _sigmoid(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-max(min(x, 60.0), -60.0)))


class RoiLandmarks:
    """MediaPipe's pose landmark model on a 256 x 256 crop, through LiteRT."""

    def __init__(self, model_path: str) -> None:
        from ai_edge_litert.interpreter import Interpreter  # pyright: ignore[reportMissingImports]

        self._it = Interpreter(model_path=model_path, num_threads=1)
        self._it.allocate_tensors()
        self._input = self._it.get_input_details()[0]["index"]
        outs = {tuple(d["shape"]): d["index"] for d in self._it.get_output_details()}
        self._marks = outs[(1, 195)]
        self._flag = outs[(1, 1)]

    def __call__(self, image):
        import numpy as np

        self._it.set_tensor(self._input, (image.astype(np.float32) / 255.0)[None])
        self._it.invoke()
        raw = self._it.get_tensor(self._marks).reshape(39, 5)[:33]
        presence = float(self._it.get_tensor(self._flag).ravel()[0])
        marks = [[float(x), float(y), _sigmoid(float(v))] for x, y, _, v, _ in raw]
        return marks, presence


def main() -> int:
    import mediapipe as mp  # pyright: ignore[reportMissingImports]
    import numpy as np

    inp, out = sys.stdin.buffer, sys.stdout.buffer
    model = os.path.join(
        os.path.dirname(str(mp.__file__)), "modules", "pose_landmark", "pose_landmark_full.tflite"
    )
    roi = RoiLandmarks(model)
    full = mp.solutions.pose.Pose(
        static_image_mode=True, model_complexity=1, enable_segmentation=True, min_detection_confidence=0.3
    )
    _send(out, {"ready": True, "mediapipe": mp.__version__})
    while True:
        try:
            (n,) = struct.unpack("<I", _read_exact(inp, 4))
            header = json.loads(_read_exact(inp, n))
            w, h, mode = int(header["w"]), int(header["h"]), str(header.get("mode", "roi"))
            if w == 0:
                return 0
            image = np.frombuffer(_read_exact(inp, w * h * 3), dtype=np.uint8).reshape(h, w, 3)
        except EOFError:
            return 0
        t0 = time.perf_counter()
        reply: dict[str, object] = {}
        tail = b""
        if mode == "roi":
            if w != ROI_PX or h != ROI_PX:
                _send(out, {"error": f"roi mode needs a {ROI_PX} x {ROI_PX} crop, got {w} x {h}"})
                continue
            marks, presence = roi(image)
        else:
            result = full.process(image)
            if result.pose_landmarks is None:
                marks, presence = None, 0.0
            else:
                marks = [[lm.x * w, lm.y * h, lm.visibility] for lm in result.pose_landmarks.landmark]
                presence = 1.0
                mask = np.clip(np.asarray(result.segmentation_mask) * 255.0 + 0.5, 0, 255).astype(np.uint8)
                reply["mask"], tail = list(mask.shape), mask.tobytes()
        reply.update(landmarks=marks, presence=presence, ms=(time.perf_counter() - t0) * 1e3)
        _send(out, reply, tail)


if __name__ == "__main__":
    sys.exit(main())
