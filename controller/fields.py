"""Potential fields: the cotangential magnitude function and every external input f(n) (paper Sec. III-E).

The non-convex constraints of the formation (angular spacing 2 pi / K about the person, distance to teammates,
trees, virtual obstacles and the person) enter the convex MPC as external accelerations f(n), one per horizon
step n = 0..N, computed here from positions only. Equation numbers are those of the published paper (RA-L
2019): eq. 10 (`act_force_mag`), 11 (`actforce`), 12 (`rep_dyn`), 13 (`rep_sta`), 14 (`clamping`), 15
(`guarantee`).

Every force is horizontal (z = 0), as in the authors' code. Positions are ENU metres; forces are m/s^2 because
they enter the dynamics as accelerations. Everything here is a pure function of its arguments.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from controller.angles import wrap_angle
from controller.kernel_args import kernel_array
from controller.messages import HorizonPlan, Obstacle, read_only

HALF_PI = 0.5 * np.pi
TWO_PI = 2.0 * np.pi
SANE_ABS = 1.0e6  # coordinates (m) or covariances (m^2) beyond this are garbage, not a place or a spread


@dataclass(frozen=True)
class FieldParams:
    """Gains and thresholds of the external inputs; every value's measured reason is in
    docs/method.md#external-inputs. Distances in m, angles in rad, forces in m/s^2 (accelerations).

    gain: G of the angular field; f_max_mps2: F_max, the clamp on the norm of the total (eq. 14);
    freeze_fraction: F's argument z starts at (pi/2) * freeze_fraction at d_min
        (docs/method.md#cotangential-field).
    tracking_c: c of eq. 10; tracking_min_fraction: the angular d_min as a fraction of d_max = 2 pi / K;
    tracking_max_mps2: clamp on the norm of the active-tracking sum (eq. 11).
    teammate_d_min_m: d_min of eq. 15; teammate_d_max_base_m: d_max of a fresh plan with zero covariances, to
        which `teammate_paths` adds both covariance radii (each at most covariance_radius_cap_m) and
        teammate_speed_mps times the plan's age beyond teammate_age_grace_s.
    teammate_peak_mps2, obstacle_peak_mps2, person_peak_mps2: each repulsion's value at (and below) its d_min.
    obstacle_d_min_m, obstacle_d_max_m: eq. 13's thresholds on the distance to a cylinder's surface, moved out
        by the braking distance v_close^2 / (2 obstacle_brake_mps2), at most obstacle_brake_margin_max_m.
    obstacle_slide, slide_max_mps2: gain and clamp of the radial slide round a trunk.
    person_d_min_fraction, person_d_max_fraction: the person's thresholds as fractions of d_des.
    approach_range_m, approach_angle_rad, approach_max_mps2: reach, angular d_max and clamp of the
        approach-angle input.
    dqmpc_d_min_m, dqmpc_d_max_m: the dqmpc baseline's repulsion thresholds.
    """

    gain: float = 50.0
    f_max_mps2: float = 8.0
    freeze_fraction: float = 0.2
    tracking_c: float = 1.0
    tracking_min_fraction: float = 0.7
    tracking_max_mps2: float = 1.0
    teammate_d_min_m: float = 1.5
    teammate_d_max_base_m: float = 2.0
    teammate_speed_mps: float = 5.0
    teammate_age_grace_s: float = 0.1
    teammate_peak_mps2: float = 8.0
    covariance_radius_cap_m: float = 5.0
    obstacle_d_min_m: float = 1.5
    obstacle_d_max_m: float = 3.0
    obstacle_peak_mps2: float = 8.0
    obstacle_brake_mps2: float = 2.0
    obstacle_brake_margin_max_m: float = 4.0
    obstacle_slide: float = 1.0
    slide_max_mps2: float = 2.0
    person_d_min_fraction: float = 7.0 / 8.0
    person_d_max_fraction: float = 1.0
    person_peak_mps2: float = 8.0
    approach_range_m: float = 3.0
    approach_angle_rad: float = 0.5
    approach_max_mps2: float = 1.0
    dqmpc_d_min_m: float = 1.0
    dqmpc_d_max_m: float = 4.0

    def teammate_d_max_head_m(self, own_cov_radius_m: float) -> float:
        """The part of eq. 15's d_max that is the same for every teammate (m): the base plus our own
        covariance radius, capped; each teammate's radius and age term are added to it."""
        return self.teammate_d_max_base_m + min(own_cov_radius_m, self.covariance_radius_cap_m)

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"FieldParams.{name} must be a finite number >= 0, got {value}")
        if not 0.0 < self.freeze_fraction < 1.0:
            raise ValueError("FieldParams.freeze_fraction must lie in (0, 1)")
        if not self.tracking_min_fraction < 1.0:
            raise ValueError("FieldParams.tracking_min_fraction must lie in [0, 1): d_min < 2 pi / K")
        if self.obstacle_d_min_m >= self.obstacle_d_max_m or self.dqmpc_d_min_m >= self.dqmpc_d_max_m:
            raise ValueError("FieldParams: every d_min must be below its d_max")
        if self.person_d_min_fraction >= self.person_d_max_fraction:
            raise ValueError("FieldParams: person_d_min_fraction must be below person_d_max_fraction")
        if self.approach_angle_rad <= 0.0:
            raise ValueError("FieldParams.approach_angle_rad must be > 0")
        if self.obstacle_brake_mps2 <= 0.0:
            raise ValueError("FieldParams.obstacle_brake_mps2 must be > 0")


