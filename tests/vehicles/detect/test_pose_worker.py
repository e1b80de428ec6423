"""The pose model's own process: answers, survives bad requests, and is restarted when it dies."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numpy as np
import pytest
from detect_footage import read_frame

from vehicles.detect.backends import CropParams, make_crop
from vehicles.detect.pose import ROI_PX, MediaPipePose, PoseWorkerError, head_and_feet, pose_python


def _crop() -> np.ndarray:
    """vtest.avi frame 640, the woman labelled F (head (358, 386), feet (368, 517)), as a pose-model crop."""
    image = read_frame("vtest.avi", 640)
    box = np.array([363 - 44, 451 - 88, 363 + 44, 451 + 88], dtype=float)
    crop, _ = make_crop(image, box, CropParams())
    return crop


def test_landmarks_of_a_real_person_are_found_in_the_crop(pose_model):
    pose = pose_model.estimate(_crop())
    marks = pose.landmarks
    assert marks is not None and marks.shape == (33, 3) and pose.presence > 0.9 and pose.mask is None
    head, feet, head_conf, feet_conf = head_and_feet(marks)
    assert head[1] < feet[1] and 0.0 < head_conf <= 1.0 and 0.0 < feet_conf <= 1.0
    assert 0.0 <= head[0] <= ROI_PX and 0.0 <= feet[1] <= ROI_PX


def test_an_empty_crop_holds_nobody(pose_model):
    assert pose_model.estimate(np.full((ROI_PX, ROI_PX, 3), 128, np.uint8)).presence < 0.5


def test_a_crop_of_the_wrong_size_is_refused_before_it_is_sent(pose_model):
    with pytest.raises(ValueError, match="256"):
        pose_model.estimate(np.zeros((100, 100, 3), np.uint8))


def test_a_killed_worker_fails_one_call_and_is_restarted_by_the_next():
    if not pose_python().exists():
        pytest.fail("the pose environment is missing: `make pose-env`", pytrace=False)
    with MediaPipePose(timeout_s=10.0) as model:
        model.start()
        proc = model._proc
        assert proc is not None
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=5)
        with pytest.raises(PoseWorkerError, match="exited|closed"):
            model.estimate(_crop())
        assert model.restarts == 1
        pose = model.estimate(_crop())
        assert pose.landmarks is not None and pose.presence > 0.9


def test_a_missing_pose_environment_is_a_clear_error(tmp_path):
    model = MediaPipePose(python=tmp_path / "nope" / "python")
    with pytest.raises(PoseWorkerError, match="make pose-env"):
        model.start()


def test_the_whole_image_mode_returns_the_person_and_its_mask(pose_model):
    image = read_frame("messi5.jpg", None)
    pose = pose_model.estimate(image[:, :, ::-1].copy(), mode="full")
    assert pose.landmarks is not None and pose.presence == 1.0
    assert pose.mask is not None and pose.mask.shape == image.shape[:2]
    nose = pose.landmarks[0, :2].round().astype(int)
    assert pose.mask[nose[1], nose[0]] > 0.9  # the face is on the person
    assert pose.mask[5, 5] < 0.1 and pose.mask[-5, -5] < 0.1  # the crowd and the pitch are not


def test_a_reply_announcing_an_impossible_mask_fails_the_call(tmp_path, monkeypatch):
    """A worker (here a stand-in script) whose reply promises a mask of a negative size is treated as broken:
    the call fails with PoseWorkerError and the worker is counted as restarted, never read from further."""
    import sys

    import vehicles.detect.pose as pose

    script = tmp_path / "liar.py"
    script.write_text(
        "import json, struct, sys\n"
        "def send(obj):\n"
        "    data = json.dumps(obj).encode()\n"
        "    sys.stdout.buffer.write(struct.pack('<I', len(data)) + data)\n"
        "    sys.stdout.buffer.flush()\n"
        "send({'ready': True, 'mediapipe': 'stand-in'})\n"
        "n = struct.unpack('<I', sys.stdin.buffer.read(4))[0]\n"
        "header = json.loads(sys.stdin.buffer.read(n))\n"
        "sys.stdin.buffer.read(header['w'] * header['h'] * 3)\n"
        "send({'landmarks': None, 'presence': 0.0, 'ms': 0.0, 'mask': [-4, 5]})\n"
        "sys.stdin.buffer.read()\n"
    )
    monkeypatch.setattr(pose, "WORKER", script)
    with MediaPipePose(python=Path(sys.executable), timeout_s=5.0) as model:
        with pytest.raises(PoseWorkerError, match="mask of shape"):
            model.estimate(np.zeros((64, 64, 3), np.uint8), mode="full")
        assert model.restarts == 1
