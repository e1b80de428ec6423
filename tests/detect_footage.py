"""Real footage for the detection tests: Debian's opencv-doc (examples/data), installed by `make footage`
(part of `make test`), and the hand-labelled frames in tests/vehicles/detect/data/labels.json. Missing
footage fails the test with the command that installs it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

FOOTAGE = Path("/usr/share/doc/opencv-doc/examples/data")
LABELS = Path(__file__).parent / "vehicles" / "detect" / "data" / "labels.json"


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
