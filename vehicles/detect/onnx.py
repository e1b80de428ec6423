"""The plug-in point for a user-supplied ONNX pose model (`skyring detect --backend onnx --onnx-model FILE`).

skyring ships no ONNX weights (none that run offline come with a permissive licence on PyPI); bring your own,
e.g. a YOLOv8/YOLO11-pose export (`yolo export model=yolo11n-pose.pt format=onnx`, AGPL-3.0 weights) or an
RTMPose/RTMO export (Apache-2.0). The contract this back-end reads
(docs/detection.md#onnx-plug-in-vehiclesdetectonnxpy):

- one input, (1, 3, S, S) float32, RGB scaled to [0, 1]; the image is letterboxed into it (aspect kept,
  padded with grey 114);
- one output, (1, 5 + 3 K, N) or (1, N, 5 + 3 K): per candidate cx, cy, w, h (input pixels), person score,
  then K keypoints as (x, y, visibility) in input pixels, COCO order (K = 17: nose, eyes, ears, shoulders,
  elbows, wrists, hips, knees, ankles). Scores and visibilities in [0, 1] (logits are passed through a
  sigmoid when any falls outside).

`find` runs the model on the whole frame; `refine` on a square crop round the tracked person (more pixels
per person, as the default back-end does). Head: the crown, CROWN_ABOVE_EARS of the ears-to-feet distance
above the ears' midpoint along the hips-to-ears axis; feet: the ankles' midpoint lowered by ANKLE_HEIGHT of
that distance (COCO has no heel or toe points). Runs on onnxruntime's CPU provider (MIT; about 80 MB).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vehicles.detect.backends import person_box
from vehicles.detect.hog import Candidate, non_max_suppression
from vehicles.detect.pixels import PersonPixels
from vehicles.detect.pose import CROWN_ABOVE_EARS

COCO_EARS, COCO_HIPS, COCO_ANKLES = (3, 4), (11, 12), (15, 16)
ANKLE_HEIGHT = 0.045
"""Ankle (lateral malleolus) above the sole, in stature: about 7-8 cm of 1.75 m."""


def _letterbox(image_bgr: np.ndarray, size: int) -> tuple[np.ndarray, float, np.ndarray]:
    """(input (1, 3, S, S) float32, scale, offset (2,)): image pixel p maps to p * scale + offset."""
    import cv2

    h, w = image_bgr.shape[:2]
    k = size / max(h, w)
    nw, nh = max(int(round(w * k)), 1), max(int(round(h * k)), 1)
    canvas = np.full((size, size, 3), 114, np.uint8)
    off = np.array([(size - nw) // 2, (size - nh) // 2], dtype=float)
    canvas[int(off[1]) : int(off[1]) + nh, int(off[0]) : int(off[0]) + nw] = cv2.resize(image_bgr, (nw, nh))
    rgb = cv2.cvtColor(canvas, cv2.COLOR_BGR2RGB).astype(np.float32) / 255.0
    return rgb.transpose(2, 0, 1)[None], k, off


def head_and_feet_coco(keypoints: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    """(head_px, feet_px, head_conf, feet_conf) from COCO keypoints (17, 3) of x, y, visibility."""
    xy, vis = keypoints[:, :2], keypoints[:, 2]
    ears = xy[list(COCO_EARS)].mean(axis=0)
    hips = xy[list(COCO_HIPS)].mean(axis=0)
    ankles = xy[list(COCO_ANKLES)].mean(axis=0)
    up = ears - hips
    norm = float(np.hypot(*up))
    up = up / norm if norm > 1e-6 else np.array([0.0, -1.0])
    span = float(np.hypot(*(ankles - ears)))
    head = ears + CROWN_ABOVE_EARS * span * up
    feet = ankles - ANKLE_HEIGHT * span * up
    head_conf = float(np.mean(np.sort(vis[:5])[-3:]))
    feet_conf = float(np.mean(vis[list(COCO_ANKLES)]))
    return head, feet, min(max(head_conf, 0.0), 1.0), min(max(feet_conf, 0.0), 1.0)


class OnnxPoseDetector:
    """A user's single-stage ONNX pose model as a skyring back-end (the module docstring's contract)."""

    name = "onnx"

    def __init__(
        self,
        model_path: str | Path,
        *,
        min_score: float = 0.4,
        nms_iou: float = 0.5,
        crop_side: float = 1.6,
        threads: int = 1,
    ) -> None:
        import onnxruntime as ort

        opts = ort.SessionOptions()
        opts.intra_op_num_threads = threads
        self._session = ort.InferenceSession(str(model_path), opts, providers=["CPUExecutionProvider"])
        inputs = self._session.get_inputs()
        if len(inputs) != 1:
            raise ValueError(f"{model_path}: expected one input, the model has {len(inputs)}")
        shape = inputs[0].shape
        if len(shape) != 4 or shape[1] != 3 or not isinstance(shape[2], int) or shape[2] != shape[3]:
            raise ValueError(f"{model_path}: expected a (1, 3, S, S) input, the model's is {shape}")
        self._input = inputs[0].name
        self._size = int(shape[2])
        self._min_score = float(min_score)
        self._nms_iou = float(nms_iou)
        self._crop_side = float(crop_side)
        self.name = f"onnx:{Path(model_path).name}"

    def _run(self, image_bgr: np.ndarray) -> list[tuple[Candidate, np.ndarray]]:
        """Candidates (box and score, in image pixels) with their COCO keypoints (17, 3) in image pixels."""
        x, k, off = _letterbox(image_bgr, self._size)
        out = np.asarray(self._session.run(None, {self._input: x})[0], dtype=np.float32)
        if out.ndim != 3 or out.shape[0] != 1:
            raise ValueError(f"ONNX output must be (1, C, N) or (1, N, C), got {out.shape}")
        rows = out[0]
        if rows.shape[0] == 56 or (rows.shape[0] < rows.shape[1] and (rows.shape[0] - 5) % 3 == 0):
            rows = rows.T
        if (rows.shape[1] - 5) % 3 != 0 or (rows.shape[1] - 5) // 3 < 17:
            raise ValueError(f"ONNX output rows must hold 5 + 3 K values with K >= 17, got {rows.shape[1]}")
        score = rows[:, 4]
        kps = rows[:, 5:].reshape(len(rows), -1, 3)[:, :17].copy()
        if np.any((score < 0) | (score > 1)):
            score = 1.0 / (1.0 + np.exp(-score))
        if np.any((kps[:, :, 2] < 0) | (kps[:, :, 2] > 1)):
            kps[:, :, 2] = 1.0 / (1.0 + np.exp(-kps[:, :, 2]))
        keep = np.flatnonzero(score >= self._min_score)
        found: list[tuple[Candidate, np.ndarray]] = []
        for i in keep:
            cx, cy, w, h = rows[i, :4]
            box = (np.array([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2]) - np.tile(off, 2)) / k
            pts = kps[i].copy()
            pts[:, :2] = (pts[:, :2] - off) / k
            found.append((Candidate(box_px=box, score=float(score[i])), pts))
        kept = {id(c) for c in non_max_suppression([c for c, _ in found], self._nms_iou)}
        return sorted([f for f in found if id(f[0]) in kept], key=lambda f: -f[0].score)

    def _person(self, cand: Candidate, kps: np.ndarray) -> PersonPixels | None:
        head, feet, head_conf, feet_conf = head_and_feet_coco(kps)
        if head[1] >= feet[1]:
            return None
        return PersonPixels(
            head_px=head,
            feet_px=feet,
            head_conf=head_conf,
            feet_conf=feet_conf,
            box_px=person_box(head, feet),
            score=cand.score,
            method="onnx",
        )

    def find(self, image_bgr: np.ndarray) -> list[PersonPixels]:
        people = [self._person(c, k) for c, k in self._run(image_bgr)]
        return [p for p in people if p is not None]

    def refine(self, image_bgr: np.ndarray, box_px: np.ndarray) -> PersonPixels | None:
        import cv2

        box = np.asarray(box_px, dtype=float)
        centre = 0.5 * (box[:2] + box[2:])
        side = max(self._crop_side * float(box[3] - box[1]), 16.0)
        k = self._size / side
        m = np.array([[k, 0.0, self._size / 2 - k * centre[0]], [0.0, k, self._size / 2 - k * centre[1]]])
        crop = cv2.warpAffine(image_bgr, m, (self._size, self._size), borderMode=cv2.BORDER_REPLICATE)
        best: PersonPixels | None = None
        best_d = np.inf
        for cand, kps in self._run(crop):
            # back from crop pixels to image pixels
            kps = kps.copy()
            kps[:, :2] = (kps[:, :2] - m[:, 2]) / k
            cand = Candidate(box_px=(cand.box_px - np.tile(m[:, 2], 2)) / k, score=cand.score)
            person = self._person(cand, kps)
            if person is None:
                continue
            d = float(np.hypot(*(0.5 * (person.head_px + person.feet_px) - centre)))
            if d < best_d:
                best, best_d = person, d
        return best

    def close(self) -> None:
        return None
