"""`skyring bench sim`: how fast the embedded simulator runs 16 MAVs at the paper's 100 Hz control rate.

Target (issue 3): at least 5x real time in one process on one core. Prints the real-time factor, the agent
tick's median and p99, and where a control period's time goes (agents vs world and bookkeeping).
"""

from __future__ import annotations

import time

from server.simulation import SimConfig, run_simulation

TARGET_REALTIME_FACTOR = 5.0


def run(*, repeats: int) -> None:
    """Simulate 16 MAVs at 100 Hz for repeats / 20 simulated seconds (200 -> 10 s) after a 10 s warm-up."""
    measured_s = max(repeats / 20.0, 1.0)
    config = SimConfig(vehicles=16, duration_s=10.0 + measured_s, warmup_s=10.0, rate_hz=100.0, seed=1,
                       trees="paper", person="paper", method="active")
    wall0 = time.perf_counter()
    report = run_simulation(config)
    wall_s = time.perf_counter() - wall0
    m = report.metrics
    tick = m["tick_ms"]
    rtf = m["realtime_factor"]
    agents_s = (tick["median"] or 0.0) * 1e-3 * 16 * 100
    print(f"sim: 16 MAVs, 100 Hz control, paper world, {config.duration_s:g} s simulated in {wall_s:.1f} s")
    print(f"  real-time factor      {rtf:.2f}x  (target >= {TARGET_REALTIME_FACTOR:g}x: "
          f"{'met' if rtf >= TARGET_REALTIME_FACTOR else 'NOT met'})")
    print(f"  agent tick            median {tick['median']:.3f} ms   p99 {tick['p99']:.3f} ms")
    print(f"  agents per sim second {agents_s:.2f} s of CPU (16 x 100 ticks at the median)")
