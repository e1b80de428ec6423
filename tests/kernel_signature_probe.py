"""Run in a fresh process by tests/controller/test_warmup.py: `warm_up()` for one method (as an agent or the
station does before its first tick) or with the default parameters ("default"), then simulated flights, each
given as `SimConfig` keyword arguments; print (JSON) which compiled kernels gained a specialization during
the flights, and how often the kernels on the MPC's rarer paths were called, so that the test can tell an
empty answer from a flight that never went there.

    python -P kernel_signature_probe.py METHOD|default FLIGHTS_JSON
"""

from __future__ import annotations

import json
import sys
from collections import Counter

from numba.core.registry import CPUDispatcher

from controller import mpc
from controller.params import ControllerParams, Method
from controller.warmup import warm_up
from server.lab.simulation import SimConfig, run_simulation

# Kernels on the MPC's less common paths, called through these names in controller/mpc.py.
WATCHED = ("solve_with_planes", "roll_out_variables", "checked_planes", "half_plane_rows")


def _dispatchers() -> dict[CPUDispatcher, str]:
    """Every compiled kernel that a module of ours holds, by the first name it was found under."""
    found: dict[CPUDispatcher, str] = {}
    for name, module in sorted(sys.modules.items()):
        if name.split(".")[0] not in ("controller", "vehicles", "server"):
            continue
        for attr, value in vars(module).items():
            if isinstance(value, CPUDispatcher):
                found.setdefault(value, f"{name}.{attr}")
    return found


def _counting(name: str, calls: Counter):
    kernel = getattr(mpc, name)

    def call(*args):
        calls[name] += 1
        return kernel(*args)

    return call


def main() -> None:
    warm_up_for, flights = sys.argv[1], json.loads(sys.argv[2])
    warm_up(None if warm_up_for == "default" else ControllerParams(method=Method(warm_up_for)))
    before = {kernel: len(kernel.signatures) for kernel in _dispatchers()}
    calls: Counter = Counter()
    for name in WATCHED:
        setattr(mpc, name, _counting(name, calls))
    for flight in flights:
        run_simulation(SimConfig(**flight))
    gained = {
        name: [str(sig) for sig in kernel.signatures[before.get(kernel, 0) :]]
        for kernel, name in _dispatchers().items()
        if len(kernel.signatures) > before.get(kernel, 0)
    }
    print(json.dumps({"gained": gained, "calls": dict(calls)}))


if __name__ == "__main__":
    main()
