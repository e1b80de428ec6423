"""controller/warmup.py runs every compiled kernel on a tick's path once."""

from __future__ import annotations

from controller import dual_active_set, fields_kernel, mpc_kernels, qp, separation_kernel, teammates, tracker
from controller.warmup import warm_up


def test_warm_up_leaves_every_kernel_of_the_tick_compiled():
    warm_up()
    kernels = (
        fields_kernel._kernel,
        mpc_kernels.solve_fast,
        mpc_kernels.rollout,
        mpc_kernels.half_plane_rows,
        mpc_kernels.solve_with_planes,
        mpc_kernels.checked_planes,
        mpc_kernels.roll_out_variables,
        qp.compiled_step_3,
        teammates.align_rows,
        teammates.fresh_paths,
        separation_kernel.row_inflation,
        tracker._predicted,
        tracker._gate_distance_sq,
        dual_active_set.solve_identity_qp,
    )
    assert all(kernel.signatures for kernel in kernels)
