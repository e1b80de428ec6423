"""`skyring bench protocol`: how long the paper's full experiment protocol takes, at 100 Hz and at 10 Hz.

Target (docs/fast-core.md): the whole protocol (306 runs, 43,020 simulated seconds) at the paper's 100 Hz in
at most 30 minutes on 2 cores. Running it takes more than an hour, so the bench samples it: one run of every
condition (30 of them) for a few tens of simulated seconds, timed by this process's CPU time, split into its
take-off (the first TAKEOFF_S seconds, which every run flies) and the formation flight after it, which costs
more per second. A protocol run of d seconds then costs the take-off plus d - TAKEOFF_S seconds at the
sample's later rate; summed over the protocol and halved, that is the time on 2 cores with the local pool's
ideal packing of 306 independent runs on two workers. Checked against a real sweep: the commloss family
(21 runs of 120 s, 8 MAVs) took 6.0 minutes on 2 cores at 100 Hz, estimated 6.2.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

from server.lab import experiments as exp
from server.lab.simulation import SimConfig, run_simulation

TARGET_MINUTES_ON_2_CORES = 30.0
CORES = 2
RATES_HZ = (exp.PAPER_RATE_HZ, exp.QUICK_RATE_HZ)
TAKEOFF_S = 10.0


@dataclass(frozen=True)
class SampledCost:
    """What one condition's sample cost: takeoff_cpu_s, CPU seconds of its first TAKEOFF_S simulated
    seconds; cpu_per_simulated_s, CPU seconds per simulated second after them."""

    takeoff_cpu_s: float
    cpu_per_simulated_s: float


def protocol_cpu_s(protocol: exp.Protocol, costs: Sequence[SampledCost]) -> float:
    """CPU seconds of the whole protocol from one sampled cost per condition (in the protocol's order):
    every condition runs every duration of the protocol, each run a take-off and then formation flight."""
    if len(costs) != len(protocol.conditions):
        raise ValueError(f"one cost per condition: {len(protocol.conditions)}, got {len(costs)}")
    runs, flight_s = protocol.runs, sum(d - TAKEOFF_S for d in protocol.durations_s)
    return sum(c.takeoff_cpu_s * runs + c.cpu_per_simulated_s * flight_s for c in costs)


def _sample(family: str, condition: exp.Condition, rate_hz: float, sample_s: float) -> SampledCost:
    """One run of the condition, sample_s simulated seconds long, in this process, timed by CPU time."""
    sample = exp.Protocol(family, (condition,), (sample_s,), rate_hz)
    (spec,) = exp.plan_runs([sample], base_seed=0)
    marks: dict[float, float] = {}  # simulated s -> CPU s, about once a simulated second

    def mark(t_s: float) -> None:
        marks[t_s] = time.process_time()

    start = time.process_time()
    run_simulation(SimConfig(**spec.config_fields()), progress=mark)
    end = time.process_time()
    takeoff_end = min(t for t in marks if t >= TAKEOFF_S)
    return SampledCost(
        takeoff_cpu_s=(marks[takeoff_end] - start) * TAKEOFF_S / takeoff_end,
        cpu_per_simulated_s=(end - marks[takeoff_end]) / (sample_s - takeoff_end),
    )


def run(*, repeats: int) -> None:
    """Sample every condition for max(2.5 TAKEOFF_S, 0.15 repeats) simulated seconds at each rate."""
    sample_s = max(2.5 * TAKEOFF_S, 0.15 * repeats)
    protocols = [exp.paper_protocol(f) for f in exp.FAMILIES]
    print(
        f"protocol: the paper's {sum(p.runs * len(p.conditions) for p in protocols)} runs, estimated from "
        f"one {sample_s:g}-s run of each condition (CPU time of one process); "
        f"target <= {TARGET_MINUTES_ON_2_CORES:g} min on {CORES} cores at {exp.PAPER_RATE_HZ:g} Hz"
    )
    print(
        f"  {'rate':>8} "
        + " ".join(f"{f:>12}" for f in exp.FAMILIES)
        + f" {'CPU min':>9} {f'on {CORES} cores':>11}  target"
    )
    for rate_hz in RATES_HZ:
        family_s = []
        for protocol in protocols:
            costs = [_sample(protocol.family, c, rate_hz, sample_s) for c in protocol.conditions]
            family_s.append(protocol_cpu_s(protocol, costs))
        total_min = sum(family_s) / 60.0
        wall_min = total_min / CORES
        verdict = (
            ("met" if wall_min <= TARGET_MINUTES_ON_2_CORES else "NOT met")
            if rate_hz == exp.PAPER_RATE_HZ
            else ""
        )
        print(
            f"  {rate_hz:>5g} Hz "
            + " ".join(f"{s / 60.0:>8.1f} min" for s in family_s)
            + f" {total_min:>9.1f} {wall_min:>7.1f} min  {verdict}"
        )
