"""Session set-up shared by every test directory."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels() -> None:
    """Load (or, on a fresh install, compile) the controller's numba kernels before the first test, so that no
    test with a wall-clock time-out pays for a compile (`make test` compiles them before pytest starts)."""
    from controller.warmup import warm_up

    warm_up()
