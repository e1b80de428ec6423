"""What decides a simulation's round-off besides the code, its parameters and its seed: the numeric platform.

numpy picks SIMD code paths for the CPU it runs on (with AVX-512, `np.arctan2` takes a vectorised path that
rounds differently from the C library's in a few per cent of arguments), OpenBLAS picks a kernel per CPU
family for the matrix products (filterpy's among them), and the C library brings its own `sin` and `atan2`.
A seeded run is the same to the bit wherever these are the same; where one differs, the closed loop rounds
differently from the first tick it matters and the flight drifts apart (docs/fast-core.md, "Same seed, same
result: on which machines"). Each run records the platform it ran on, so that runs compared one by one can
be checked to come from one platform.
"""

from __future__ import annotations

import ctypes
import functools
import platform
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

# OpenBLAS's `get_corename` under the names numpy's wheels give it (64-bit integers, then 32) and its own
CORENAME_FUNCTIONS = (
    "scipy_openblas_get_corename64_",
    "scipy_openblas_get_corename",
    "openblas_get_corename",
)


@dataclass(frozen=True)
class NumericPlatform:
    """numpy_version; numpy_simd: the SIMD targets numpy dispatches to in this process (its CPU's, less any
    that NPY_DISABLE_CPU_FEATURES turned off); blas_core: the kernel OpenBLAS chose ("SkylakeX", "Haswell";
    OPENBLAS_CORETYPE overrides it), None when it cannot be asked; libc: the C library and its version;
    machine: the CPU architecture."""

    numpy_version: str
    numpy_simd: tuple[str, ...]
    blas_core: str | None
    libc: str
    machine: str

    def to_json(self) -> dict[str, Any]:
        return {
            "numpy_version": self.numpy_version,
            "numpy_simd": list(self.numpy_simd),
            "blas_core": self.blas_core,
            "libc": self.libc,
            "machine": self.machine,
        }

    @classmethod
    def from_json(cls, doc: dict[str, Any]) -> NumericPlatform:
        """The platform a run document recorded; ValueError when the document does not hold one."""
        try:
            return cls(
                numpy_version=str(doc["numpy_version"]),
                numpy_simd=tuple(str(s) for s in doc["numpy_simd"]),
                blas_core=None if doc["blas_core"] is None else str(doc["blas_core"]),
                libc=str(doc["libc"]),
                machine=str(doc["machine"]),
            )
        except (KeyError, TypeError) as exc:
            raise ValueError(f"not a numeric platform: {doc!r}") from exc


@functools.cache
def numeric_platform() -> NumericPlatform:
    """This process's numeric platform (it cannot change once numpy is loaded)."""
    libc_name, libc_version = platform.libc_ver()
    return NumericPlatform(
        numpy_version=np.__version__,
        numpy_simd=_numpy_simd(),
        blas_core=_openblas_core(),
        libc=f"{libc_name} {libc_version}".strip() or "unknown",
        machine=platform.machine(),
    )


def _numpy_simd() -> tuple[str, ...]:
    """The dispatch targets numpy uses here (the tables `np.show_runtime` prints)."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    return tuple(target for target in __cpu_dispatch__ if __cpu_features__.get(target, False))


def _openblas_core() -> str | None:
    """The kernel of the OpenBLAS that numpy's wheel carries (its functions carry the wheel's prefix and
    suffix), asked through its own `get_corename`; None for another BLAS or a build without the call."""
    libs = Path(np.__file__).resolve().parent.parent / "numpy.libs"
    for path in sorted(libs.glob("lib*openblas*.so*")):
        try:
            lib = ctypes.CDLL(str(path))
        except OSError:
            continue
        for name in CORENAME_FUNCTIONS:
            function = getattr(lib, name, None)
            if function is not None:
                function.restype = ctypes.c_char_p
                core = function()
                return core.decode() if core else None
    return None
