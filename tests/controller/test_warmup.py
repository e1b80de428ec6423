"""controller/warmup.py runs every compiled kernel on a tick's path once."""

from __future__ import annotations

from controller import (
    fields_kernel,
    mpc_kernels,
    qp,
    reference_kernel,
    separation_kernel,
    teammates,
    tracker,
)
from controller.warmup import warm_up


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
        tracker._predicted,
        tracker._gate_distance_sq,
    )
    assert all(kernel.signatures for kernel in kernels)
