"""Run in a fresh process by tests/controller/test_warmup.py: `warm_up()` for one method (as an agent or the
station does before its first tick), with the default parameters ("default"), or with the trackers' compiled
Kalman filter ("compiled-kf", which the flights then fly too), then simulated flights, each given as
`SimConfig` keyword arguments; print (JSON) which compiled kernels gained a specialization during the
flights, and how often the kernels on the rarer paths were called, so that the test can tell an empty answer
from a flight that never went there.

    python -P kernel_signature_probe.py METHOD|default|compiled-kf FLIGHTS_JSON
"""

from __future__ import annotations

import json
import sys
from collections import Counter

from numba.core.registry import CPUDispatcher

from controller import kalman, mpc
from controller.params import ControllerParams, Method
from controller.tracker import TrackerParams
from controller.warmup import warm_up
from server.lab.simulation import SimConfig, run_simulation

# Kernels on the less common paths, called through these names in their modules: the MPC's, and the compiled
# Kalman filter's (not the default filter).
WATCHED = {
    mpc: ("solve_with_planes", "roll_out_variables", "checked_planes", "half_plane_rows"),
    kalman: ("predicted", "updated"),
}
COMPILED_KF = TrackerParams(kalman_filter="compiled")


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


def _counting(module, name: str, calls: Counter):
    kernel = getattr(module, name)

    def call(*args):
        calls[name] += 1
        return kernel(*args)

    return call


def main() -> None:
    warm_up_for, flights = sys.argv[1], json.loads(sys.argv[2])
    compiled_kf = warm_up_for == "compiled-kf"
    if compiled_kf:
        warm_up(ControllerParams(tracker=COMPILED_KF))
    else:
        warm_up(None if warm_up_for == "default" else ControllerParams(method=Method(warm_up_for)))
    # scanned now, as well as after the flights: wrapping the watched names below hides a kernel that lives
    # only in its own module (kalman's) from a later scan; modules the flights import show in the later one
    warmed = _dispatchers()
    before = {kernel: len(kernel.signatures) for kernel in warmed}
    calls: Counter = Counter()
    for module, names in WATCHED.items():
        for name in names:
            setattr(module, name, _counting(module, name, calls))
    for flight in flights:
        config = SimConfig(**flight)
        params = ControllerParams(method=config.method, tracker=COMPILED_KF) if compiled_kf else None
        run_simulation(config, controller_params=params)
    gained = {
        name: [str(sig) for sig in kernel.signatures[before.get(kernel, 0) :]]
        for kernel, name in {**_dispatchers(), **warmed}.items()
        if len(kernel.signatures) > before.get(kernel, 0)
    }
    print(json.dumps({"gained": gained, "calls": dict(calls)}))


if __name__ == "__main__":
    main()
