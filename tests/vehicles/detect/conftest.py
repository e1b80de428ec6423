"""Shared set-up for the detection tests: the real footage from Debian's opencv-doc and the pose
environment, both installed by `make test` (targets `footage` and `pose-env`). Missing either fails the
test with the command that installs it: they are part of the test set-up, not optional."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

FOOTAGE = Path("/usr/share/doc/opencv-doc/examples/data")
LABELS = Path(__file__).parent / "data" / "labels.json"


def footage(name: str) -> Path:
    path = FOOTAGE / name
    if not path.is_file():
        pytest.fail(f"{path} is missing: `make footage` installs Debian's opencv-doc", pytrace=False)
    return path


def read_frame(name: str, frame: int | None) -> np.ndarray:
    """A still, or frame `frame` of a video, as (H, W, 3) BGR."""
    import cv2

    path = footage(name)
    if frame is None:
        image = cv2.imread(str(path))
    else:
        cap = cv2.VideoCapture(str(path))
        cap.set(cv2.CAP_PROP_POS_FRAMES, frame)
        ok, image = cap.read()
        cap.release()
        assert ok, f"cannot read frame {frame} of {path}"
    assert image is not None
    return image


@pytest.fixture(scope="module")
def pose_model():
    """One pose worker per test module (the pose environment's Python, started once)."""
    from vehicles.detect.pose import MediaPipePose, pose_python

    if not pose_python().exists():
        pytest.fail(f"{pose_python()} is missing: `make pose-env` builds the pose environment", pytrace=False)
    model = MediaPipePose()
    model.start()
    yield model
    model.close()
