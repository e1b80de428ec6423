"""`skyring detect` as a user runs it: on real footage, with a preview, and with bad options."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

VTEST = Path("/usr/share/doc/opencv-doc/examples/data/vtest.avi")


def _skyring(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "server.cli", *args], capture_output=True, text=True, timeout=timeout
    )


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """30 frames of vtest.avi through `skyring detect`. The footage plays at its own frame rate (a camera
    stand-in) and the detector takes the newest frame, so how many frames show the person depends on the
    detector keeping up: the tests that read this run are marked `alone`. Beside the parallel suite, CI's
    first frame took 14 s (the next one processed was number 139, not 8 as on an idle machine) and 12 of 30
    frames had a detection."""
    if not VTEST.is_file():
        pytest.fail(f"{VTEST} is missing: `make footage` installs Debian's opencv-doc", pytrace=False)
    out = tmp_path_factory.mktemp("detect")
    proc = _skyring(
        "detect",
        "--id",
        "3",
        "--camera",
        str(VTEST),
        "--frames",
        "30",
        "--out",
        str(out / "det.jsonl"),
        "--preview",
        str(out / "preview"),
    )
    lines = [json.loads(x) for x in (out / "det.jsonl").read_text().splitlines()]
    return proc, lines, out


@pytest.mark.alone
def test_detections_of_real_footage_are_written_with_capture_stamps(run):
    proc, lines, _ = run
    assert proc.returncode == 0, proc.stderr
    dets = [x for x in lines if x["type"] == "detection"]
    assert len(dets) >= 15  # most of 30 frames, after the first search
    stamps = [d["stamp_s"] for d in dets]
    assert stamps == sorted(stamps) and all(s > 1.7e9 for s in stamps)  # wall-clock capture times
    for d in dets:
        assert d["vehicle_id"] == 3 and d["image_size_px"] == [768, 576]
        assert d["head_px"][1] < d["feet_px"][1]
        assert 0.0 <= d["head_conf"] <= 1.0 and 0.0 <= d["feet_conf"] <= 1.0


@pytest.mark.alone
def test_reports_carry_the_camera_state_and_a_thumbnail(run):
    _, lines, _ = run
    reports = [x for x in lines if x["type"] == "report"]
    assert reports and reports[-1]["camera_state"] in ("streaming", "ended")
    assert reports[-1]["frames"] >= 30 and reports[-1]["detector_errors"] == 0
    assert any(r["thumbnail_jpeg_b64"] for r in reports)


@pytest.mark.alone
def test_the_preview_writes_every_processed_frame_with_its_overlay(run):
    _, _, out = run
    frames = sorted((out / "preview").glob("frame-*.jpg"))
    assert len(frames) == 30


def test_bad_options_end_with_status_2_and_one_line():
    for args, word in (
        (["detect", "--id", "1", "--camera", "/nonexistent.avi"], "--camera"),
        (["detect", "--id", "0", "--camera", str(VTEST)], "--id"),
        (["detect", "--id", "1", "--camera", str(VTEST), "--backend", "yolo"], "--backend"),
        (
            ["detect", "--id", "1", "--camera", str(VTEST), "--calibration", "/nonexistent.yaml"],
            "--calibration",
        ),
    ):
        proc = _skyring(*args, timeout=60)
        assert proc.returncode == 2, (args, proc.stderr)
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and word in lines[0], (args, proc.stderr)


def test_write_calibration_gives_an_opencv_yaml_template(tmp_path):
    path = tmp_path / "cam.yaml"
    proc = _skyring("detect", "--write-calibration", str(path), timeout=60)
    assert proc.returncode == 0, proc.stderr
    text = path.read_text()
    assert text.startswith("%YAML:1.0") and "camera_to_body_rotation" in text and "1470.3" in text  # fx
