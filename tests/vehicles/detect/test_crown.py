"""Where the head point goes: the crown read from the person's segmentation mask when there is one, from
the body's proportions when there is none (vehicles/detect/pose.py)."""

from __future__ import annotations

import numpy as np

from vehicles.detect.pose import CROWN_ABOVE_EARS, crown_from_mask, head_and_feet

EARS = np.array([50.3, 60.0])


def _standing(ears: np.ndarray = EARS, feet_y: float = 160.0) -> np.ndarray:
    """(33, 3) landmarks of an upright person: ears at `ears`, hips 40 px below, feet at feet_y."""
    marks = np.zeros((33, 3))
    marks[:, 2] = 0.9
    marks[:, :2] = ears
    marks[[23, 24], :2] = ears + [0.0, 40.0]
    marks[[29, 30, 31, 32], :2] = [ears[0], feet_y]
    return marks


def _head_mask(top_y: float, shape: tuple[int, int] = (200, 100)) -> np.ndarray:
    """A mask with the person (probability 1) from row top_y down, the background 0, a soft 1-px edge."""
    rows = np.arange(shape[0], dtype=np.float32)[:, None]
    return np.broadcast_to(np.clip(rows - top_y + 0.5, 0.0, 1.0), shape).astype(np.float32)


def test_the_crown_is_the_mask_edge_straight_above_the_ears():
    crown = crown_from_mask(EARS, _head_mask(top_y=31.0), search_px=40.0)
    assert crown is not None
    assert crown[0] == EARS[0]
    assert abs(crown[1] - 31.0) <= 0.5


def test_no_crown_when_the_ears_are_off_the_mask():
    assert crown_from_mask(EARS, _head_mask(top_y=70.0), search_px=40.0) is None


def test_no_crown_when_the_mask_runs_on_past_the_search():
    assert crown_from_mask(EARS, _head_mask(top_y=10.0), search_px=30.0) is None


def test_no_crown_when_the_head_leaves_the_image():
    assert crown_from_mask(EARS, _head_mask(top_y=0.0), search_px=100.0) is None


def test_head_and_feet_take_the_crown_from_the_mask():
    head, feet, _, _ = head_and_feet(_standing(), _head_mask(top_y=31.0))
    assert np.allclose(head, [EARS[0], 31.0], atol=0.5)
    assert np.allclose(feet, [EARS[0], 160.0])


def test_without_a_usable_mask_the_crown_is_the_body_proportion_above_the_ears():
    expected = EARS - [0.0, CROWN_ABOVE_EARS * 100.0]  # ears to feet: 100 px
    for mask in (None, _head_mask(top_y=70.0)):
        head, _, _, _ = head_and_feet(_standing(), mask)
        assert np.allclose(head, expected, atol=1e-9)