@dataclass(frozen=True)
class FieldTerms:
    """Which external inputs a method uses (docs/method.md#baselines).

    active: every term. dqmpc: teammate and obstacle repulsion only, with its own thresholds. price: none
    inside the MPC (its repulsion is applied after the MPC, see baselines.py).
    """

    tracking: bool = True
    teammates: bool = True
    obstacles: bool = True
    person: bool = True
    approach: bool = True
    dqmpc_thresholds: bool = False

    @classmethod
    def for_method(cls, method: str) -> FieldTerms:
        """The terms of a method by name ("active", "dqmpc", "price"; a `Method` enum value works too)."""
        name = getattr(method, "value", method)
        if name == "active":
            return cls()
        if name == "dqmpc":
            return cls(tracking=False, person=False, approach=False, dqmpc_thresholds=True)
        if name == "price":
            return cls(tracking=False, teammates=False, obstacles=False, person=False, approach=False)
        raise ValueError(f"unknown method {method!r}: choose active, dqmpc or price")


@dataclass(frozen=True, eq=False)
class TeammatePaths:
    """Teammates' horizon plans aligned to our horizon, as arrays (J teammates, N+1 steps).

    positions_m: (J, N+1, 3) teammate j's planned position at our step n; vehicle_ids: (J,) int, used only to
    break exact ties; in_formation: (J,) bool, only these count for K and the angular term (all are avoided);
    d_max_m: (J,) the teammate-repulsion d_max of eq. 15 for each (covariance radii and message age included).
    rejected: plans dropped for non-finite or absurd numbers while building this.
    ages_s: (J,) each plan's age at now (s); None: all fresh (0).
    gps_offsets_m: (J, 3) each sender's GPS offset relative to the team (HorizonPlan.gps_offset_m);
    None: zeros.
    """

    positions_m: np.ndarray
    vehicle_ids: np.ndarray
    in_formation: np.ndarray
    d_max_m: np.ndarray
    rejected: int = 0
    ages_s: np.ndarray | None = None
    gps_offsets_m: np.ndarray | None = None

    def placed_by(self, own_offset_m: np.ndarray) -> TeammatePaths:
        """These paths shifted by own_offset_m (3,) less each sender's offset: where the teammates are
        relative to us, both GPS offsets taken out (controller/gps_offset.py)."""
        offsets = np.zeros((self.count, 3)) if self.gps_offsets_m is None else self.gps_offsets_m
        shift = np.asarray(own_offset_m, dtype=float)[None, :] - offsets
        if not shift.any():
            return self
        # the constructor, not dataclasses.replace: this runs every tick, and replace looks up every field
        return TeammatePaths(
            self.positions_m + shift[:, None, :],
            self.vehicle_ids,
            self.in_formation,
            self.d_max_m,
            self.rejected,
            self.ages_s,
            self.gps_offsets_m,
        )

    @property
    def ages(self) -> np.ndarray:
        """(J,) each plan's age (s), zeros when not given."""
        return np.zeros(self.count) if self.ages_s is None else self.ages_s

    @classmethod
    def empty(cls, steps: int, *, rejected: int = 0) -> TeammatePaths:
        return cls(
            np.zeros((0, steps, 3)), np.zeros(0, dtype=int), np.zeros(0, dtype=bool), np.zeros(0), rejected
        )

    @property
    def count(self) -> int:
        return int(self.positions_m.shape[0])


