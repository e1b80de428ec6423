"""server/lab/numeric_platform.py: every run records the numeric platform it was computed on (numpy's SIMD
targets, OpenBLAS's kernel, the C library), the one thing besides code, parameters and seed that decides its
bits, and a report says when its runs came from more than one."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

import pytest

from server.lab import experiments as exp
from server.lab import report as rep
from server.lab.numeric_platform import NumericPlatform, numeric_platform

SPEC = exp.plan_runs([exp.quick_protocol("obstacles")], base_seed=0)[0]
OTHER = NumericPlatform("2.4.6", ("X86_V3",), "Haswell", "glibc 2.36", "x86_64")


def test_a_finished_run_records_the_platform_of_the_process_that_ran_it():
    short = exp.Condition(
        name="2 MAVs", x=2.0, settings=(("vehicles", 2), ("warmup_s", 1.0), ("rate_hz", 10.0))
    )
    (spec,) = exp.plan_runs([exp.Protocol("scalability", (short,), (2.0,), rate_hz=10.0)], base_seed=0)
    result = exp.run_one(spec)
    assert result.ok and result.platform == numeric_platform()


def test_a_run_file_keeps_its_platform(tmp_path):
    exp.write_run(exp.RunResult(spec=SPEC, report={"config": {}, "metrics": {}}, platform=OTHER), tmp_path)
    loaded = exp.load_run(SPEC, tmp_path)
    assert loaded is not None and loaded.platform == OTHER


def test_a_run_file_from_before_platforms_were_recorded_loads_without_one(tmp_path):
    path = exp.write_run(exp.RunResult(spec=SPEC, report={"config": {}, "metrics": {}}), tmp_path)
    doc = json.loads(path.read_text())
    del doc["experiment"]["platform"]
    path.write_text(json.dumps(doc))
    loaded = exp.load_run(SPEC, tmp_path)
    assert loaded is not None and loaded.platform is None


@pytest.mark.skipif(platform.machine() != "x86_64", reason="OpenBLAS's Nehalem kernel exists on x86-64 only")
def test_the_platform_shows_numpy_targets_and_the_blas_kernel_the_environment_chose():
    """NPY_DISABLE_CPU_FEATURES and OPENBLAS_CORETYPE, set before numpy loads, change what a run computes
    with: the platform must say so (here every SIMD target this machine has off, and the SSE4.2 kernel,
    which any CPU that runs numpy 2.4 has)."""
    env = {
        **os.environ,
        "NPY_DISABLE_CPU_FEATURES": " ".join(numeric_platform().numpy_simd),
        "OPENBLAS_CORETYPE": "Nehalem",
    }
    code = (
        "import json; from server.lab.numeric_platform import numeric_platform; "
        "print(json.dumps(numeric_platform().to_json()))"
    )
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    there = NumericPlatform.from_json(json.loads(out.stdout))
    assert (there.numpy_simd, there.blas_core) == ((), "Nehalem")
    assert (there.numpy_version, there.libc) == (numeric_platform().numpy_version, numeric_platform().libc)


def test_a_report_names_the_platform_of_its_runs_without_a_warning_when_there_is_one():
    results = [exp.RunResult(spec=SPEC, report={}, platform=numeric_platform())] * 3
    text = "\n".join(rep.platform_lines(results))
    assert f"- 3 run(s): numpy {numeric_platform().numpy_version}" in text
    assert rep.MIXED_PLATFORMS not in text


def test_a_report_warns_when_its_runs_came_from_more_than_one_platform():
    results = [
        exp.RunResult(spec=SPEC, report={}, platform=numeric_platform()),
        exp.RunResult(spec=SPEC, report={}, platform=OTHER),
    ]
    text = "\n".join(rep.platform_lines(results))
    assert "OpenBLAS kernel Haswell" in text and rep.MIXED_PLATFORMS in text


def test_a_platform_document_without_its_fields_is_refused():
    with pytest.raises(ValueError, match="not a numeric platform"):
        NumericPlatform.from_json({"numpy_version": "2.4.6"})
