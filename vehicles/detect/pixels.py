"""What a detector reports about a person in one image, and the message the detect process sends its agent.

Pixel convention (OpenCV's): u to the right, v down, (0, 0) the centre of the top-left pixel, in the raw
(distorted) image the camera delivered. The head point is the top of the head (the crown) and the feet point
the midpoint between the soles of the two feet: the two ends of the person's height, which the agent turns
into a range and a 3-D position (vehicles/detect/localize.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller.messages import frozen_array


def _freeze(obj: object, name: str, shape: tuple[int, ...]) -> None:
    object.__setattr__(obj, name, frozen_array(getattr(obj, name), shape, name))


@dataclass(frozen=True, eq=False)
class PersonPixels:
    """One person in one image.

    head_px (2,): top of the head; feet_px (2,): midpoint between the soles; head_conf, feet_conf in [0, 1]:
    how sure the back-end is that each point is visible and where it says (low for an occluded or cut-off
    point); box_px (4,): x0, y0, x1, y1 of the person's extent; score: the back-end's detection score
    (comparable within one back-end only); method: which stage produced the points ("pose", "hog", "onnx").
    """

    head_px: np.ndarray
    feet_px: np.ndarray
    head_conf: float
    feet_conf: float
    box_px: np.ndarray
    score: float = 1.0
    method: str = "pose"

    def __post_init__(self) -> None:
        _freeze(self, "head_px", (2,))
        _freeze(self, "feet_px", (2,))
        _freeze(self, "box_px", (4,))
        for name in ("head_conf", "feet_conf"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise ValueError(f"{name} must be in [0, 1], got {value}")

    @property
    def height_px(self) -> float:
        """Pixel distance from the feet point to the head point."""
        return float(np.hypot(*(self.feet_px - self.head_px)))

    @property
    def confidence(self) -> float:
        """The weaker of the two points' confidences: a detection is as good as its worse end."""
        return min(self.head_conf, self.feet_conf)


@dataclass(frozen=True, eq=False)
class CameraDetection:
    """One person seen by vehicle_id's camera in the frame captured at stamp_s (seconds, the clock the
    agent's telemetry is stamped with).

    frame_seq counts the camera's frames (gaps show dropped frames); image_size_px (width, height) lets the
    agent check the frame against its calibration; person: the pixels (raw, distorted image).
    """

    vehicle_id: int
    stamp_s: float
    frame_seq: int
    image_size_px: tuple[int, int]
    person: PersonPixels

    def __post_init__(self) -> None:
        if not math.isfinite(self.stamp_s):
            raise ValueError(f"stamp_s must be finite, got {self.stamp_s}")
        w, h = self.image_size_px
        if not (int(w) > 0 and int(h) > 0):
            raise ValueError(f"image_size_px must be positive, got {self.image_size_px}")
