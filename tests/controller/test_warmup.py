"""controller/warmup.py runs every compiled kernel on a tick's path once, in the specializations a flight
uses."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from controller import (
    fields_kernel,
    mpc_kernels,
    qp,
    reference_kernel,
    separation_kernel,
    teammates,
    tick_kernel,
    tracker,
)
from controller.params import Method
from controller.warmup import warm_up

PROBE = Path(__file__).resolve().parents[1] / "kernel_signature_probe.py"
# Per method, short flights that reach the rarer paths: half-planes the closed form misses (from a clustered
# start), the fixed rows' re-solve (the 100 Hz ring), the price baseline's own half-planes, a lossy link.
FLIGHTS = {
    Method.ACTIVE: (
        {"vehicles": 8, "duration_s": 20.0, "warmup_s": 19.0, "rate_hz": 10.0, "start": "cluster", "seed": 3},
        {"vehicles": 4, "duration_s": 12.0, "warmup_s": 11.0, "rate_hz": 100.0, "seed": 2},
        # a lossy link: holds, phantom teammates, late detections re-filtered
        {"vehicles": 10, "duration_s": 12.0, "warmup_s": 11.0, "rate_hz": 10.0, "seed": 4, "comm_loss": 0.6},
    ),
    Method.PRICE: ({"vehicles": 4, "duration_s": 14.0, "warmup_s": 13.0, "rate_hz": 10.0, "trees": "none"},),
    Method.DQMPC: (
        {"vehicles": 5, "duration_s": 14.0, "warmup_s": 13.0, "rate_hz": 10.0, "start": "cluster"},
    ),
}
# What each method's flights must have called, so that "nothing compiled" is not a flight that went nowhere.
REACHED = {
    Method.ACTIVE: ("solve_with_planes", "roll_out_variables", "checked_planes"),
    Method.PRICE: ("checked_planes",),
    Method.DQMPC: ("checked_planes",),
}


def _probe(warm_up_for: str, methods: list[Method]) -> dict:
    """The probe's report ({"gained": kernel -> new signatures, "calls": kernel -> calls}) for the flights of
    `methods` after warm_up_for's warm-up, in a fresh process."""
    flights = [{**flight, "method": m.value} for m in methods for flight in FLIGHTS[m]]
    run = subprocess.run(
        # -P: the probe's folder (tests/, whose server/ holds tests) does not go before the packages
        [sys.executable, "-P", str(PROBE), warm_up_for, json.dumps(flights)],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads(run.stdout.splitlines()[-1])


def test_warm_up_leaves_every_kernel_of_the_tick_compiled():
    """Every kernel the tick calls from Python. Kernels called only from other kernels (the rollout inside
    `roll_out_variables`, the active set inside `compiled_step_3`) are compiled into their callers: loaded
    from numba's cache, a caller does not load them on their own, so they have no signature to check."""
    warm_up()
    kernels = (
        fields_kernel._kernel,
        mpc_kernels.solve_fast,
        mpc_kernels.half_plane_rows,
        mpc_kernels.solve_with_planes,
        mpc_kernels.checked_planes,
        mpc_kernels.roll_out_variables,
        qp.compiled_step_3,
        teammates.fresh_paths,
        reference_kernel.start_and_horizon,
        reference_kernel.aim,
        reference_kernel.waypoint,
        separation_kernel.tick_rows,
        tick_kernel.inputs_and_rows,
        tracker._predicted,
        tracker._gate_distance_sq,
    )
    assert all(kernel.signatures for kernel in kernels)


@pytest.mark.parametrize("method", list(Method), ids=lambda m: m.value)
def test_a_flight_after_warm_up_compiles_no_kernel_again(method: Method):
    """numba compiles a kernel once per layout and writability of its arrays: an array handed over read-only
    in flight where the warm-up's was writable loads (or, on a fresh install, compiles: 1.4 s for
    solve_with_planes) a second specialization mid-flight. The warm-up for the method, as an agent and the
    station run it; checked in a fresh process, as they start."""
    report = _probe(method.value, [method])
    assert {name: report["calls"].get(name, 0) > 0 for name in REACHED[method]} == dict.fromkeys(
        REACHED[method], True
    )
    assert report["gained"] == {}


def test_the_compiled_kalman_filters_warm_up_covers_its_flights():
    """`TrackerParams(kalman_filter="compiled")` (not the default) moves the track with controller/kalman.py's
    kernels: warmed up with it, the active method's flights (late detections re-filtered over the lossy link
    among them) compile nothing again."""
    report = _probe("compiled-kf", [Method.ACTIVE])
    assert report["calls"].get("predicted", 0) > 0 and report["calls"].get("updated", 0) > 0
    assert report["gained"] == {}


def test_the_default_warm_up_covers_every_methods_flight():
    """The kernels take one layout whatever the method (`controller/kernel_args.py`), so `warm_up()` with the
    default parameters leaves nothing for a price or dqmpc flight to compile either."""
    report = _probe("default", list(Method))
    assert report["gained"] == {}
    assert report["calls"].get("solve_with_planes", 0) > 0
