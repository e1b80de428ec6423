"""reference.py's start state, terminal reference and way-point for a formation tick, as compiled kernels.

`start_and_horizon`: where the plan starts (`reference.initial_state` on `reference.plan_state_at`: the
previous plan's state at `now` on a leash to the measurement) and our previous plan on the horizon
(`teammates.align_rows`, moved to begin there: the path the external inputs and the separation rows are
computed on), in one call. `aim`: the terminal reference (`reference.terminal_reference` with
`reference.input_displacement`'s pass-through) clipped into the arena. `waypoint`: the set-point
(`reference.plan_state_at` and `reference.plan_acceleration_at` a few steps ahead) and whether it is finite.

All keep numpy's operations in numpy's order, its products by `np.dot` (the BLAS call numpy's @ makes) and
its clip by `scalar_kernels`: the same bits as formation.py's numpy form
(tests/controller/test_formation_compiled.py; docs/fast-core.md, "Bits in compiled code"). The bearing stays
numpy's `arctan2` (numba's differs in the last bit). Compiled code is cached on disk (`cache=True`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from controller.scalar_kernels import maximum, minimum
from controller.teammates import align_rows


@numba.njit(cache=True, inline="always")
def _leashed(measured, reference, leash, out):  # pragma: no cover - compiled
    """out (3,) = `reference.leashed(measured, reference, leash)`."""
    gap = reference - measured
    dist = math.sqrt(np.dot(gap, gap))
    if dist <= leash:
        out[:] = reference
    else:
        scale = leash / dist
        for i in range(3):
            out[i] = measured[i] + gap[i] * scale


@numba.njit(cache=True)
def start_and_horizon(
    now_s,
    has_plan,
    plan,  # (2, L, 3): the previous plan's positions (m) and velocities (m/s), `align_rows`' table
    lengths,  # (2,) int64: its valid length, twice
    stamps,  # (2,) s: its stamp, twice
    plan_dts,  # (2,) s: its step, twice
    rows,  # (2,) int64: 0, 1
    measured_p,  # (3,) m
    measured_v,  # (3,) m/s
    leash_p,
    leash_v,
    dt,
    start,  # out (2, 3): the start position and velocity
    horizon,  # out (2, S, 3): our previous plan's positions and velocities at now_s + n dt, moved
):  # pragma: no cover - compiled; tested against formation.py's numpy form
    """The start state (formation `_start_state` with a sane measurement and a finite now_s) and our
    previous plan on the horizon (`_own_horizon`) in one call; without a plan, a hover at the measurement."""
    steps = horizon.shape[1]
    length = lengths[0]
    elapsed = now_s - stamps[0]
    covered = has_plan and not (elapsed < 0.0 or elapsed > (length - 1) * plan_dts[0])
    if covered:
        # reference.plan_state_at
        last = length - 1
        k = min(max(elapsed / plan_dts[0], 0.0), float(last))
        lo = min(math.floor(k), last)
        hi = min(lo + 1, last)
        a = k - lo
        b = 1.0 - a
        ref = np.empty((2, 3))
        for w in range(2):
            for i in range(3):
                ref[w, i] = b * plan[w, lo, i] + a * plan[w, hi, i]
        _leashed(measured_p, ref[0], leash_p, start[0])
        _leashed(measured_v, ref[1], leash_v, start[1])
    else:
        start[0, :] = measured_p
        start[1, :] = measured_v
    if has_plan:
        align_rows(plan, lengths, stamps, plan_dts, rows, now_s, dt, False, horizon)
    else:
        for n in range(steps):
            horizon[0, n, :] = start[0]
            horizon[1, n, :] = start[1]
    # the plan moved to begin at the start position (a hover is there already); the velocities to begin at
    # the measured velocity
    for w in range(0 if has_plan else 1, 2):
        shift = np.empty(3)
        for i in range(3):
            shift[i] = (start[0, i] if w == 0 else measured_v[i]) - horizon[w, 0, i]
        for n in range(steps):
            for i in range(3):
                horizon[w, n, i] = horizon[w, n, i] + shift[i]


@numba.njit(cache=True)
def aim(
    start_p,  # (3,) m
    person_p,  # (3,) m
    person_v,  # (3,) m/s
    bearing,  # rad: reference.bearing_rad of start_p seen from person_p, or the preferred bearing
    d_des,
    h_des,
    horizon_s,
    predict,  # reference.ReferenceParams.predict_person
    pass_through,  # reference.ReferenceParams.pass_through
    weights,  # (N+1,) s^2: input_displacement's dt^2 (N - n + 1/2)
    inputs,  # (N+1, 3) m/s^2: the external inputs f(0..N)
    dt,
    lower,  # (3,) m: the arena's box
    upper,  # (3,) m
    out,  # out (2, 3): the terminal position (m) and velocity (m/s)
):  # pragma: no cover - compiled; tested against formation.py's numpy form
    """formation `_target` for formation flight: eq. 4's point d_des from the person (at the horizon end when
    predicting) along `bearing`, h_des above it, with the person's horizontal velocity; moved by what the
    inputs add over the horizon when passing through; the position clipped into the arena."""
    if predict:
        cx = person_p[0] + person_v[0] * horizon_s
        cy = person_p[1] + person_v[1] * horizon_s
        cz = person_p[2] + person_v[2] * horizon_s
    else:
        cx, cy, cz = person_p[0] + 0.0, person_p[1] + 0.0, person_p[2] + 0.0
    out[0, 0] = cx + d_des * math.cos(bearing)
    out[0, 1] = cy + d_des * math.sin(bearing)
    out[0, 2] = cz + h_des
    out[1, 0], out[1, 1], out[1, 2] = person_v[0], person_v[1], 0.0
    if pass_through:
        shift_p = np.dot(weights, inputs)
        for i in range(3):
            total = inputs[0, i]
            for n in range(1, inputs.shape[0]):
                total = total + inputs[n, i]
            out[0, i] = out[0, i] + shift_p[i]
            out[1, i] = out[1, i] + dt * total
    for i in range(3):
        out[0, i] = minimum(maximum(out[0, i], lower[i]), upper[i])


@numba.njit(cache=True)
def waypoint(
    positions,  # (L, 3) m: a plan's states x(0)..
    velocities,  # (L, 3) m/s
    elapsed_s,
    dt,
    position_out,  # out (3,) m
    velocity_out,  # out (3,) m/s
    acceleration_out,  # out (3,) m/s^2
):  # pragma: no cover - compiled; tested against formation.py's numpy form
    """formation `_waypoint`: the plan's position and velocity `elapsed_s` after x(0) (`plan_state_at`:
    interpolated, held at the last state) and its acceleration on the step that begins there
    (`plan_acceleration_at`: zero from the last state on); returns whether all nine numbers are finite."""
    last = positions.shape[0] - 1
    k = min(max(elapsed_s / dt, 0.0), float(last))
    lo = min(math.floor(k), last)
    hi = min(lo + 1, last)
    a = k - lo
    b = 1.0 - a
    step = math.floor(max(elapsed_s / dt, 0.0) + 1e-9)  # a whole step's time may land just below it
    finite = True
    for i in range(3):
        position_out[i] = b * positions[lo, i] + a * positions[hi, i]
        velocity_out[i] = b * velocities[lo, i] + a * velocities[hi, i]
        acceleration_out[i] = 0.0 if step >= last else (velocities[step + 1, i] - velocities[step, i]) / dt
        finite = finite and (
            math.isfinite(position_out[i])
            and math.isfinite(velocity_out[i])
            and math.isfinite(acceleration_out[i])
        )
    return finite
