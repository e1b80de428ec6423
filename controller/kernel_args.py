"""How arrays are handed to the compiled kernels: in one layout, so that each kernel has one specialization.

numba compiles a kernel once per combination of its arguments' types, and an array's layout and writability
are part of its type. A caller whose array is read-only (a message's) on some ticks and writable on others
would make a kernel load, or on a fresh install compile, a second specialization in the middle of a flight
(`solve_with_planes`: 19 ms loaded, 1.4 s compiled), after `controller.warmup` compiled the first.
"""

from __future__ import annotations

import numpy as np


def kernel_array(value, dtype) -> np.ndarray:
    """`value` as a C-contiguous, writable array of `dtype` (None: its own), the layout the kernels are
    compiled for; a copy only when `value` is not such an array already."""
    arr = np.asarray(value, dtype=dtype)
    flags = arr.flags  # one flags object, not two (this runs some twenty times a tick)
    if flags.c_contiguous and flags.writeable:
        return arr
    return np.array(arr, order="C")
