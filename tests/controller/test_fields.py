"""Specification of the potential fields (controller/fields.py): the cotangential magnitude and every external
input of paper eqs. 10-15."""

from __future__ import annotations

import numpy as np
import pytest

from controller.fields import (
    FieldParams,
    FieldTerms,
    ObstacleSet,
    TeammatePaths,
    braking_margin_m,
    cotangential_magnitude,
    covariance_radius_m,
    external_inputs,
    peak_gain,
    plan_path,
    teammate_paths,
)
from controller.messages import HorizonPlan, Obstacle

STEPS = 16
PERSON = np.array([0.0, 0.0, 0.9])
ACTIVE = FieldTerms.for_method("active")
DEFAULTS = FieldParams()


def on_circle(bearing_deg: float, radius_m: float = 8.0, height_m: float = 8.9) -> np.ndarray:
    b = np.radians(bearing_deg)
    return np.array([radius_m * np.cos(b), radius_m * np.sin(b), height_m])


def held(position: np.ndarray) -> np.ndarray:
    """(STEPS, 3) a position held over the horizon."""
    return np.repeat(np.asarray(position, dtype=float)[None, :], STEPS, axis=0)


def mates(*positions, in_formation=True, d_max_m=3.0) -> TeammatePaths:
    paths = np.stack([held(p) for p in positions]) if positions else np.zeros((0, STEPS, 3))
    n = len(positions)
    flags = np.full(n, in_formation, dtype=bool) if np.isscalar(in_formation) else np.asarray(in_formation)
    return TeammatePaths(paths, np.arange(1, n + 1), flags, np.full(n, d_max_m))


def trees(*centers, radius_m=0.3) -> ObstacleSet:
    return ObstacleSet.from_obstacles(
        [
            Obstacle(obstacle_id=f"t{i}", center_m=np.asarray(c, dtype=float), radius_m=radius_m)
            for i, c in enumerate(centers)
        ]
    )


def inputs(
    own,
    *,
    teammates=None,
    obstacles=None,
    team_size=None,
    params=DEFAULTS,
    terms=ACTIVE,
    d_des_m=8.0,
    in_formation=True,
):
    teammates = mates() if teammates is None else teammates
    obstacles = trees() if obstacles is None else obstacles
    k = 1 + int(np.count_nonzero(teammates.in_formation)) if team_size is None else team_size
    own_path = held(own) if np.ndim(own) == 1 else own
    return external_inputs(
        own_positions_m=own_path,
        person_position_m=PERSON,
        teammates=teammates,
        obstacles=obstacles,
        team_size=k,
        d_des_m=d_des_m,
        params=params,
        terms=terms,
        own_id=0,
        in_formation=in_formation,
    )


