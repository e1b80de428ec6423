"""Shared set-up for the detection tests: the real footage from Debian's opencv-doc and the pose
environment, both installed by `make test` (targets `footage` and `pose-env`). Missing either fails the
test with the command that installs it: they are part of the test set-up, not optional."""

from __future__ import annotations

import pytest


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
