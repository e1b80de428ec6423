"""Per-frame detection of the one person the team follows: acquire with a full-frame search, then track.

Acquisition runs the back-end's `find` on the whole frame and takes the most confident person (the
operator frames the athlete at take-off; `prefer_px` can point at them), or, after a loss, the person
nearest to where the track was heading. Tracking predicts the person's box in the next frame from the last
two (constant velocity in the image, in pixels per second of capture time) and runs only the back-end's
`refine` on a crop round it: one pose-model call instead of a full scan. A refined person whose size or
place jumps against the prediction (by `max_size_change` or `max_shift` heights) is not taken (a
neighbour, or a pose model guessing). After `lost_after` frames without the person, the next frame searches
the whole image again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vehicles.detect.backends import BOX_PER_PERSON, PersonDetector, person_box
from vehicles.detect.pixels import PersonPixels


@dataclass(frozen=True)
class PipelineParams:
    """lost_after: frames without the person before a full search; max_speed_frac: a track whose box
    centre moves more than this many box heights per second is not extrapolated further (a jump);
    min_confidence: a refined person below this counts as not seen; max_size_change: a refined person
    more than this factor taller or shorter than the track is not taken; max_shift: nor one whose centre is
    further than this many heights from the predicted centre."""

    lost_after: int = 3
    max_speed_frac: float = 3.0
    min_confidence: float = 0.3
    max_size_change: float = 1.35
    max_shift: float = 0.5

    def __post_init__(self) -> None:
        if self.lost_after < 1:
            raise ValueError("lost_after must be at least 1")


@dataclass(frozen=True, eq=False)
class FrameResult:
    """What the pipeline made of one frame: person (None when not seen), searched (a full-frame search
    ran), everyone (all people the search found; empty when tracking)."""

    person: PersonPixels | None
    searched: bool
    everyone: tuple[PersonPixels, ...] = ()


class DetectionPipeline:
    """Acquire, then track, one person through a sequence of frames."""

    def __init__(self, backend: PersonDetector, params: PipelineParams | None = None) -> None:
        self._backend = backend
        self._p = params or PipelineParams()
        self._last: tuple[float, PersonPixels] | None = None
        self._velocity = np.zeros(4)  # box corners, pixels per second
        self._misses = 0
        self.searches = 0
        self.refines = 0

    @property
    def backend(self) -> PersonDetector:
        return self._backend

    @property
    def tracking(self) -> bool:
        return self._last is not None

    def predicted_box(self, stamp_s: float) -> np.ndarray | None:
        """(4,) where the tracked person's box should be at stamp_s, or None when not tracking."""
        if self._last is None:
            return None
        t0, person = self._last
        dt = min(max(stamp_s - t0, 0.0), 1.0)
        return person.box_px + self._velocity * dt

    def process(
        self, image_bgr: np.ndarray, stamp_s: float, *, prefer_px: np.ndarray | None = None
    ) -> FrameResult:
        """Detect the followed person in one frame captured at stamp_s."""
        box = self.predicted_box(stamp_s)
        if box is not None:
            self.refines += 1
            person = self._backend.refine(image_bgr, box)
            if person is not None and self._plausible(person, box):
                self._update(stamp_s, person)
                return FrameResult(person=person, searched=False)
            self._misses += 1
            if self._misses < self._p.lost_after:
                return FrameResult(person=None, searched=False)
            self._last = None
            if prefer_px is None:
                prefer_px = 0.5 * (box[:2] + box[2:])
        self.searches += 1
        everyone = tuple(p for p in self._backend.find(image_bgr) if p.confidence >= self._p.min_confidence)
        if not everyone:
            return FrameResult(person=None, searched=True)
        if prefer_px is not None:
            target = np.asarray(prefer_px, dtype=float)
            chosen = min(everyone, key=lambda p: float(np.hypot(*(0.5 * (p.head_px + p.feet_px) - target))))
        else:
            chosen = max(everyone, key=lambda p: p.score * p.confidence)
        self._velocity = np.zeros(4)
        self._last = None
        self._update(stamp_s, chosen)
        return FrameResult(person=chosen, searched=True, everyone=everyone)

    def _plausible(self, person: PersonPixels, predicted_box: np.ndarray) -> bool:
        if person.confidence < self._p.min_confidence:
            return False
        height = float(predicted_box[3] - predicted_box[1]) / BOX_PER_PERSON
        ratio = person.height_px / max(height, 1.0)
        if not 1.0 / self._p.max_size_change <= ratio <= self._p.max_size_change:
            return False
        centre = 0.5 * (person.head_px + person.feet_px)
        shift = float(np.hypot(*(centre - 0.5 * (predicted_box[:2] + predicted_box[2:]))))
        return shift <= self._p.max_shift * height

    def _update(self, stamp_s: float, person: PersonPixels) -> None:
        box = person_box(person.head_px, person.feet_px)
        if self._last is not None:
            t0, old = self._last
            dt = stamp_s - t0
            if dt > 1e-3:
                v = (box - old.box_px) / dt
                height = max(float(box[3] - box[1]), 1.0)
                speed = float(np.hypot(v[0] + v[2], v[1] + v[3])) / 2.0
                self._velocity = v if speed <= self._p.max_speed_frac * height else np.zeros(4)
        self._last = (stamp_s, person)
        self._misses = 0

    def reset(self) -> None:
        """Forget the track: the next frame searches the whole image."""
        self._last = None
        self._velocity = np.zeros(4)
        self._misses = 0
