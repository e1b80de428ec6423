"""`skyring bench detect`: the default detector's speed on 2040 x 1086 frames (the paper's camera size).

Frames: 120 consecutive frames of vtest.avi (Debian's opencv-doc), scaled by 1.885 to the frame's height and
centred on a 2040 x 1086 grey canvas, so the people are 120-250 px tall, as the camera model predicts for
a 1.75 m person at 8-15 m. Measured, each on one core: HOG's full-frame search alone, a full acquisition
(HOG + the pose model on every candidate), one tracking step (the pose model on a crop round the tracked
person), and the acquire-then-track pipeline over the sequence: its frames per second is what `skyring
detect` sustains when the processor is free for it.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

VIDEO = Path("/usr/share/doc/opencv-doc/examples/data/vtest.avi")
SIZE = (2040, 1086)


def _frames(n: int) -> list[np.ndarray]:
    import cv2

    if not VIDEO.is_file():
        raise SystemExit(f"{VIDEO} is missing: `make footage` installs Debian's opencv-doc")
    cap = cv2.VideoCapture(str(VIDEO))
    out = []
    while len(out) < n:
        ok, img = cap.read()
        if not ok:
            break
        k = SIZE[1] / img.shape[0]
        scaled = cv2.resize(img, (round(img.shape[1] * k), SIZE[1]), interpolation=cv2.INTER_LINEAR)
        canvas = np.full((SIZE[1], SIZE[0], 3), 128, np.uint8)
        x0 = (SIZE[0] - scaled.shape[1]) // 2
        canvas[:, x0 : x0 + scaled.shape[1]] = scaled
        out.append(canvas)
    cap.release()
    return out


def _ms(samples: list[float]) -> str:
    s = sorted(samples)
    p90 = s[min(len(s) - 1, int(0.9 * len(s)))]
    return f"median {statistics.median(s) * 1e3:7.1f} ms   p90 {p90 * 1e3:7.1f} ms   (n={len(s)})"


def run(repeats: int = 200) -> None:
    """Print the timings; `repeats` caps the frames used (at least 20)."""
    from vehicles.detect.backends import HogPoseDetector
    from vehicles.detect.hog import HogPeople
    from vehicles.detect.pipeline import DetectionPipeline

    n = max(20, min(repeats, 120))
    frames = _frames(n)
    detector = HogPoseDetector()
    detector.pose.start()
    try:
        hog = HogPeople()
        hog_t = []
        for f in frames[:10]:
            t0 = time.perf_counter()
            hog.find(f)
            hog_t.append(time.perf_counter() - t0)
        find_t = []
        for f in frames[:10]:
            t0 = time.perf_counter()
            detector.find(f)
            find_t.append(time.perf_counter() - t0)
        people = detector.find(frames[0])
        refine_t = []
        if people:
            box = people[0].box_px
            for f in frames[:30]:
                t0 = time.perf_counter()
                p = detector.refine(f, box)
                refine_t.append(time.perf_counter() - t0)
                if p is not None:
                    box = p.box_px
        pipe = DetectionPipeline(detector)
        pipe_t = []
        seen = 0
        for i, f in enumerate(frames):
            t0 = time.perf_counter()
            if pipe.process(f, i * 0.1).person is not None:
                seen += 1
            pipe_t.append(time.perf_counter() - t0)
    finally:
        detector.close()
    total = sum(pipe_t)
    print(f"detect: default back-end (HOG + MediaPipe pose), {SIZE[0]} x {SIZE[1]} frames, one core each")
    print(f"  HOG full-frame search        {_ms(hog_t)}")
    print(f"  acquisition (HOG + pose)     {_ms(find_t)}")
    if refine_t:
        print(f"  tracking step (pose on crop) {_ms(refine_t)}")
    print(f"  pipeline over {len(frames)} frames      {_ms(pipe_t)}")
    print(
        f"  pipeline: {len(frames) / total:.1f} frames/s, person in {seen}/{len(frames)} frames, "
        f"{pipe.searches} full searches"
    )
