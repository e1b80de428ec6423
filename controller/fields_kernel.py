"""The external inputs of fields.py (eqs. 10-15) as one compiled kernel (numba).

`fields.external_inputs` is the readable numpy form and the reference; `external_inputs_compiled` here takes
the same arguments, returns the same `ExternalInputs`, and computes every term in one pass over the horizon
steps without numpy's per-call overhead (about 40 small array operations per call there). The arithmetic is
written in the reference's order, term by term, so the two agree to round-off:
tests/controller/test_fields_kernel.py checks them on recorded flights. Compiled code is cached on disk
(`cache=True`): only the first start compiles.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from controller.fields import ExternalInputs, FieldParams, FieldTerms, ObstacleSet, TeammatePaths
from controller.kernel_args import kernel_array

HALF_PI = 0.5 * np.pi
TWO_PI = 2.0 * np.pi
TERMS = ("total", "tracking", "teammates", "obstacles", "person", "approach")

# Indices into the parameter vector handed to the kernel (`param_vector`).
(
    P_GAIN,
    P_F_MAX,
    P_FREEZE,
    P_TRACKING_C,
    P_TRACKING_MIN_FRACTION,
    P_TRACKING_MAX,
    P_TEAMMATE_D_MIN,
    P_TEAMMATE_PEAK,
    P_OBSTACLE_D_MIN,
    P_OBSTACLE_D_MAX,
    P_OBSTACLE_PEAK,
    P_OBSTACLE_BRAKE,
    P_OBSTACLE_BRAKE_MARGIN_MAX,
    P_OBSTACLE_SLIDE,
    P_SLIDE_MAX,
    P_PERSON_D_MIN_FRACTION,
    P_PERSON_D_MAX_FRACTION,
    P_PERSON_PEAK,
    P_APPROACH_RANGE,
    P_APPROACH_ANGLE,
    P_APPROACH_MAX,
    P_DQMPC_D_MIN,
    P_DQMPC_D_MAX,
) = range(23)


# The parameter vectors made so far, by the id of their FieldParams (kept here, so the id stays theirs).
_PARAM_VECTORS: dict[int, tuple[FieldParams, np.ndarray]] = {}


def param_vector(params: FieldParams) -> np.ndarray:
    """(23,) the kernel's parameters (indices P_*), made once per FieldParams object: a controller hands the
    same object every tick, and looking it up by value (functools.lru_cache) hashes its 30 fields, 2 us."""
    made = _PARAM_VECTORS.get(id(params))
    if made is not None and made[0] is params:
        return made[1]
    if len(_PARAM_VECTORS) >= 16:
        _PARAM_VECTORS.clear()
    vector = _params_as_vector(params)
    _PARAM_VECTORS[id(params)] = (params, vector)
    return vector


def _params_as_vector(params: FieldParams) -> np.ndarray:
    p = params
    return np.array(
        [
            p.gain,
            p.f_max_mps2,
            p.freeze_fraction,
            p.tracking_c,
            p.tracking_min_fraction,
            p.tracking_max_mps2,
            p.teammate_d_min_m,
            p.teammate_peak_mps2,
            p.obstacle_d_min_m,
            p.obstacle_d_max_m,
            p.obstacle_peak_mps2,
            p.obstacle_brake_mps2,
            p.obstacle_brake_margin_max_m,
            p.obstacle_slide,
            p.slide_max_mps2,
            p.person_d_min_fraction,
            p.person_d_max_fraction,
            p.person_peak_mps2,
            p.approach_range_m,
            p.approach_angle_rad,
            p.approach_max_mps2,
            p.dqmpc_d_min_m,
            p.dqmpc_d_max_m,
        ]
    )


# ------------------------------------------------------------------------------------- scalar helpers
@numba.njit(cache=True, inline="always")
def _magnitude(d, d_min, d_max, gain, freeze):  # pragma: no cover - compiled
    """fields.cotangential_magnitude for scalars (d_min < d_max)."""
    span = d_max - d_min
    z0 = HALF_PI * freeze
    frac = (d - d_min) / span
    if frac < 0.0:
        frac = 0.0
    elif frac > 1.0:
        frac = 1.0
    w = (HALF_PI - z0) * (1.0 - frac)
    w2 = w * w
    if w < 0.05:
        shape = w * w2 * (1.0 / 3.0 + w2 * (2.0 / 15.0 + w2 * 17.0 / 315.0))
    else:
        shape = math.tan(w) - w
    return (gain * HALF_PI) / span * shape


@numba.njit(cache=True, inline="always")
def _peak_gain(peak, d_min, d_max, freeze):  # pragma: no cover - compiled
    z0 = HALF_PI * freeze
    return peak * (d_max - d_min) / (HALF_PI * (1.0 / math.tan(z0) + z0 - HALF_PI))


@numba.njit(cache=True, inline="always")
def _safe(d):  # pragma: no cover - compiled
    """The divisor fields.py uses for a norm: itself above 1e-9, else inf (NaN stays NaN's inf)."""
    return d if d > 1e-9 else np.inf


@numba.njit(cache=True, inline="always")
def _wrap(angle):  # pragma: no cover - compiled
    return (angle + np.pi) % TWO_PI - np.pi


@numba.njit(cache=True)
def _clamp_rows(v, limit):  # pragma: no cover - compiled
    """fields.clamp_norm in place on (N, 2)."""
    for n in range(v.shape[0]):
        norm = math.sqrt(v[n, 0] * v[n, 0] + v[n, 1] * v[n, 1])
        if norm != norm:
            scale = np.nan
        else:
            scale = min(1.0, limit / max(norm, 1e-300))
        v[n, 0] = v[n, 0] * scale
        v[n, 1] = v[n, 1] * scale


# ------------------------------------------------------------------------------------------- the kernel
@numba.njit(cache=True)
def _kernel(
    own,
    own_vel,
    has_vel,
    person_xy,
    mate_pos,
    mate_ids,
    mate_in_formation,
    mate_d_max,
    centers,
    radii,
    heights,
    team_size,
    d_des,
    prm,
    use_tracking,
    use_teammates,
    use_obstacles,
    use_person,
    use_approach,
    dqmpc,
    own_id,
    in_formation,
    out,
):  # pragma: no cover - compiled; tested against fields.external_inputs
    """Write out[k, n, :2] for the terms in TERMS order (out zeroed by the caller); return the fault flag.

    own (N+1, 3), own_vel (N+1, 3) (read when has_vel), person_xy (N+1, 2), mate_pos (J, N+1, 3),
    mate_ids (J,), mate_in_formation (J,), mate_d_max (J,), centers (M, 2), radii (M,), heights (M,),
    prm: `param_vector`.
    """
    steps = own.shape[0]
    n_mates = mate_pos.shape[0]
    n_obs = centers.shape[0]
    freeze = prm[P_FREEZE]
    rel = np.empty((steps, 2))
    rho = np.empty(steps)
    tangent = np.empty((steps, 2))
    for n in range(steps):
        rel[n, 0] = own[n, 0] - person_xy[n, 0]
        rel[n, 1] = own[n, 1] - person_xy[n, 1]
        rho[n] = math.sqrt(rel[n, 0] * rel[n, 0] + rel[n, 1] * rel[n, 1])
        safe = _safe(rho[n])
        tangent[n, 0] = -rel[n, 1] / safe
        tangent[n, 1] = rel[n, 0] / safe
    tracking = out[1]
    teammate = out[2]
    obstacle = out[3]
    person = out[4]
    approach = out[5]

    # --- active tracking (eqs. 10-11), then its own clamp
    any_in = False
    for j in range(n_mates):
        any_in = any_in or mate_in_formation[j]
    if use_tracking and in_formation and n_mates > 0 and any_in and team_size >= 2:
        d_max = TWO_PI / team_size
        d_min = prm[P_TRACKING_MIN_FRACTION] * d_max
        gamma = np.empty(steps)
        for n in range(steps):
            gamma[n] = math.atan2(rel[n, 1], rel[n, 0])
        summed = np.zeros(steps)
        signed = np.empty(steps)
        for j in range(n_mates):
            if not mate_in_formation[j]:
                continue
            within = False
            for n in range(steps):
                gj = math.atan2(mate_pos[j, n, 1] - person_xy[n, 1], mate_pos[j, n, 0] - person_xy[n, 0])
                signed[n] = _wrap(gamma[n] - gj)
                within = within or abs(signed[n]) < d_max
            if not within:
                continue
            for n in range(steps):
                mag = _magnitude(abs(signed[n]), d_min, d_max, prm[P_GAIN], freeze)
                if signed[n] > 0.0:
                    side = 1.0
                elif signed[n] < 0.0:
                    side = -1.0
                elif signed[n] == 0.0:
                    side = -1.0 if own_id < mate_ids[j] else 1.0
                else:
                    side = signed[n]  # NaN, as np.sign
                summed[n] += mag * side
        for n in range(steps):
            scalar = (abs(d_des - rho[n]) + prm[P_TRACKING_C]) * summed[n]
            tracking[n, 0] = scalar * tangent[n, 0]
            tracking[n, 1] = scalar * tangent[n, 1]
        _clamp_rows(tracking, prm[P_TRACKING_MAX])

    # --- teammates as dynamic obstacles (eqs. 12, 15)
    if use_teammates and n_mates > 0:
        if dqmpc:
            d_min = prm[P_DQMPC_D_MIN]
        else:
            d_min = prm[P_TEAMMATE_D_MIN]
        for j in range(n_mates):
            if dqmpc:
                d_max = prm[P_DQMPC_D_MAX]
            else:
                d_max = max(mate_d_max[j], d_min + 1e-3)
            within = False
            for n in range(steps):
                dx = own[n, 0] - mate_pos[j, n, 0]
                dy = own[n, 1] - mate_pos[j, n, 1]
                within = within or math.sqrt(dx * dx + dy * dy) < d_max
            if not within:
                continue
            tie = -1.0 if own_id < mate_ids[j] else 1.0
            gain = _peak_gain(prm[P_TEAMMATE_PEAK], d_min, d_max, freeze)
            for n in range(steps):
                dx = own[n, 0] - mate_pos[j, n, 0]
                dy = own[n, 1] - mate_pos[j, n, 1]
                dist = math.sqrt(dx * dx + dy * dy)
                mag = _magnitude(dist, d_min, d_max, gain, freeze)
                if dist <= 1e-9:
                    ux, uy = tie, 0.0
                else:
                    safe = _safe(dist)
                    ux, uy = dx / safe, dy / safe
                teammate[n, 0] += mag * ux
                teammate[n, 1] += mag * uy

    # --- static and virtual obstacles (eq. 13) with the braking margin and the slide; approach angle
    if (use_obstacles or use_approach) and n_obs > 0:
        if dqmpc:
            d_min, d_max = prm[P_DQMPC_D_MIN], prm[P_DQMPC_D_MAX]
        else:
            d_min, d_max = prm[P_OBSTACLE_D_MIN], prm[P_OBSTACLE_D_MAX]
        surface = np.empty((n_obs, steps))
        margin = np.zeros((n_obs, steps))
        below = np.empty((n_obs, steps), dtype=np.bool_)
        any_obstacle = False
        any_near = False
        brake = prm[P_OBSTACLE_BRAKE]
        for m in range(n_obs):
            for n in range(steps):
                dx = own[n, 0] - centers[m, 0]
                dy = own[n, 1] - centers[m, 1]
                dist = math.sqrt(dx * dx + dy * dy)
                surface[m, n] = dist - radii[m]
                if has_vel and not dqmpc:
                    along = (dx * own_vel[n, 0] + dy * own_vel[n, 1]) / _safe(dist)
                    closing = max(-along, 0.0)
                    if along != along:
                        closing = np.nan
                    margin[m, n] = min(closing * closing / (2.0 * brake), prm[P_OBSTACLE_BRAKE_MARGIN_MAX])
                    if closing != closing:
                        margin[m, n] = np.nan
                below[m, n] = own[n, 2] < heights[m] + d_min
                any_obstacle = any_obstacle or (below[m, n] and surface[m, n] - margin[m, n] < d_max)
                any_near = any_near or (below[m, n] and surface[m, n] < prm[P_APPROACH_RANGE])
        if use_obstacles and any_obstacle:
            gain = _peak_gain(prm[P_OBSTACLE_PEAK], d_min, d_max, freeze)
            mags = np.zeros((n_obs, steps))
            units = np.empty((n_obs, steps, 2))
            any_mag = False
            for m in range(n_obs):
                for n in range(steps):
                    dx = own[n, 0] - centers[m, 0]
                    dy = own[n, 1] - centers[m, 1]
                    d = surface[m, n] + radii[m]
                    if d <= 1e-9:
                        units[m, n, 0], units[m, n, 1] = 1.0, 0.0
                    else:
                        safe = _safe(d)
                        units[m, n, 0], units[m, n, 1] = dx / safe, dy / safe
                    if below[m, n]:
                        b = _magnitude(surface[m, n] - margin[m, n], d_min, d_max, gain, freeze)
                        mags[m, n] = _magnitude(surface[m, n], d_min, d_max, gain, freeze)
                        any_mag = any_mag or mags[m, n] > 0.0
                    else:
                        b = 0.0
                    obstacle[n, 0] += b * units[m, n, 0]
                    obstacle[n, 1] += b * units[m, n, 1]
            if prm[P_OBSTACLE_SLIDE] > 0.0 and any_mag:
                person_d_min = prm[P_PERSON_D_MIN_FRACTION] * d_des
                for n in range(steps):
                    slide = 0.0
                    for m in range(n_obs):
                        blocked = abs(units[m, n, 0] * tangent[n, 0] + units[m, n, 1] * tangent[n, 1])
                        cx = centers[m, 0] - person_xy[n, 0]
                        cy = centers[m, 1] - person_xy[n, 1]
                        rho_m = math.sqrt(cx * cx + cy * cy)
                        inner_open = rho_m - radii[m] - d_min > person_d_min
                        side = -1.0 if (d_des < rho_m and inner_open) else 1.0
                        slide += prm[P_OBSTACLE_SLIDE] * mags[m, n] * blocked * side
                    slide = min(max(slide, -prm[P_SLIDE_MAX]), prm[P_SLIDE_MAX]) if slide == slide else slide
                    safe = _safe(rho[n])
                    obstacle[n, 0] = obstacle[n, 0] + slide * (rel[n, 0] / safe)
                    obstacle[n, 1] = obstacle[n, 1] + slide * (rel[n, 1] / safe)
        if use_approach and in_formation and any_near:
            for n in range(steps):
                gamma = math.atan2(rel[n, 1], rel[n, 0])
                scalar = 0.0
                for m in range(n_obs):
                    if not (below[m, n] and surface[m, n] < prm[P_APPROACH_RANGE]):
                        continue
                    cx = centers[m, 0] - person_xy[n, 0]
                    cy = centers[m, 1] - person_xy[n, 1]
                    rho_m = math.sqrt(cx * cx + cy * cy)
                    if not (rho_m + radii[m] + prm[P_OBSTACLE_D_MIN] < rho[n]):
                        continue
                    signed = _wrap(gamma - math.atan2(cy, cx))
                    mag = _magnitude(abs(signed), 0.0, prm[P_APPROACH_ANGLE], prm[P_GAIN], freeze)
                    ramp = 1.0 - surface[m, n] / prm[P_APPROACH_RANGE]
                    ramp = min(max(ramp, 0.0), 1.0) if ramp == ramp else ramp
                    scalar += mag * ramp * (1.0 if signed >= 0.0 else -1.0)
                approach[n, 0] = scalar * tangent[n, 0]
                approach[n, 1] = scalar * tangent[n, 1]
            _clamp_rows(approach, prm[P_APPROACH_MAX])

    # --- the person as an obstacle, never pushing into a trunk
    if use_person:
        lo = prm[P_PERSON_D_MIN_FRACTION] * d_des
        hi = prm[P_PERSON_D_MAX_FRACTION] * d_des
        any_close = False
        for n in range(steps):
            any_close = any_close or rho[n] < hi
        if hi > lo and any_close:
            gain = _peak_gain(prm[P_PERSON_PEAK], lo, hi, freeze)
            nonzero = False
            for n in range(steps):
                mag = _magnitude(rho[n], lo, hi, gain, freeze)
                if rho[n] <= 1e-9:
                    ux, uy = 1.0, 0.0
                else:
                    safe = _safe(rho[n])
                    ux, uy = rel[n, 0] / safe, rel[n, 1] / safe
                person[n, 0] = mag * ux
                person[n, 1] = mag * uy
                nonzero = nonzero or person[n, 0] != 0.0 or person[n, 1] != 0.0
            if n_obs > 0 and nonzero:
                reach = prm[P_OBSTACLE_D_MIN]
                for m in range(n_obs):
                    for n in range(steps):
                        tx = centers[m, 0] - own[n, 0]
                        ty = centers[m, 1] - own[n, 1]
                        dist = math.sqrt(tx * tx + ty * ty)
                        if not (dist - radii[m] < reach and own[n, 2] < heights[m]):
                            continue
                        safe = _safe(dist)
                        tx, ty = tx / safe, ty / safe
                        push = person[n, 0] * tx + person[n, 1] * ty
                        if push > 0.0:
                            person[n, 0] = person[n, 0] - push * tx
                            person[n, 1] = person[n, 1] - push * ty

    # --- the clamped total (eq. 14)
    total = out[0]
    finite = True
    for n in range(steps):
        for a in range(2):
            total[n, a] = tracking[n, a] + teammate[n, a] + obstacle[n, a] + person[n, a] + approach[n, a]
    _clamp_rows(total, prm[P_F_MAX])
    for n in range(steps):
        finite = finite and math.isfinite(total[n, 0]) and math.isfinite(total[n, 1])
    if not finite:
        total[:, :] = 0.0
    return not finite


def external_inputs_compiled(
    *,
    own_positions_m: np.ndarray,
    person_position_m: np.ndarray,
    teammates: TeammatePaths,
    obstacles: ObstacleSet,
    team_size: int,
    d_des_m: float,
    params: FieldParams,
    terms: FieldTerms,
    own_id: int = 0,
    in_formation: bool = True,
    own_velocities_mps: np.ndarray | None = None,
) -> ExternalInputs:
    """fields.external_inputs, compiled: same arguments, same result (to round-off)."""
    own = np.asarray(own_positions_m, dtype=float)  # input_terms hands it on as the kernel takes it
    steps = own.shape[0]
    person = np.asarray(person_position_m, dtype=float)
    if person.shape == (steps, 3):
        person_xy = person[:, :2].copy()
    else:
        person_xy = np.ascontiguousarray(np.broadcast_to(person[..., :2], (steps, 2)))
    out, fault = input_terms(
        own_positions_m=own,
        own_velocities_mps=own_velocities_mps,
        person_xy_m=person_xy,
        teammates=teammates,
        obstacles=obstacles,
        team_size=team_size,
        d_des_m=d_des_m,
        params=params,
        terms=terms,
        own_id=own_id,
        in_formation=in_formation,
    )
    return ExternalInputs(
        total=out[0],
        tracking=out[1],
        teammates=out[2],
        obstacles=out[3],
        person=out[4],
        approach=out[5],
        fault=fault,
    )


def input_terms(
    *,
    own_positions_m: np.ndarray,
    own_velocities_mps: np.ndarray | None,
    person_xy_m: np.ndarray,
    teammates: TeammatePaths,
    obstacles: ObstacleSet,
    team_size: int,
    d_des_m: float,
    params: FieldParams,
    terms: FieldTerms,
    own_id: int,
    in_formation: bool,
) -> tuple[np.ndarray, bool]:
    """The kernel on a tick's arrays, for the person's horizontal position at each step, person_xy_m (N+1, 2)
    (contiguous): (6, N+1, 3) in TERMS order (the clamped total first) and the fault flag. What a controller
    tick calls (it takes the total), without building the terms' message."""
    own = kernel_array(own_positions_m, float)
    has_vel = own_velocities_mps is not None
    own_vel = kernel_array(own_velocities_mps, float) if has_vel else own
    out = np.zeros((6, own.shape[0], 3))
    centers, radii, heights = obstacles.kernel_arrays()
    fault = _kernel(
        own,
        own_vel,
        has_vel,
        kernel_array(person_xy_m, float),
        kernel_array(teammates.positions_m, float),
        kernel_array(teammates.vehicle_ids, np.int64),
        kernel_array(teammates.in_formation, np.bool_),
        kernel_array(teammates.d_max_m, float),
        centers,
        radii,
        heights,
        int(team_size),
        float(d_des_m),
        param_vector(params),
        terms.tracking,
        terms.teammates,
        terms.obstacles,
        terms.person,
        terms.approach,
        terms.dqmpc_thresholds,
        int(own_id),
        bool(in_formation),
        out,
    )
    return out, bool(fault)
