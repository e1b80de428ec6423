"""Trees: the paper's 13, the --trees parser, and seeded random placement with clearances."""

import numpy as np
import pytest

from vehicles.sim.person import paper_path
from vehicles.sim.trees import PAPER_TREES_XY, TreeSpec, _distance_to_polyline, paper_trees, random_trees


def test_paper_trees_are_the_13_of_the_paper_as_tree_cylinders():
    trees = paper_trees()
    assert len(trees) == 13
    np.testing.assert_allclose([t.center_m for t in trees], PAPER_TREES_XY)
    assert {t.kind for t in trees} == {"tree"}
    assert all(t.radius_m == pytest.approx(0.3) for t in trees)
    assert len({t.obstacle_id for t in trees}) == 13


@pytest.mark.parametrize(
    ("text", "kind", "count"),
    [("paper", "paper", 0), ("none", "none", 0), ("NONE", "none", 0), ("7", "random", 7)],
)
def test_tree_spec_parses_paper_none_and_a_count(text, kind, count):
    spec = TreeSpec.parse(text)
    assert (spec.kind, spec.count) == (kind, count)


@pytest.mark.parametrize("text", ["forest", "-1", "2.5", "", "1000"])
def test_tree_spec_rejects_anything_else_with_the_accepted_forms(text):
    with pytest.raises(ValueError, match="trees"):
        TreeSpec.parse(text)


def test_random_trees_are_reproducible_and_differ_between_seeds():
    a = random_trees(np.random.default_rng(1), count=10)
    b = random_trees(np.random.default_rng(1), count=10)
    c = random_trees(np.random.default_rng(2), count=10)
    np.testing.assert_array_equal([t.center_m for t in a], [t.center_m for t in b])
    assert not np.allclose([t.center_m for t in a], [t.center_m for t in c])


def test_random_trees_keep_clear_of_starts_the_path_and_each_other():
    starts = [((0.0, 0.0), 3.0), ((8.0, 0.0), 3.0), ((-4.0, 6.9), 3.0)]
    path = paper_path()
    trees = random_trees(
        np.random.default_rng(5),
        count=25,
        keep_clear=starts,
        keep_clear_path_xy_m=path,
        path_clearance_m=1.5,
        min_spacing_m=2.0,
    )
    centers = np.array([t.center_m for t in trees])
    assert len(trees) == 25
    for c, r in starts:
        assert np.min(np.hypot(*(centers - c).T)) >= r + 0.3
    assert min(_distance_to_polyline(p, path) for p in centers) >= 1.8
    gaps = np.hypot(*(centers[:, None, :] - centers[None, :, :]).transpose(2, 0, 1))
    assert np.min(gaps[np.triu_indices(25, 1)]) >= 2.0
    assert np.max(np.abs(centers)) <= 19.0


def test_random_trees_say_so_when_they_do_not_fit():
    with pytest.raises(ValueError, match="could not place"):
        random_trees(np.random.default_rng(0), count=50, arena_half_m=3.0, max_attempts=2000)
