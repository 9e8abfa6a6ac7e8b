"""The box table: concatenation keeps the rows in order and the columns every part has; box
overlap: the sweep that finds overlapping pairs against testing every pair."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist.detections.boxes import (
    BoxTable,
    concat_boxes,
    iou_matrix,
    overlapping_pairs,
    pair_iou,
)


def test_concat_boxes_keeps_order_and_common_columns() -> None:
    a = BoxTable.build([0, 0], [[0, 0, 1, 1], [1, 1, 2, 2]], [1, 2])
    a.extra.update({"gt": np.array([5.0, 6.0]), "only_a": np.array([1.0, 1.0])})
    b = BoxTable.build([3], [[2, 2, 3, 3]], [7])
    b.extra["gt"] = np.array([9.0])
    out = concat_boxes([a, b])
    np.testing.assert_array_equal(out.frame, [0, 0, 3])
    np.testing.assert_array_equal(out.track_id, [1, 2, 7])
    np.testing.assert_array_equal(out.boxes[2], [2, 2, 3, 3])
    assert set(out.extra) == {"gt"}
    np.testing.assert_array_equal(out.extra["gt"], [5.0, 6.0, 9.0])


def test_concat_of_nothing_is_empty() -> None:
    assert len(concat_boxes([])) == 0


def test_empty_table_has_no_frames() -> None:
    empty = BoxTable.empty()
    assert list(empty.by_frame()) == [] and empty.frame_index() == {}


def dense_pairs(a: np.ndarray, b: np.ndarray) -> list[tuple[int, int]]:
    """Every pair tested: interiors overlap in columns and rows."""
    a3, b3 = a[:, None, :], b[None, :, :]
    cols = np.minimum(a3[..., 2], b3[..., 2]) > np.maximum(a3[..., 0], b3[..., 0])
    rows = np.minimum(a3[..., 3], b3[..., 3]) > np.maximum(a3[..., 1], b3[..., 1])
    i, j = np.nonzero(cols & rows)
    return list(zip(i.tolist(), j.tolist(), strict=True))


def random_boxes(rng: np.random.Generator, n: int, span: float) -> np.ndarray:
    left = rng.uniform(0, span, n).round(0)  # rounded: shared edges and ties are common
    top = rng.uniform(0, span / 3, n).round(0)
    w = rng.choice([0.0, 1.0, 5.0, 40.0], n) + rng.uniform(0, 30, n).round(0)
    h = rng.choice([0.0, 1.0, 20.0], n) + rng.uniform(0, 20, n).round(0)
    return np.stack([left, top, left + w, top + h], axis=1)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31), st.integers(0, 60), st.integers(0, 60), st.sampled_from([50, 400]))
def test_overlapping_pairs_equal_testing_every_pair(seed: int, n: int, m: int, span: int) -> None:
    rng = np.random.default_rng(seed)
    a, b = random_boxes(rng, n, span), random_boxes(rng, m, span)
    if n:
        a[rng.integers(0, n)] = [np.nan, 0, 1, 1]  # a non-finite box overlaps nothing
    i, j = overlapping_pairs(a, b)
    assert sorted(zip(i.tolist(), j.tolist(), strict=True)) == dense_pairs(a, b)
    np.testing.assert_array_equal(pair_iou(a, b, i, j), iou_matrix(a, b)[i, j])


def test_overlapping_pairs_by_hand() -> None:
    a = np.array([[0.0, 0.0, 10.0, 10.0], [20.0, 0.0, 30.0, 10.0]])
    b = np.array(
        [
            [10.0, 0.0, 20.0, 10.0],  # touches both along an edge: no interior overlap
            [5.0, 5.0, 25.0, 8.0],  # overlaps both
            [0.0, 10.0, 10.0, 20.0],  # below a[0], sharing its bottom edge
            [9.0, -5.0, 21.0, 0.5],  # overlaps both by a sliver
        ]
    )
    i, j = overlapping_pairs(a, b)
    assert sorted(zip(i.tolist(), j.tolist(), strict=True)) == [(0, 1), (0, 3), (1, 1), (1, 3)]
    empty = overlapping_pairs(np.zeros((0, 4)), b)
    assert empty[0].shape == (0,) and empty[1].shape == (0,)
