"""MediaPipe pose landmarks as a child process: run by the pose environment's Python, not skyring's.

MediaPipe 0.10.21 is the last release whose wheel carries its pose models, and it needs numpy < 2 and
protobuf < 5, so it cannot share skyring's environment: `make pose-env` builds `.venv-pose` for it, and
vehicles/detect/pose.py starts this file there and talks to it over stdin/stdout. This file imports nothing
from skyring.

Protocol (binary, little-endian), one request at a time:
  request:  u32 header length, header JSON {"w": int, "h": int}, then w * h * 3 bytes of RGB pixels
  reply:    u32 length, JSON {"landmarks": [[x_px, y_px, visibility] * 33] or null, "ms": float}
At start the worker replies once with {"ready": true, "mediapipe": version}. A header with "w": 0 ends it.
"""

import json
import struct
import sys
import time


def _send(out, obj: dict) -> None:
    data = json.dumps(obj).encode()
    out.write(struct.pack("<I", len(data)) + data)
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


def main() -> int:
    import mediapipe as mp
    import numpy as np

    inp, out = sys.stdin.buffer, sys.stdout.buffer
    pose = mp.solutions.pose.Pose(
        static_image_mode=True, model_complexity=1, enable_segmentation=False, min_detection_confidence=0.3
    )
    _send(out, {"ready": True, "mediapipe": mp.__version__})
    while True:
        try:
            (n,) = struct.unpack("<I", _read_exact(inp, 4))
            header = json.loads(_read_exact(inp, n))
            w, h = int(header["w"]), int(header["h"])
            if w == 0:
                return 0
            image = np.frombuffer(_read_exact(inp, w * h * 3), dtype=np.uint8).reshape(h, w, 3)
        except EOFError:
            return 0
        t0 = time.perf_counter()
        result = pose.process(image)
        ms = (time.perf_counter() - t0) * 1e3
        if result.pose_landmarks is None:
            _send(out, {"landmarks": None, "ms": ms})
        else:
            marks = [[lm.x * w, lm.y * h, lm.visibility] for lm in result.pose_landmarks.landmark]
            _send(out, {"landmarks": marks, "ms": ms})


if __name__ == "__main__":
    sys.exit(main())
