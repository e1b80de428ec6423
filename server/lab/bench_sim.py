"""`skyring bench sim`: how fast the embedded simulator runs 16 MAVs at the paper's 100 Hz control rate.

Target (docs/architecture.md#performance-targets): at least 10x real time in one process on one core. The
real-time factor is measured after a 10 s warm-up (takeoff), like the report's `realtime_factor`: world, 16
agents (tracker, controller), links and the runner's bookkeeping included. Beside the wall-clock factor the
bench prints the factor in CPU time of this process, which is what the wall-clock one would be on an otherwise
idle core (on a shared machine the wall clock also counts other processes' time). Four rows: the MPC solved
every control tick (the paper), the same with DAQP as the active-set step (`MpcParams.active_set`), the same
with the trackers' compiled Kalman filter (`TrackerParams.kalman_filter`; filterpy's is of record), and
solved at 10 Hz with the set-points following the latest plan in between (`--replan-rate 10`).
"""

from __future__ import annotations

import time

from controller.mpc import MpcParams
from controller.params import ControllerParams, Method
from controller.tracker import TrackerParams
from server.lab.simulation import SimConfig, run_simulation

TARGET_REALTIME_FACTOR = 10.0
WARMUP_S = 10.0


def run(*, repeats: int) -> None:
    """Simulate 16 MAVs at 100 Hz for repeats / 20 simulated seconds (200 -> 10 s) after the warm-up."""
    measured_s = max(repeats / 20.0, 2.0)
    print(
        f"sim: 16 MAVs, 100 Hz control, paper world (13 trees, walking person), {measured_s:g} s measured "
        f"after a {WARMUP_S:g} s warm-up; target >= {TARGET_REALTIME_FACTOR:g}x real time on one core"
    )
    print(
        f"  {'MPC solved':<24} {'real-time factor':>16} {'(CPU time)':>11} {'agent tick median':>18} "
        f"{'p99':>9}  target"
    )
    rows = (
        ("every tick (paper)", 0.0, "compiled", "filterpy"),
        ("every tick, DAQP", 0.0, "daqp", "filterpy"),
        ("every tick, compiled KF", 0.0, "compiled", "compiled"),
        ("at 10 Hz", 10.0, "compiled", "filterpy"),
    )
    for label, replan_hz, active_set, kalman_filter in rows:
        config = SimConfig(
            vehicles=16,
            duration_s=WARMUP_S + measured_s,
            warmup_s=WARMUP_S,
            rate_hz=100.0,
            seed=1,
            trees="paper",
            person="paper",
            method=Method.ACTIVE,
            replan_hz=replan_hz,
        )
        marks: list[tuple[float, float]] = []  # (simulated s, CPU s) at each progress call after warm-up
        m = run_simulation(
            config,
            progress=lambda t, marks=marks: marks.append((t, time.process_time())),
            controller_params=ControllerParams(
                mpc=MpcParams(active_set=active_set), tracker=TrackerParams(kalman_filter=kalman_filter)
            ),
        ).metrics
        end_cpu = time.process_time()
        rtf, tick = m["realtime_factor"], m["tick_ms"]
        cpu_rtf = (config.duration_s - marks[0][0]) / (end_cpu - marks[0][1]) if marks else float("nan")
        verdict = "met" if rtf >= TARGET_REALTIME_FACTOR else "NOT met"
        print(
            f"  {label:<24} {rtf:>15.2f}x {cpu_rtf:>10.2f}x {tick['median']:>15.3f} ms {tick['p99']:>6.2f} ms"
            f"  {verdict}"
        )
