"""OpenCV's HOG people detector (Dalal and Triggs' linear SVM, shipped inside OpenCV): candidate boxes.

It runs offline with nothing to download, but gives boxes only, so the default back-end uses it to find
candidates and the pose model to place head and feet (vehicles/detect/backends.py). OpenCV 5 dropped
HOGDescriptor, hence the `< 5` pin. The default detector's 64 x 128 window sees a person about 96 px tall,
so the image is resized by 96 / min_person_px first, within a pixel budget that bounds the time (0.1-0.15 s
for about 1 megapixel on this kind of machine; `skyring bench detect` measures it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

WINDOW_PERSON_PX = 96.0
"""Height of a person inside the default detector's 128 px window."""


@dataclass(frozen=True)
class HogParams:
    """min_person_px: the smallest person (pixels, head to feet) to find; max_work_pixels: the resized
    image's pixel budget (a large frame finds only larger persons rather than taking longer); hit_threshold:
    SVM margin (below 0 gives more candidates for the pose model to check); win_stride_px, scale_step: the
    scan's spatial and scale steps; nms_iou: boxes overlapping more than this are merged."""

    min_person_px: float = 64.0
    max_work_pixels: int = 1_100_000
    hit_threshold: float = -0.3
    win_stride_px: int = 8
    scale_step: float = 1.05
    nms_iou: float = 0.45

    def __post_init__(self) -> None:
        if not (self.min_person_px > 0 and self.max_work_pixels > 0 and self.scale_step > 1.0):
            raise ValueError("min_person_px, max_work_pixels must be positive and scale_step above 1")


@dataclass(frozen=True, eq=False)
class Candidate:
    """A person candidate: box_px (4,) x0, y0, x1, y1 in the input image; score: the SVM margin."""

    box_px: np.ndarray
    score: float


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two x0, y0, x1, y1 boxes."""
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    if w <= 0 or h <= 0:
        return 0.0
    inter = w * h
    return float(inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter))


def non_max_suppression(candidates: list[Candidate], iou_limit: float) -> list[Candidate]:
    """Keep the best-scoring candidates, dropping any that overlaps a kept one by more than iou_limit."""
    kept: list[Candidate] = []
    for c in sorted(candidates, key=lambda c: -c.score):
        if all(iou(c.box_px, k.box_px) <= iou_limit for k in kept):
            kept.append(c)
    return kept


class HogPeople:
    """HOG + linear SVM people detector; `find(image_bgr)` -> candidates, best first."""

    def __init__(self, params: HogParams | None = None) -> None:
        import cv2

        if not hasattr(cv2, "HOGDescriptor"):
            raise RuntimeError(
                f"OpenCV {cv2.__version__} has no HOGDescriptor (removed in OpenCV 5): install "
                "opencv-python-headless < 5"
            )
        self._cv2 = cv2
        self._p = params or HogParams()
        self._hog = cv2.HOGDescriptor()
        self._hog.setSVMDetector(np.asarray(cv2.HOGDescriptor.getDefaultPeopleDetector(), dtype=np.float32))

    @property
    def params(self) -> HogParams:
        return self._p

    def work_scale(self, width_px: int, height_px: int) -> float:
        """The resize factor for an image of this size: 96 / min_person_px, capped by the pixel budget."""
        scale = WINDOW_PERSON_PX / self._p.min_person_px
        return min(scale, math.sqrt(self._p.max_work_pixels / float(width_px * height_px)))

    def find(self, image_bgr: np.ndarray) -> list[Candidate]:
        cv2 = self._cv2
        h, w = image_bgr.shape[:2]
        s = self.work_scale(w, h)
        work = cv2.resize(image_bgr, (round(w * s), round(h * s)), interpolation=cv2.INTER_LINEAR)
        stride = (self._p.win_stride_px, self._p.win_stride_px)
        rects, weights = self._hog.detectMultiScale(
            work,
            hitThreshold=self._p.hit_threshold,
            winStride=stride,
            padding=(8, 8),
            scale=self._p.scale_step,
        )
        found = [
            Candidate(box_px=np.array([x, y, x + bw, y + bh], dtype=float) / s, score=float(wt))
            for (x, y, bw, bh), wt in zip(np.reshape(rects, (-1, 4)), np.ravel(weights), strict=True)
        ]
        return non_max_suppression(found, self._p.nms_iou)
