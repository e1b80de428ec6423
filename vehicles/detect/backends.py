"""Detector back-ends: the interface every one implements, and the default (HOG to acquire, MediaPipe pose
on a crop to place head and feet).

A back-end answers two questions (docs/detection.md#back-ends):
- `find(image)`: everyone in a whole frame (acquisition; slow: a full-frame scan);
- `refine(image, box)`: the person in a region round a predicted box (tracking; fast: one crop).

A crop is a square round the box (`crop_side` times the box's height) resampled to `crop_px`; columns further
than `mask_half_width` person-heights from the box's centre are greyed out so that a neighbour beside the
person does not take the pose model's attention (the model reports one person per crop).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from vehicles.detect.hog import HogParams, HogPeople
from vehicles.detect.pixels import PersonPixels
from vehicles.detect.pose import ROI_PX, MediaPipePose, PoseEstimate, head_and_feet

BOX_PER_PERSON = 4.0 / 3.0
"""A person box is this many person heights tall (the HOG window's convention: 96 px of person in 128)."""


HIDE_HALF_WIDTH = 0.17
"""Half-width, in person heights, of the band that greys out an already found person (shoulders are about
a quarter of the height wide)."""

NEIGHBOUR_SHIFT = 0.35
"""A found person's neighbours are looked for in crops shifted sideways by this many of its heights (about
where a person walking shoulder to shoulder stands; 0.3-0.4 find the same people in the labelled frames)."""

NEIGHBOUR_HEIGHT_RATIO = 1.25
"""A neighbour found that way is kept only if its height is within this ratio of the person's: side by side
means at about the same distance; a pose joining one person's head to another's legs is not."""

CANDIDATE_SHIFTS = (0.0, -0.08, 0.08)
"""Each HOG candidate's crop is given to the pose model at its box and shifted up and down by these many
box heights, and the most confident pose is kept: where two people overlap, the centred crop can join one's
head to the other's legs, and a crop that centres either of them better finds that one whole."""

WHOLE_IMAGE_PX = 640
"""The whole-image pass runs on the image shrunk to this longest side (MediaPipe's detector works at 224)."""


def _duplicate(person: PersonPixels, found: list[PersonPixels]) -> bool:
    """True when person is one already found: head and feet both within a fifth of its height."""
    tol = 0.2 * person.height_px
    return any(
        np.hypot(*(person.head_px - f.head_px)) < tol and np.hypot(*(person.feet_px - f.feet_px)) < tol
        for f in found
    )


class PersonDetector(Protocol):
    """What the detection pipeline needs from a back-end. Images are (H, W, 3) uint8 BGR."""

    name: str

    def find(self, image_bgr: np.ndarray) -> list[PersonPixels]:
        """Every person found in the whole image, most confident first."""
        ...

    def refine(self, image_bgr: np.ndarray, box_px: np.ndarray) -> PersonPixels | None:
        """The person inside the region round box_px (4,) x0, y0, x1, y1, or None."""
        ...

    def close(self) -> None:
        """Release child processes and sessions."""
        ...


def person_box(head_px: np.ndarray, feet_px: np.ndarray) -> np.ndarray:
    """(4,) the person box of a head and feet point: BOX_PER_PERSON heights tall, half as wide, centred."""
    centre = 0.5 * (np.asarray(head_px, dtype=float) + np.asarray(feet_px, dtype=float))
    h = max(float(np.hypot(*(np.asarray(feet_px) - np.asarray(head_px)))), 1.0) * BOX_PER_PERSON
    return np.array([centre[0] - h / 4, centre[1] - h / 2, centre[0] + h / 4, centre[1] + h / 2])


@dataclass(frozen=True)
class CropParams:
    """crop_px: side of the resampled crop given to the pose model; crop_side: crop side in box heights;
    mask_half_width: columns beyond this many box heights from the centre are greyed (0 = no mask);
    min_points_conf: head or feet below this make the result unusable; min_presence: the landmark model's
    own person-presence score below which the crop holds nobody."""

    crop_px: int = ROI_PX
    crop_side: float = 1.15
    mask_half_width: float = 0.25
    min_points_conf: float = 0.2
    min_presence: float = 0.5


def crop_transform(box_px: np.ndarray, p: CropParams) -> np.ndarray:
    """(2, 3) affine image -> crop transform of the square crop round box_px."""
    cx, cy = 0.5 * (box_px[0] + box_px[2]), 0.5 * (box_px[1] + box_px[3])
    side = max(p.crop_side * float(box_px[3] - box_px[1]), 8.0)
    k = p.crop_px / side
    return np.array([[k, 0.0, p.crop_px / 2 - k * cx], [0.0, k, p.crop_px / 2 - k * cy]])


def make_crop(
    image_bgr: np.ndarray, box_px: np.ndarray, p: CropParams, *, hide: list[PersonPixels] | tuple = ()
) -> tuple[np.ndarray, np.ndarray]:
    """(crop RGB (crop_px, crop_px, 3), affine (2, 3) image -> crop). Columns beyond mask_half_width and
    the bodies of the people in `hide` (a band HIDE_HALF_WIDTH of their height either side of their
    head-feet line) are filled with the crop's mean colour."""
    import cv2

    m = crop_transform(box_px, p)
    crop = cv2.warpAffine(
        image_bgr, m, (p.crop_px, p.crop_px), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
    )
    grey = tuple(int(c) for c in crop.mean(axis=(0, 1)))
    if p.mask_half_width > 0:
        half = p.mask_half_width * float(box_px[3] - box_px[1]) * m[0, 0]
        lo, hi = int(max(p.crop_px / 2 - half, 0)), int(min(p.crop_px / 2 + half, p.crop_px))
        crop[:, :lo] = grey
        crop[:, hi:] = grey
    for other in hide:
        a, b = m @ np.append(other.head_px, 1.0), m @ np.append(other.feet_px, 1.0)
        width = max(int(round(2 * HIDE_HALF_WIDTH * float(np.hypot(*(b - a))))), 1)
        top = a + (a - b) * 0.1
        cv2.line(crop, (int(top[0]), int(top[1])), (int(b[0]), int(b[1])), grey, thickness=width)
    return cv2.cvtColor(crop, cv2.COLOR_BGR2RGB), m


def to_image(points_crop: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Crop pixels (..., 2) back to image pixels through the inverse of the affine m (2, 3)."""
    k = m[0, 0]
    return (np.asarray(points_crop, dtype=float) - m[:, 2]) / k


class HogPoseDetector:
    """The default back-end: HOG finds candidates, MediaPipe's pose model places head and feet on a crop.

    Offline: OpenCV's HOG model is compiled into OpenCV, MediaPipe's pose models are inside its wheel.
    """

    name = "hog+mediapipe"

    def __init__(
        self,
        *,
        pose: MediaPipePose | None = None,
        hog: HogParams | None = None,
        crop: CropParams | None = None,
        max_candidates: int = 10,
    ) -> None:
        self._pose = pose or MediaPipePose()
        self._hog = HogPeople(hog)
        self._crop = crop or CropParams()
        self._max_candidates = int(max_candidates)

    @property
    def pose(self) -> MediaPipePose:
        return self._pose

    def find(self, image_bgr: np.ndarray) -> list[PersonPixels]:
        """HOG candidates, each crop (at the box and shifted up and down) given to the landmark model with the
        people found so far greyed out and tried again after the person it gave is greyed too (two people in
        one box); then, beside each person found, crops shifted sideways with that person greyed (a
        neighbour walking shoulder to shoulder, whom HOG merges into one box and the centred crop masks
        out); then MediaPipe's own detector on the whole image for a person too large or too unusually
        posed for HOG."""
        found: list[PersonPixels] = []
        for cand in self._hog.find(image_bgr)[: self._max_candidates]:
            for _ in range(2):
                person = self._best_of_shifts(image_bgr, cand.box_px, hide=found)
                if person is None or _duplicate(person, found):
                    break
                found.append(person)
        for person in list(found):
            for side in (-1.0, 1.0):
                shift = side * NEIGHBOUR_SHIFT * person.height_px
                box = person.box_px + np.array([shift, 0.0, shift, 0.0])
                other = self.refine(image_bgr, box, hide=[person])
                if other is None or _duplicate(other, found):
                    continue
                if abs(math.log(other.height_px / person.height_px)) <= math.log(NEIGHBOUR_HEIGHT_RATIO):
                    found.append(other)
        whole = self._whole_image(image_bgr)
        if whole is not None and not _duplicate(whole, found):
            found.append(whole)
        return sorted(found, key=lambda p: -p.score)

    def refine(
        self, image_bgr: np.ndarray, box_px: np.ndarray, *, hide: list[PersonPixels] | tuple = ()
    ) -> PersonPixels | None:
        """The person in the crop round box_px; people in `hide` are greyed out of the crop first."""
        box = np.asarray(box_px, dtype=float)
        crop, m = make_crop(image_bgr, box, self._crop, hide=hide)
        pose = self._pose.estimate(crop, mode="roi")
        if pose.landmarks is None or pose.presence < self._crop.min_presence:
            return None
        person = self._person(pose, m)
        if person is None:
            return None
        box_h = float(box[3] - box[1]) / BOX_PER_PERSON
        if not 0.5 * box_h <= person.height_px <= 1.5 * box_h:
            return None  # a person of another size than the one looked for: a neighbour or a false pose
        return person

    def _best_of_shifts(
        self, image_bgr: np.ndarray, box_px: np.ndarray, *, hide: list[PersonPixels]
    ) -> PersonPixels | None:
        """The most confident person of the crops round box_px shifted by CANDIDATE_SHIFTS; the shifted ones
        are tried only when the first (the box itself) holds a person, as most candidates hold nobody."""
        height = float(box_px[3] - box_px[1])
        people: list[PersonPixels] = []
        for dy in CANDIDATE_SHIFTS:
            person = self.refine(image_bgr, box_px + np.array([0.0, dy, 0.0, dy]) * height, hide=hide)
            if person is None and not people:
                return None
            if person is not None:
                people.append(person)
        return max(people, key=lambda p: p.score)

    def _whole_image(self, image_bgr: np.ndarray) -> PersonPixels | None:
        import cv2

        h, w = image_bgr.shape[:2]
        k = min(1.0, WHOLE_IMAGE_PX / max(h, w))
        small = cv2.resize(image_bgr, (round(w * k), round(h * k)), interpolation=cv2.INTER_AREA)
        pose = self._pose.estimate(cv2.cvtColor(small, cv2.COLOR_BGR2RGB), mode="full")
        if pose.landmarks is None:
            return None
        m = np.array([[k, 0.0, 0.0], [0.0, k, 0.0]])
        return self._person(pose, m, method="pose-whole")

    def _person(self, pose: PoseEstimate, m: np.ndarray, method: str = "pose") -> PersonPixels | None:
        marks = pose.landmarks
        assert marks is not None
        head_c, feet_c, head_conf, feet_conf = head_and_feet(marks, pose.mask)
        if min(head_conf, feet_conf) < self._crop.min_points_conf or head_c[1] >= feet_c[1]:
            return None
        head, feet = to_image(head_c, m), to_image(feet_c, m)
        return PersonPixels(
            head_px=head,
            feet_px=feet,
            head_conf=head_conf,
            feet_conf=feet_conf,
            box_px=person_box(head, feet),
            score=pose.presence * float(np.mean(marks[:, 2])),
            method=method,
        )

    def close(self) -> None:
        self._pose.close()