def radial_tangent(position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rel = position[:2] - PERSON[:2]
    r = rel / np.linalg.norm(rel)
    return r, np.array([-r[1], r[0]])


# ------------------------------------------------------------------------------------ cotangential magnitude
def test_magnitude_is_zero_at_and_beyond_d_max():
    values = cotangential_magnitude(np.array([3.0, 3.0001, 4.0, 1e6]), d_min=1.5, d_max=3.0, gain=50.0)
    np.testing.assert_array_equal(values, 0.0)


def test_magnitude_strictly_decreases_between_the_thresholds():
    d = np.linspace(1.5 + 1e-6, 3.0 - 1e-6, 500)
    values = np.asarray(cotangential_magnitude(d, d_min=1.5, d_max=3.0, gain=50.0))
    assert np.all(np.diff(values) < 0.0)
    assert values[-1] > 0.0


def test_magnitude_below_d_min_is_saturated_at_its_finite_d_min_value():
    d_min, d_max, gain, freeze = 1.5, 3.0, 50.0, 0.2
    z0 = 0.5 * np.pi * freeze
    expected = gain * (0.5 * np.pi) / (d_max - d_min) * (1.0 / np.tan(z0) + z0 - 0.5 * np.pi)
    below = cotangential_magnitude(
        np.array([1.5, 1.0, 0.0, -7.0]), d_min=d_min, d_max=d_max, gain=gain, freeze_fraction=freeze
    )
    np.testing.assert_allclose(below, expected, rtol=1e-12)
    assert np.isfinite(expected)


def test_magnitude_is_vectorised_like_scalar_calls():
    d = np.array([[0.5, 1.7], [2.2, 2.9]])
    vector = np.asarray(cotangential_magnitude(d, d_min=1.5, d_max=3.0, gain=20.0))
    scalar = np.array(
        [[cotangential_magnitude(float(x), d_min=1.5, d_max=3.0, gain=20.0) for x in row] for row in d]
    )
    assert vector.shape == (2, 2)
    np.testing.assert_allclose(vector, scalar, rtol=1e-12)
    assert isinstance(cotangential_magnitude(2.0, d_min=1.5, d_max=3.0, gain=20.0), float)


def test_magnitude_rejects_inverted_thresholds():
    with pytest.raises(ValueError, match="d_min < d_max"):
        cotangential_magnitude(1.0, d_min=3.0, d_max=3.0, gain=1.0)


def test_peak_gain_makes_the_field_equal_the_peak_at_d_min():
    gain = peak_gain(8.0, d_min=1.5, d_max=3.0, freeze_fraction=0.2)
    value = cotangential_magnitude(1.5, d_min=1.5, d_max=3.0, gain=gain, freeze_fraction=0.2)
    assert value == pytest.approx(8.0)


# ------------------------------------------------------------------------------------------- total and clamp
def random_scene(rng: np.random.Generator, *, adversarial: bool):
    own = on_circle(rng.uniform(-180, 180), rng.uniform(0.0, 12.0))
    n_mates = int(rng.integers(1, 16))
    n_trees = int(rng.integers(0, 14))
    if adversarial:  # everything piled onto the MAV, the person under it
        spots = own + rng.normal(0.0, 0.3, size=(n_mates + n_trees, 3))
        spots[: n_mates // 2] = own
    else:
        spots = rng.uniform(-15, 15, size=(n_mates + n_trees, 3))
    flags = rng.random(n_mates) < 0.7
    team = TeammatePaths(
        np.stack([held(p) for p in spots[:n_mates]]),
        np.arange(1, n_mates + 1),
        flags,
        rng.uniform(2.5, 6.0, n_mates),
    )
    obstacles = trees(*spots[n_mates:, :2], radius_m=float(rng.uniform(0.1, 1.0)))
    return own, team, obstacles


@pytest.mark.parametrize("adversarial", [False, True])
def test_total_norm_never_exceeds_f_max(adversarial):
    rng = np.random.default_rng(7 if adversarial else 3)
    params = DEFAULTS
    worst = 0.0
    for _ in range(300):
        own, team, obstacles = random_scene(rng, adversarial=adversarial)
        result = inputs(own, teammates=team, obstacles=obstacles, d_des_m=float(rng.uniform(2.0, 12.0)))
        worst = max(worst, float(np.linalg.norm(result.total, axis=1).max()))
        assert np.all(np.isfinite(result.total))
    assert worst <= params.f_max_mps2 + 1e-9
    if adversarial:
        assert worst == pytest.approx(params.f_max_mps2)


def test_every_input_is_horizontal():
    rng = np.random.default_rng(11)
    for _ in range(50):
        own, team, obstacles = random_scene(rng, adversarial=False)
        result = inputs(own, teammates=team, obstacles=obstacles)
        for term in (
            result.total,
            result.tracking,
            result.teammates,
            result.obstacles,
            result.person,
            result.approach,
        ):
            np.testing.assert_array_equal(term[:, 2], 0.0)


def test_non_finite_total_becomes_zero_and_is_flagged():
    own = held(on_circle(0.0))
    own[5] = np.nan
    result = inputs(own, teammates=mates(on_circle(10.0)))
    assert result.fault
    np.testing.assert_array_equal(result.total, 0.0)


def test_finite_inputs_are_not_flagged():
    assert not inputs(on_circle(0.0), teammates=mates(on_circle(10.0))).fault


# ---------------------------------------------------------------------------------------- active tracking
def test_tracking_input_is_tangent_to_the_circle():
    for bearing, rho in [(0.0, 8.0), (37.0, 6.5), (-120.0, 10.0), (179.0, 8.0)]:
        own = on_circle(bearing, rho)
        f = inputs(own, teammates=mates(on_circle(bearing + 25.0)), team_size=3).tracking[0, :2]
        radial, _ = radial_tangent(own)
        assert np.linalg.norm(f) > 0.1
        assert abs(f @ radial) < 1e-9


@pytest.mark.parametrize("offset_deg", [20.0, -20.0])
def test_tracking_input_points_away_from_the_neighbour(offset_deg):
    own = on_circle(0.0)
    f = inputs(own, teammates=mates(on_circle(offset_deg)), team_size=3).tracking[0, :2]
    _, tangent = radial_tangent(own)
    assert np.sign(f @ tangent) == -np.sign(offset_deg)


@pytest.mark.parametrize("team_size", [2, 3, 5, 8, 16])
def test_tracking_input_vanishes_once_the_gap_reaches_two_pi_over_k(team_size):
    gap = 360.0 / team_size
    own = on_circle(10.0)
    at_gap = inputs(own, teammates=mates(on_circle(10.0 + gap)), team_size=team_size).tracking
    short = inputs(own, teammates=mates(on_circle(10.0 + 0.9 * gap)), team_size=team_size).tracking
    np.testing.assert_allclose(at_gap, 0.0, atol=1e-9)
    assert np.linalg.norm(short[0]) > 1e-3


def test_tracking_d_min_lies_below_two_pi_over_k_for_every_team_size():
    params = FieldParams()
    for team_size in range(2, 17):
        d_max = 2 * np.pi / team_size
        assert 0.0 <= params.tracking_min_fraction * d_max < d_max


def test_tracking_sum_is_clamped_below_the_input_authority():
    own = on_circle(0.0, 14.0)  # far off the circle: the factor |d_des - rho| + c is large
    crowd = mates(*[on_circle(b) for b in (3.0, 6.0, 9.0, 12.0)])
    f = inputs(own, teammates=crowd, team_size=5).tracking
    assert np.linalg.norm(f, axis=1).max() == pytest.approx(FieldParams().tracking_max_mps2)


def test_out_of_formation_teammates_do_not_steer_the_spacing():
    own = on_circle(0.0)
    result = inputs(own, teammates=mates(on_circle(20.0), in_formation=False), team_size=1)
    np.testing.assert_array_equal(result.tracking, 0.0)


def test_exactly_coincident_bearings_split_by_vehicle_id():
    own = on_circle(30.0)
    team = TeammatePaths(
        np.stack([held(on_circle(30.0, 12.0))]), np.array([5]), np.array([True]), np.array([3.0])
    )
    f = inputs(own, teammates=team, team_size=3).tracking[0, :2]
    _, tangent = radial_tangent(own)
    assert f @ tangent < -0.1  # own id 0 < 5: clockwise


# ----------------------------------------------------------------------------------- repulsion and person
def test_teammate_repulsion_points_away_and_vanishes_beyond_d_max():
    own = np.array([0.0, 8.0, 8.9])
    near = inputs(own, teammates=mates(own + np.array([2.0, 0.5, 0.0])), team_size=1).teammates[0, :2]
    far = inputs(own, teammates=mates(own + np.array([3.01, 0.0, 0.0])), team_size=1).teammates
    assert near @ np.array([-2.0, -0.5]) > 0.0
    assert abs(near[0] * 0.5 - near[1] * 2.0) < 1e-9  # along the line between the two
    np.testing.assert_array_equal(far, 0.0)


def test_teammate_repulsion_uses_each_step_of_the_plan():
    own = held(np.array([0.0, 8.0, 8.9]))
    passing = held(np.array([10.0, 8.0, 8.9]))
    passing[10:] = [1.8, 8.0, 8.9]  # the teammate's plan comes close from step 10 on
    team = TeammatePaths(passing[None], np.array([1]), np.array([False]), np.array([3.0]))
    f = inputs(own, teammates=team, team_size=1).teammates
    np.testing.assert_array_equal(f[:10], 0.0)
    assert np.all(f[10:, 0] < -1.0)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_obstacle_input_points_away_from_the_obstacle(seed):
    rng = np.random.default_rng(seed)
    for _ in range(100):
        own = on_circle(rng.uniform(-180, 180), rng.uniform(4.0, 12.0))
        centre = own[:2] + rng.normal(0.0, 1.5, 2)
        f = inputs(own, obstacles=trees(centre)).obstacles[0, :2]
        away = own[:2] - centre
        if np.linalg.norm(away) - 0.3 < FieldParams().obstacle_d_max_m - 1e-6:
            assert f @ away > 0.0
        else:
            np.testing.assert_array_equal(f, 0.0)


def test_obstacle_thresholds_apply_to_the_surface_distance():
    own = np.array([8.0, 0.0, 8.9])
    thin = inputs(own, obstacles=trees([8.0, 3.2], radius_m=0.3)).obstacles  # surface 2.9 m away
    thick = inputs(own, obstacles=trees([8.0, 3.2], radius_m=0.1)).obstacles  # surface 3.1 m away
    assert np.linalg.norm(thin[0]) > 0.0
    np.testing.assert_array_equal(thick, 0.0)


def test_braking_margin_is_the_stopping_distance_of_the_closing_speed():
    diff = np.array([[[0.0, -4.0]] * 3])  # the source lies 4 m ahead (+y) at every step
    velocities = np.array([[0.0, 3.0], [3.0, 0.0], [0.0, 10.0]])  # closing, passing, very fast
    margin = braking_margin_m(diff_xy=diff, velocities_xy=velocities, brake_mps2=2.0, cap_m=4.0)
    np.testing.assert_allclose(margin, [[2.25, 0.0, 4.0]])


def test_obstacle_thresholds_move_out_by_the_braking_distance_when_closing():
    own = held(np.array([8.0, 0.0, 8.9]))
    tree = trees([8.0, 4.3])  # surface 4.0 m ahead (+y), beyond d_max = 3 m at rest

    def obstacle_force(velocity):
        vel = np.repeat(np.asarray(velocity, dtype=float)[None, :], STEPS, axis=0)
        return external_inputs(
            own_positions_m=own,
            person_position_m=PERSON,
            teammates=mates(),
            obstacles=tree,
            team_size=1,
            d_des_m=8.0,
            params=DEFAULTS,
            terms=ACTIVE,
            own_velocities_mps=vel,
        ).obstacles[0, :2]

    closing = obstacle_force([0.0, 3.0, 0.0])  # margin 2.25 m: effective surface 1.75 m
    assert closing[1] < -3.0
    np.testing.assert_array_equal(obstacle_force([0.0, 0.0, 0.0]), 0.0)
    np.testing.assert_array_equal(obstacle_force([0.0, -3.0, 0.0]), 0.0)
    np.testing.assert_array_equal(obstacle_force([3.0, 0.0, 0.0]), 0.0)


def test_person_repulsion_never_pushes_the_mav_into_a_nearby_trunk():
    # The MAV is 6.5 m from the person (inside d_min = 7 m), a trunk 1 m beyond it on the same line.
    own = held(np.array([-6.5, 0.0, 8.9]))
    trunk = trees([-7.8, 0.0])
    f = external_inputs(
        own_positions_m=own,
        person_position_m=PERSON,
        teammates=mates(),
        obstacles=trunk,
        team_size=1,
        d_des_m=8.0,
        params=DEFAULTS,
        terms=ACTIVE,
    )
    alone = external_inputs(
        own_positions_m=own,
        person_position_m=PERSON,
        teammates=mates(),
        obstacles=trees(),
        team_size=1,
        d_des_m=8.0,
        params=DEFAULTS,
        terms=ACTIVE,
    )
    assert alone.person[0, 0] == pytest.approx(-8.0)  # the full peak, straight at where the trunk is
    np.testing.assert_allclose(f.person[:, :2], 0.0, atol=1e-9)
    assert np.all(f.total[:, 0] > 0.0)  # the trunk's repulsion wins


def test_obstacle_blocking_the_circle_also_pushes_the_mav_outwards():
    own = on_circle(0.0)
    ahead = on_circle(12.0)[:2]  # a trunk on the circle, 1.7 m ahead counter-clockwise
    f = inputs(own, obstacles=trees(ahead), params=FieldParams(obstacle_slide=1.0)).obstacles[0, :2]
    plain = inputs(own, obstacles=trees(ahead), params=FieldParams(obstacle_slide=0.0)).obstacles[0, :2]
    radial, _ = radial_tangent(own)
    assert f @ radial > plain @ radial + 0.5


def test_a_mav_pushed_out_beyond_a_trunk_slides_inwards_to_its_circle():
    """A trunk at radius 10 m beside a MAV at 11 m: the d_des = 8 m circle runs inside the trunk with the
    passage open (10 - 0.3 - 1.5 = 8.2 m > the person's 7 m), so the slide points inwards, round the trunk
    towards the slot, not further out."""
    own = on_circle(0.0, 11.0)
    beside = on_circle(8.0, 10.0)[:2]  # 1.4 m ahead tangentially, 1.5 m from the MAV's side of its bark
    f = inputs(own, obstacles=trees(beside), params=FieldParams(obstacle_slide=1.0)).obstacles[0, :2]
    plain = inputs(own, obstacles=trees(beside), params=FieldParams(obstacle_slide=0.0)).obstacles[0, :2]
    radial, _ = radial_tangent(own)
    assert f @ radial < plain @ radial - 0.5


def test_obstacle_above_which_the_mav_flies_is_ignored():
    own = np.array([8.0, 0.0, 8.9])
    low = ObstacleSet(np.array([[8.0, 2.0]]), np.array([0.3]), np.array([5.0]))
    np.testing.assert_array_equal(inputs(own, obstacles=low).obstacles, 0.0)


def test_person_repulsion_pushes_out_inside_d_des_and_vanishes_at_it():
    inside = inputs(on_circle(40.0, 7.2)).person[0, :2]
    radial, _ = radial_tangent(on_circle(40.0))
    assert inside @ radial > 0.1
    np.testing.assert_allclose(inputs(on_circle(40.0, 8.0)).person, 0.0, atol=1e-12)  # rho = 8 - 1e-15


def test_person_thresholds_scale_with_d_des():
    own = on_circle(0.0, 4.5)
    assert np.linalg.norm(inputs(own, d_des_m=5.0).person[0]) > 0.1  # d_min 4.375, d_max 5
    np.testing.assert_array_equal(inputs(own, d_des_m=4.0).person, 0.0)


# --------------------------------------------------------------------------------------- approach angle
def test_approach_input_pushes_away_from_an_obstacle_on_the_line_of_approach():
    for side in (+1.0, -1.0):
        own = on_circle(0.0, 9.0)
        trunk = on_circle(side * 8.0, 6.5)[:2]  # between the MAV and the person, slightly to one side
        f = inputs(own, obstacles=trees(trunk)).approach[0, :2]
        radial, tangent = radial_tangent(own)
        assert np.sign(f @ tangent) == -side
        assert abs(f @ radial) < 1e-9


def test_approach_input_ignores_an_obstacle_beside_the_mav_on_the_circle():
    own = on_circle(0.0)
    np.testing.assert_array_equal(inputs(own, obstacles=trees(on_circle(14.0)[:2])).approach, 0.0)


# ------------------------------------------------------------------------------------------- the methods
def test_dqmpc_has_only_repulsion_with_its_own_thresholds():
    terms = FieldTerms.for_method("dqmpc")
    own = on_circle(0.0, 7.0)
    result = inputs(own, teammates=mates(own + np.array([3.5, 0.0, 0.0])), terms=terms, team_size=2)
    np.testing.assert_array_equal(result.tracking, 0.0)
    np.testing.assert_array_equal(result.person, 0.0)
    assert np.linalg.norm(result.teammates[0]) > 0.0  # 3.5 m is inside DQMPC's d_max of 4 m


def test_price_has_no_input_in_the_mpc():
    own = on_circle(0.0, 7.0)
    result = inputs(
        own,
        teammates=mates(own + np.array([1.0, 0.0, 0.0])),
        obstacles=trees(own[:2] + 1.0),
        terms=FieldTerms.for_method("price"),
    )
    np.testing.assert_array_equal(result.total, 0.0)


def test_unknown_method_is_rejected():
    with pytest.raises(ValueError, match="unknown method"):
        FieldTerms.for_method("swarm")


# ---------------------------------------------------------------------------------------- teammate plans
def straight_plan(*, stamp_s: float, vehicle_id: int = 1, cov_scale: float = 0.25) -> HorizonPlan:
    positions = np.stack([np.array([float(i), 0.0, 8.0]) for i in range(17)])
    velocities = np.tile([10.0, 0.0, 0.0], (17, 1))
    return HorizonPlan(
        vehicle_id=vehicle_id,
        stamp_s=stamp_s,
        dt_s=0.1,
        positions_m=positions,
        velocities_mps=velocities,
        position_cov_m2=np.eye(3) * cov_scale,
    )


def test_plan_is_shifted_by_its_age_and_held_at_its_end():
    path = plan_path(straight_plan(stamp_s=10.0), now_s=10.25, dt_s=0.1, steps=16)
    np.testing.assert_allclose(path[:3, 0], [2.5, 3.5, 4.5])
    np.testing.assert_allclose(path[-3:, 0], [15.5, 16.0, 16.0])


def test_teammate_d_max_grows_with_covariance_and_message_age():
    params = FieldParams()
    fresh = teammate_paths(
        [straight_plan(stamp_s=5.0)], now_s=5.1, dt_s=0.1, steps=16, own_cov_radius_m=0.5, params=params
    )
    stale = teammate_paths(
        [straight_plan(stamp_s=4.5)], now_s=5.1, dt_s=0.1, steps=16, own_cov_radius_m=0.5, params=params
    )
    wide = teammate_paths(
        [straight_plan(stamp_s=5.0, cov_scale=4.0)],
        now_s=5.1,
        dt_s=0.1,
        steps=16,
        own_cov_radius_m=0.5,
        params=params,
    )
    assert fresh.d_max_m[0] == pytest.approx(3.0)
    assert stale.d_max_m[0] == pytest.approx(3.0 + 5.0 * 0.5)
    assert wide.d_max_m[0] == pytest.approx(3.0 + 1.5)


def test_covariance_radius_is_the_root_of_the_largest_eigenvalue():
    rotation = np.array([[0.6, -0.8, 0.0], [0.8, 0.6, 0.0], [0.0, 0.0, 1.0]])
    tilted = rotation @ np.diag([9.0, 1.0, 4.0]) @ rotation.T
    assert covariance_radius_m(tilted) == pytest.approx(3.0)
    np.testing.assert_allclose(covariance_radius_m(np.stack([np.eye(3) * 0.25, tilted])), [0.5, 3.0])


def test_covariance_radius_ignores_the_vertical_variance():
    honest_gps = np.diag([0.25, 0.25, 1.0])
    assert covariance_radius_m(honest_gps) == pytest.approx(0.5)
    vertical_tilt = np.array([[0.25, 0.0, 0.4], [0.0, 0.16, 0.0], [0.4, 0.0, 4.0]])
    assert covariance_radius_m(vertical_tilt) == pytest.approx(0.5)


def test_honest_gps_covariance_keeps_a_k16_neighbour_outside_d_max():
    chord_m = 2.0 * 8.0 * np.sin(np.pi / 16)
    plan = straight_plan(stamp_s=5.0)
    honest = HorizonPlan(
        vehicle_id=plan.vehicle_id,
        stamp_s=plan.stamp_s,
        dt_s=plan.dt_s,
        positions_m=plan.positions_m,
        velocities_mps=plan.velocities_mps,
        in_formation=True,
        position_cov_m2=np.diag([0.25, 0.25, 1.0]),
    )
    paths = teammate_paths(
        [honest],
        now_s=5.0,
        dt_s=0.1,
        steps=16,
        own_cov_radius_m=float(covariance_radius_m(np.diag([0.25, 0.25, 1.0]))),
        params=FieldParams(),
    )
    assert paths.d_max_m[0] == pytest.approx(3.0)
    assert paths.d_max_m[0] < chord_m - 0.1


def test_teammate_plan_with_absurd_numbers_is_dropped_and_counted():
    bad = straight_plan(stamp_s=0.0, vehicle_id=2, cov_scale=1e12)
    team = teammate_paths(
        [straight_plan(stamp_s=0.0), bad],
        now_s=0.1,
        dt_s=0.1,
        steps=16,
        own_cov_radius_m=0.5,
        params=DEFAULTS,
    )
    assert (team.count, team.rejected) == (1, 1)


def test_price_reads_only_the_first_state_of_a_plan():
    team = teammate_paths(
        [straight_plan(stamp_s=0.0)],
        now_s=0.5,
        dt_s=0.1,
        steps=16,
        own_cov_radius_m=0.5,
        params=FieldParams(),
        current_position_only=True,
    )
    np.testing.assert_array_equal(team.positions_m[0], held(np.array([0.0, 0.0, 8.0])))


def test_obstacle_with_non_finite_centre_is_dropped():
    good = Obstacle(obstacle_id="a", center_m=np.array([1.0, 2.0]), radius_m=0.3)
    bad = Obstacle(obstacle_id="b", center_m=np.array([np.nan, 2.0]), radius_m=0.3)
    assert ObstacleSet.from_obstacles([good, bad]).count == 1