@dataclass(frozen=True, eq=False)
class ObstacleSet:
    """Vertical cylinders as arrays: centers_m (M, 2), radii_m (M,), heights_m (M,)."""

    centers_m: np.ndarray
    radii_m: np.ndarray
    heights_m: np.ndarray

    @classmethod
    def from_obstacles(cls, obstacles: Sequence[Obstacle]) -> ObstacleSet:
        """Stack obstacles; one with a non-finite (or beyond 1000 km) centre is dropped (callers count
        `len(obstacles) - count`)."""
        kept = [o for o in obstacles if float(np.abs(o.center_m).max()) < SANE_ABS]
        if not kept:
            return cls(np.zeros((0, 2)), np.zeros(0), np.zeros(0))
        return cls(
            np.array([o.center_m for o in kept]),
            np.array([o.radius_m for o in kept]),
            np.array([o.height_m for o in kept]),
        )

    @property
    def count(self) -> int:
        return int(self.radii_m.shape[0])

    def kernel_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(centers_m, radii_m, heights_m) as the compiled kernels take them (`kernel_array`)."""
        return (
            kernel_array(self.centers_m, float),
            kernel_array(self.radii_m, float),
            kernel_array(self.heights_m, float),
        )


@dataclass(frozen=True, eq=False)
class ExternalInputs:
    """The external inputs f(0..N) of one MAV, total and per term, each (N+1, 3) m/s^2 (z always 0).

    total is what the MPC gets (eq. 14, clamped). The terms are before the total clamp (tracking and approach
    after their own clamps) and are for display and debugging. fault is True when the total was not finite and
    was replaced by zeros.
    """

    total: np.ndarray
    tracking: np.ndarray
    teammates: np.ndarray
    obstacles: np.ndarray
    person: np.ndarray
    approach: np.ndarray
    fault: bool = False


# --------------------------------------------------------------------------------------------- field shape
def cotangential_magnitude(d, *, d_min, d_max, gain, freeze_fraction: float = 0.2):
    """Cotangential field magnitude F(d) (docs/method.md#cotangential-field).

    F(d) = G (pi/2) / D * (cot z + z - pi/2) with D = d_max - d_min and z rising linearly from
    z0 = (pi/2) * freeze_fraction at d = d_min to pi/2 at d = d_max. So F(d_max) = 0 and F = 0 beyond, F is
    strictly decreasing on (d_min, d_max) (dF/dz = -G (pi/2)/D cot^2 z < 0), and it is held at the finite
    F(d_min)
    below d_min: the original field with its pole moved just below d_min, instead of the original's flat
    freeze over [d_min, d_min + 0.1], so the function stays strictly monotone above d_min.

    d, d_min, d_max, gain: floats or arrays that broadcast (d_min < d_max elementwise). Returns a float for
    scalar arguments, else an array of the broadcast shape.
    """
    d_arr = np.asarray(d, dtype=float)
    lo = np.asarray(d_min, dtype=float)
    span = np.asarray(d_max, dtype=float) - lo
    if (span <= 0.0).any():
        raise ValueError("cotangential_magnitude needs d_min < d_max")
    z0 = HALF_PI * freeze_fraction
    frac = np.clip((d_arr - lo) / span, 0.0, 1.0)
    # w = pi/2 - z; cot z + z - pi/2 = tan w - w, summed as a series near d_max where it would cancel.
    w = (HALF_PI - z0) * (1.0 - frac)
    w2 = w * w
    shape = np.where(w < 0.05, w * w2 * (1.0 / 3.0 + w2 * (2.0 / 15.0 + w2 * 17.0 / 315.0)), np.tan(w) - w)
    out = (np.asarray(gain, dtype=float) * HALF_PI) / span * shape
    return float(out) if out.ndim == 0 else out


def peak_gain(peak, *, d_min, d_max, freeze_fraction: float):
    """The gain G that makes the cotangential field equal `peak` at (and below) d_min."""
    z0 = HALF_PI * freeze_fraction
    return peak * (np.asarray(d_max, dtype=float) - d_min) / (HALF_PI * (1.0 / np.tan(z0) + z0 - HALF_PI))


def clamp_norm(vectors: np.ndarray, limit: float) -> np.ndarray:
    """Scale every row of (..., k) whose norm exceeds limit down to norm limit (eq. 14's rule)."""
    norms = np.sqrt(np.einsum("...i,...i->...", vectors, vectors))
    scale = np.minimum(1.0, limit / np.maximum(norms, 1e-300))
    return vectors * scale[..., None]


# --------------------------------------------------------------------------------------------- teammates
def plan_path(plan: HorizonPlan, *, now_s: float, dt_s: float, steps: int) -> np.ndarray:
    """(steps, 3) a plan's positions at our times now_s + n dt_s, n = 0..steps-1.

    The plan is shifted by its age and linearly interpolated; before its x(0) and beyond its last state it is
    held (a plan older than its horizon gives the teammate's last planned position).
    """
    return _aligned(
        plan.positions_m[None],
        np.array([plan.stamp_s]),
        np.array([plan.dt_s]),
        now_s=now_s,
        dt_s=dt_s,
        steps=steps,
    )[0]


def plan_velocities(plan: HorizonPlan, *, now_s: float, dt_s: float, steps: int) -> np.ndarray:
    """(steps, 3) a plan's velocities at our times now_s + n dt_s, aligned as in `plan_path`."""
    return _aligned(
        plan.velocities_mps[None],
        np.array([plan.stamp_s]),
        np.array([plan.dt_s]),
        now_s=now_s,
        dt_s=dt_s,
        steps=steps,
    )[0]


def _aligned(
    positions: np.ndarray, stamps: np.ndarray, plan_dts: np.ndarray, *, now_s: float, dt_s: float, steps: int
) -> np.ndarray:
    """(J, steps, 3) plans (J, L, 3) stamped stamps (J,) with steps plan_dts (J,) sampled at now_s + n
    dt_s."""
    last = positions.shape[1] - 1
    t = now_s + dt_s * np.arange(steps)
    k = np.clip((t[None, :] - stamps[:, None]) / plan_dts[:, None], 0.0, float(last))
    lo = np.minimum(k.astype(int), last)
    hi = np.minimum(lo + 1, last)
    a = (k - lo)[..., None]
    rows = np.arange(positions.shape[0])[:, None]
    return (1.0 - a) * positions[rows, lo] + a * positions[rows, hi]


def covariance_radius_m(cov_m2: np.ndarray) -> float | np.ndarray:
    """Horizontal radius of a position covariance for eq. 15: the square root of the largest eigenvalue of
    its horizontal (x, y) 2x2 block (m), horizontal because every force is
    (docs/method.md#avoidance-guarantee).

    cov_m2: (3, 3) or (2, 2), or (J, 3, 3) for J radii at once.
    """
    cov = np.asarray(cov_m2, dtype=float)[..., :2, :2]
    a, b, c = cov[..., 0, 0], 0.5 * (cov[..., 0, 1] + cov[..., 1, 0]), cov[..., 1, 1]
    largest = 0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b * b)  # closed-form 2x2 eigenvalue
    radius = np.sqrt(np.maximum(largest, 0.0))
    return float(radius) if radius.ndim == 0 else radius


@functools.lru_cache(maxsize=64)
def _stacked_covariance_radii(covs: bytes) -> np.ndarray:
    """(J,) `covariance_radius_m` of J stacked (3, 3) covariances given as their float64 bytes, read-only.
    Remembered: `teammate_paths` stacks the same few covariances tick after tick (the agent's phantoms carry
    the default one), and the closed form is a dozen numpy calls."""
    radii = covariance_radius_m(np.frombuffer(covs).reshape(-1, 3, 3))
    assert isinstance(radii, np.ndarray)  # one radius per covariance of the stack
    return read_only(radii)


def teammate_age_term_m(ages_s: np.ndarray, params: FieldParams) -> np.ndarray:
    """r_comm of eq. 15 for plans of these ages (s): teammate_speed_mps * max(0, age - grace), m."""
    return params.teammate_speed_mps * np.maximum(
        np.asarray(ages_s, dtype=float) - params.teammate_age_grace_s, 0.0
    )


def teammate_paths(
    plans: Sequence[HorizonPlan],
    *,
    now_s: float,
    dt_s: float,
    steps: int,
    own_cov_radius_m: float,
    params: FieldParams,
    current_position_only: bool = False,
) -> TeammatePaths:
    """Align every teammate's latest plan to our horizon and compute its eq. 15 d_max.

    d_max = teammate_d_max_base_m + r_sigma(own) + r_sigma(j) + teammate_speed_mps * max(0, age - grace)
    (each r_sigma capped at covariance_radius_cap_m): the guarantee's r_sigma_k + r_sigma_j + r_comm on top of
    a fixed base. current_position_only (the `price` baseline, which shares no plans) holds each plan's x(0)
    over the horizon. Plans must have finite stamps and positive steps; a plan with a non-finite (or beyond
    1000 km) position or covariance is dropped and counted in `rejected`.
    """
    if not plans:
        return TeammatePaths.empty(steps)
    if len({len(p.positions_m) for p in plans}) == 1:
        stacked = np.stack([p.positions_m for p in plans])
    else:
        stacked = None
    covs = np.stack([p.position_cov_m2 for p in plans])
    if stacked is not None:
        worst = np.maximum(np.abs(stacked).max(axis=(1, 2)), np.abs(covs).max(axis=(1, 2)))
    else:
        worst = np.array([max(np.abs(p.positions_m).max(), np.abs(p.position_cov_m2).max()) for p in plans])
    sane = worst < SANE_ABS
    rejected = len(plans) - int(np.count_nonzero(sane))
    if rejected:
        plans = [p for p, ok in zip(plans, sane, strict=True) if ok]
        stacked = stacked[sane] if stacked is not None else None
        covs = covs[sane]
        if not plans:
            return TeammatePaths.empty(steps, rejected=rejected)
    stamps = np.array([p.stamp_s for p in plans])
    if current_position_only:
        paths = np.repeat(np.array([p.positions_m[0] for p in plans])[:, None, :], steps, axis=1)
    elif stacked is not None:
        plan_dts = np.array([p.dt_s for p in plans])
        paths = _aligned(stacked, stamps, plan_dts, now_s=now_s, dt_s=dt_s, steps=steps)
    else:
        paths = np.stack([plan_path(p, now_s=now_s, dt_s=dt_s, steps=steps) for p in plans])
    cap = params.covariance_radius_cap_m
    radii = np.minimum(_stacked_covariance_radii(covs.tobytes()), cap)
    d_max = (
        params.teammate_d_max_head_m(own_cov_radius_m) + radii + teammate_age_term_m(now_s - stamps, params)
    )
    ids = np.array([p.vehicle_id for p in plans], dtype=int)
    in_formation = np.array([p.in_formation for p in plans], dtype=bool)
    offsets = np.stack([p.gps_offset_m for p in plans])
    return TeammatePaths(paths, ids, in_formation, d_max, rejected, np.maximum(now_s - stamps, 0.0), offsets)


# --------------------------------------------------------------------------------------------- the terms
def _tangents(rel_xy: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """Counter-clockwise unit tangents (..., 2) of the circles about the person; zero where rho ~ 0."""
    safe = np.where(rho > 1e-9, rho, np.inf)
    return np.stack((-rel_xy[..., 1], rel_xy[..., 0]), axis=-1) / safe[..., None]


def _away(diff_xy: np.ndarray, dist: np.ndarray, tie_sign) -> np.ndarray:
    """Unit vectors along diff_xy (..., 2); where dist ~ 0, +-x by tie_sign so that two MAVs split."""
    unit = diff_xy / np.where(dist > 1e-9, dist, np.inf)[..., None]
    tie = dist <= 1e-9
    if tie.any():
        fallback = np.zeros_like(unit)
        fallback[..., 0] = np.broadcast_to(tie_sign, dist.shape)
        unit = np.where(tie[..., None], fallback, unit)
    return unit


def tracking_inputs(
    *,
    rel_xy: np.ndarray,
    rho: np.ndarray,
    mates_rel_xy: np.ndarray,
    mate_ids: np.ndarray,
    own_id: int,
    team_size: int,
    d_des_m: float,
    params: FieldParams,
) -> np.ndarray:
    """Active-tracking input (eqs. 10-11), (N+1, 2), before its clamp.

    rel_xy (N+1, 2): own horizontal position minus the person's, rho (N+1,) its norm; mates_rel_xy (J, N+1,
    2): the in-formation teammates' positions minus the person's. For every teammate j the magnitude is
    (|d_des - rho| + c) F(delta), delta in [0, pi] the angle between the two bearings about the person (the
    plain angle, not the original's squared one), thresholds d_min = tracking_min_fraction * 2 pi / K and
    d_max = 2 pi / K; the direction is the tangent to the circle about the person that points away from j
    (an exact tie is split by vehicle id).
    """
    if mates_rel_xy.shape[0] == 0 or team_size < 2:
        return np.zeros_like(rel_xy)
    gamma = np.arctan2(rel_xy[:, 1], rel_xy[:, 0])
    gamma_j = np.arctan2(mates_rel_xy[..., 1], mates_rel_xy[..., 0])
    signed = wrap_angle(gamma[None, :] - gamma_j)
    d_max = TWO_PI / team_size
    delta = np.abs(signed)
    within = (delta < d_max).any(axis=1)  # only teammates closer than 2 pi / K at some step push
    if not within.any():
        return np.zeros_like(rel_xy)
    signed, delta, mate_ids = signed[within], delta[within], mate_ids[within]
    mag = cotangential_magnitude(
        delta,
        d_min=params.tracking_min_fraction * d_max,
        d_max=d_max,
        gain=params.gain,
        freeze_fraction=params.freeze_fraction,
    )
    side = np.sign(signed)
    if (side == 0.0).any():
        side = np.where(side == 0.0, np.where(own_id < mate_ids, -1.0, 1.0)[:, None], side)
    scalar = (np.abs(d_des_m - rho) + params.tracking_c) * (mag * side).sum(axis=0)
    return scalar[:, None] * _tangents(rel_xy, rho)


def repulsion_inputs(
    *,
    diff_xy: np.ndarray,
    dist: np.ndarray,
    d_min: float,
    d_max: float | np.ndarray,
    peak: float,
    params: FieldParams,
    tie_sign: float | np.ndarray = 1.0,
) -> np.ndarray:
    """Sum over the first axis of cotangential repulsions F(dist) along diff_xy (eq. 12), (N+1, 2).

    diff_xy (M, N+1, 2) from each source to us; dist (M, N+1) the distance the thresholds apply to; d_min a
    float, d_max and tie_sign floats or (M, 1) columns; the field equals `peak` at d_min. Sources never within
    d_max are skipped.
    """
    within = (dist < d_max).any(axis=1) if diff_xy.shape[0] else np.zeros(0, dtype=bool)
    if not within.any():
        return np.zeros(diff_xy.shape[1:])
    diff_xy, dist = diff_xy[within], dist[within]
    d_max = d_max[within] if isinstance(d_max, np.ndarray) and d_max.ndim == 2 else d_max
    tie_sign = tie_sign[within] if isinstance(tie_sign, np.ndarray) and tie_sign.ndim == 2 else tie_sign
    gain = peak_gain(peak, d_min=d_min, d_max=d_max, freeze_fraction=params.freeze_fraction)
    mag = np.asarray(
        cotangential_magnitude(
            dist, d_min=d_min, d_max=d_max, gain=gain, freeze_fraction=params.freeze_fraction
        )
    )
    norm = np.sqrt(np.einsum("...i,...i->...", diff_xy, diff_xy))
    return (mag[..., None] * _away(diff_xy, norm, tie_sign)).sum(axis=0)


def braking_margin_m(
    *, diff_xy: np.ndarray, velocities_xy: np.ndarray, brake_mps2: float, cap_m: float
) -> np.ndarray:
    """Distance (M, N+1) the MAV needs to stop its approach to each source: v_close^2 / (2 brake_mps2),
    capped at cap_m.

    diff_xy (M, N+1, 2) from each source to us; velocities_xy (N+1, 2) our velocity at each step; v_close the
    velocity component towards the source (0 when moving away or past it).
    """
    dist = np.sqrt(np.einsum("mni,mni->mn", diff_xy, diff_xy))
    along = np.einsum("mni,ni->mn", diff_xy, velocities_xy) / np.where(dist > 1e-9, dist, np.inf)
    closing = np.maximum(-along, 0.0)
    return np.minimum(closing * closing / (2.0 * brake_mps2), cap_m)


def obstacle_inputs(
    *,
    diff_xy: np.ndarray,
    surface: np.ndarray,
    rel_xy: np.ndarray,
    rho: np.ndarray,
    person_xy: np.ndarray,
    obstacles: ObstacleSet,
    d_min: float,
    d_max: float,
    person_d_min_m: float,
    d_des_m: float,
    active: np.ndarray,
    params: FieldParams,
    margin_m: np.ndarray | float = 0.0,
) -> np.ndarray:
    """Static and virtual obstacle input (eq. 13) with its radial slide, (N+1, 2).

    diff_xy (M, N+1, 2) from each axis to us; surface (M, N+1) the distance to each cylinder's surface; active
    (M, N+1) masks cylinders the MAV is above; margin_m (M, N+1) or a float moves both thresholds of the
    repulsion (not of the slide) out (the braking margin, `braking_margin_m`). The repulsion F(surface)
    points away from the axis. The slide (FieldParams.obstacle_slide) adds obstacle_slide * F * |tangential
    part of the direction| along the radius about the person, towards the side of the obstacle where the
    circle of radius d_des_m runs: inwards when the circle passes inside the obstacle's radius and the passage
    between the obstacle's clearance and the person's d_min is open, outwards otherwise; the slide sum is
    clamped at slide_max_mps2. (Sliding by the MAV's own radius instead left a MAV that a trunk had pushed
    out beyond it stuck there, sliding further out, while its slot lay inside: docs/method.md.)
    """
    freeze = params.freeze_fraction
    gain = peak_gain(params.obstacle_peak_mps2, d_min=d_min, d_max=d_max, freeze_fraction=freeze)
    brake = cotangential_magnitude(
        surface - margin_m, d_min=d_min, d_max=d_max, gain=gain, freeze_fraction=freeze
    )
    brake = np.where(active, brake, 0.0)
    unit = _away(diff_xy, surface + obstacles.radii_m[:, None], 1.0)
    force = (brake[..., None] * unit).sum(axis=0)
    # The slide steers round the trunk at its own distance: the braking margin only stops the approach.
    mag = np.where(
        active,
        cotangential_magnitude(surface, d_min=d_min, d_max=d_max, gain=gain, freeze_fraction=freeze),
        0.0,
    )
    if params.obstacle_slide > 0.0 and (mag > 0.0).any():
        tangent = _tangents(rel_xy, rho)
        blocked = np.abs(np.einsum("mni,ni->mn", unit, tangent))
        rho_m = np.sqrt(
            np.einsum(
                "mni,mni->mn",
                obstacles.centers_m[:, None, :] - person_xy[None],
                obstacles.centers_m[:, None, :] - person_xy[None],
            )
        )
        inner_open = rho_m - obstacles.radii_m[:, None] - d_min > person_d_min_m
        side = np.where((d_des_m < rho_m) & inner_open, -1.0, 1.0)
        slide = np.clip(
            (params.obstacle_slide * mag * blocked * side).sum(axis=0),
            -params.slide_max_mps2,
            params.slide_max_mps2,
        )
        radial = rel_xy / np.where(rho > 1e-9, rho, np.inf)[:, None]
        force = force + slide[:, None] * radial
    return force


def away_from_trunks(
    force_xy: np.ndarray, *, own_xy: np.ndarray, obstacles: ObstacleSet, reach_m: float, own_z: np.ndarray
) -> np.ndarray:
    """The person's repulsion (N+1, 2) without its components towards trunks within reach_m of the MAV.

    The person's keep-out is a comfort distance, a trunk a collision (docs/method.md#the-person): each
    cylinder the MAV is beside (below its top) with its surface closer than reach_m removes the part of the
    force that points at its axis.
    """
    out = force_xy.copy()
    diff = obstacles.centers_m[:, None, :] - own_xy[None]  # (M, N+1, 2) from us to each axis
    dist = np.sqrt(np.einsum("mni,mni->mn", diff, diff))
    near = (dist - obstacles.radii_m[:, None] < reach_m) & (own_z[None, :] < obstacles.heights_m[:, None])
    for m in np.flatnonzero(near.any(axis=1)):
        toward = diff[m] / np.where(dist[m] > 1e-9, dist[m], np.inf)[:, None]
        push = np.einsum("ni,ni->n", out, toward)
        out = out - np.where(near[m] & (push > 0.0), push, 0.0)[:, None] * toward
    return out


def approach_inputs(
    *,
    own_xy: np.ndarray,
    rel_xy: np.ndarray,
    rho: np.ndarray,
    person_xy: np.ndarray,
    obstacles: ObstacleSet,
    active: np.ndarray,
    params: FieldParams,
) -> np.ndarray:
    """Approach-angle input against local minima behind obstacles, (N+1, 2), before its clamp.

    An obstacle counts when active (M, N+1) (its surface within approach_range_m of the MAV) and it lies
    inside the MAV's radius about the person with its clearance (rho_m + radius + obstacle_d_min_m < rho): it
    is then in the MAV's line of approach (and of sight). The push is tangential, of magnitude F(|gamma_k -
    gamma_m|) (thresholds 0 and approach_angle_rad about the person) times the ramp (1 - surface /
    approach_range_m), and points away from the obstacle's bearing (the original always pushed
    counter-clockwise).
    """
    if obstacles.count == 0:
        return np.zeros_like(rel_xy)
    obs_rel = obstacles.centers_m[:, None, :] - person_xy[None]
    gamma_m = np.arctan2(obs_rel[..., 1], obs_rel[..., 0])
    gamma = np.arctan2(rel_xy[:, 1], rel_xy[:, 0])
    signed = wrap_angle(gamma[None, :] - gamma_m)
    mag = cotangential_magnitude(
        np.abs(signed),
        d_min=0.0,
        d_max=params.approach_angle_rad,
        gain=params.gain,
        freeze_fraction=params.freeze_fraction,
    )
    diff = own_xy[None, :, :] - obstacles.centers_m[:, None, :]
    surface = np.sqrt(np.einsum("mni,mni->mn", diff, diff)) - obstacles.radii_m[:, None]
    ramp = np.clip(1.0 - surface / params.approach_range_m, 0.0, 1.0)
    rho_m = np.sqrt(np.einsum("mni,mni->mn", obs_rel, obs_rel))
    in_line = rho_m + obstacles.radii_m[:, None] + params.obstacle_d_min_m < rho[None, :]
    side = np.where(signed >= 0.0, 1.0, -1.0)
    scalar = np.where(active & in_line, mag * ramp * side, 0.0).sum(axis=0)
    return scalar[:, None] * _tangents(rel_xy, rho)


def external_inputs(
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
    """Every external input for horizon steps n = 0..N and their clamped total (eqs. 10-14).

    own_positions_m: (N+1, 3) our position at step n (the previous plan, the start position at n = 0);
    person_position_m: (3,) or (N+1, 3) the fused person estimate (per step when predicted over the horizon);
    teammates: all teammates (in formation or not); obstacles: trees and virtual obstacles (vertical
    cylinders);
    team_size: K, the MAVs in formation including us; in_formation: False drops our own angular terms;
    own_velocities_mps: (N+1, 3) our velocity at step n; when given, the obstacle thresholds move out by the
    braking margin (FieldParams.obstacle_brake_mps2; not for the dqmpc thresholds).

    total = clamp_{f_max}(clamp_{tracking_max}(f_act) + f_dyn + f_sta + f_person +
    clamp_{approach_max}(f_ang)): the tangential steering terms are clamped below the
    input authority on their own (docs/method.md#runaway-off-the-circle), the safety terms only by the total
    clamp (eq. 14); f_person never points
    at a trunk within obstacle_d_min_m (`away_from_trunks`). A non-finite total becomes zero with
    fault=True.
    """
    own = np.asarray(own_positions_m, dtype=float)
    steps = own.shape[0]
    own_xy = own[:, :2]
    person_xy = np.broadcast_to(np.asarray(person_position_m, dtype=float)[..., :2], (steps, 2))
    rel = own_xy - person_xy
    rho = np.sqrt(np.einsum("ij,ij->i", rel, rel))
    zero = np.zeros((steps, 2))
    tracking = teammate = obstacle = person = approach = zero

    if terms.tracking and in_formation and teammates.count and teammates.in_formation.any():
        mates = teammates.in_formation
        mates_rel = teammates.positions_m[mates, :, :2] - person_xy[None]
        tracking = clamp_norm(
            tracking_inputs(
                rel_xy=rel,
                rho=rho,
                mates_rel_xy=mates_rel,
                mate_ids=teammates.vehicle_ids[mates],
                own_id=own_id,
                team_size=team_size,
                d_des_m=d_des_m,
                params=params,
            ),
            params.tracking_max_mps2,
        )

    if terms.teammates and teammates.count:
        diff = own_xy[None] - teammates.positions_m[..., :2]
        dist = np.sqrt(np.einsum("jni,jni->jn", diff, diff))
        if terms.dqmpc_thresholds:
            d_min, d_max = params.dqmpc_d_min_m, params.dqmpc_d_max_m
        else:
            d_min = params.teammate_d_min_m
            d_max = np.maximum(teammates.d_max_m, d_min + 1e-3)[:, None]
        tie = np.where(own_id < teammates.vehicle_ids, -1.0, 1.0)[:, None]
        teammate = repulsion_inputs(
            diff_xy=diff,
            dist=dist,
            d_min=d_min,
            d_max=d_max,
            peak=params.teammate_peak_mps2,
            params=params,
            tie_sign=tie,
        )

    if (terms.obstacles or terms.approach) and obstacles.count:
        diff = own_xy[None] - obstacles.centers_m[:, None, :]
        surface = np.sqrt(np.einsum("mni,mni->mn", diff, diff)) - obstacles.radii_m[:, None]
        if terms.dqmpc_thresholds:
            d_min, d_max = params.dqmpc_d_min_m, params.dqmpc_d_max_m
        else:
            d_min, d_max = params.obstacle_d_min_m, params.obstacle_d_max_m
        margin = 0.0
        if own_velocities_mps is not None and not terms.dqmpc_thresholds:
            margin = braking_margin_m(
                diff_xy=diff,
                velocities_xy=np.asarray(own_velocities_mps)[:, :2],
                brake_mps2=params.obstacle_brake_mps2,
                cap_m=params.obstacle_brake_margin_max_m,
            )
        # A cylinder counts only where the MAV is not clearly above its top.
        below_top = own[None, :, 2] < obstacles.heights_m[:, None] + d_min
        if terms.obstacles and (below_top & (surface - margin < d_max)).any():
            obstacle = obstacle_inputs(
                diff_xy=diff,
                surface=surface,
                rel_xy=rel,
                rho=rho,
                person_xy=person_xy,
                obstacles=obstacles,
                d_min=d_min,
                d_max=d_max,
                person_d_min_m=params.person_d_min_fraction * d_des_m,
                d_des_m=d_des_m,
                active=below_top,
                params=params,
                margin_m=margin,
            )
        if terms.approach and in_formation:
            near = below_top & (surface < params.approach_range_m)
            if near.any():
                approach = clamp_norm(
                    approach_inputs(
                        own_xy=own_xy,
                        rel_xy=rel,
                        rho=rho,
                        person_xy=person_xy,
                        obstacles=obstacles,
                        active=near,
                        params=params,
                    ),
                    params.approach_max_mps2,
                )

    if terms.person:
        lo, hi = params.person_d_min_fraction * d_des_m, params.person_d_max_fraction * d_des_m
        if hi > lo and (rho < hi).any():
            person = repulsion_inputs(
                diff_xy=rel[None],
                dist=rho[None],
                d_min=lo,
                d_max=hi,
                peak=params.person_peak_mps2,
                params=params,
            )
            if obstacles.count and (person != 0.0).any():
                person = away_from_trunks(
                    person,
                    own_xy=own_xy,
                    obstacles=obstacles,
                    reach_m=params.obstacle_d_min_m,
                    own_z=own[:, 2],
                )

    total_xy = clamp_norm(tracking + teammate + obstacle + person + approach, params.f_max_mps2)
    fault = not bool(np.isfinite(total_xy).all())
    if fault:
        total_xy = zero

    def as3(xy: np.ndarray) -> np.ndarray:
        out = np.zeros((steps, 3))
        out[:, :2] = xy
        return out

    return ExternalInputs(
        total=as3(total_xy),
        tracking=as3(tracking),
        teammates=as3(teammate),
        obstacles=as3(obstacle),
        person=as3(person),
        approach=as3(approach),
        fault=fault,
    )
