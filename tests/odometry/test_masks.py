"""Box masks of the built-in visual odometry: where new corners may be detected."""

from __future__ import annotations

import numpy as np

from slopedist.odometry.masks import (
    check_boxes,
    grown_boxes,
    half_size_corner_mask,
    inside_boxes,
)


def test_corner_mask_keeps_away_from_tracks_border_and_boxes() -> None:
    tracks = np.array([[40.0, 40.0]], np.float32)  # full resolution: (20, 20) at half size
    boxes = np.array([[20.0, 30.0, 40.0, 44.0]])  # half size: columns 10–20, rows 15–22
    mask = half_size_corner_mask((50, 60), tracks, boxes, radius=2, border=3)
    assert mask.shape == (50, 60) and mask.dtype == np.uint8
    assert np.all(mask[18:23, 18:23] == 0)  # within 2 half-size pixels of the track
    assert mask[20, 23] == 255 and mask[23, 23] == 255
    assert np.all(mask[:3] == 0) and np.all(mask[-3:] == 0)
    assert np.all(mask[:, :3] == 0) and np.all(mask[:, -3:] == 0)
    assert np.all(mask[15:23, 10:21] == 0)
    assert mask[14, 12] == 255 and mask[16, 9] == 255 and mask[16, 24] == 255
    assert (
        mask == 255
    ).sum() == 44 * 54 - 25 - 8 * 11 + 5 * 3  # overlap: rows 18–22, columns 18–20


def test_no_tracks_and_no_boxes_leave_only_the_border() -> None:
    mask = half_size_corner_mask((20, 30), np.empty((0, 2), np.float32), np.empty((0, 4)), 2, 2)
    assert (mask == 255).sum() == 16 * 26


def test_inside_grown_boxes() -> None:
    boxes = np.array([[10.0, 10.0, 20.0, 20.0]])
    pts = np.array([[9.0, 15.0], [15.0, 15.0], [21.5, 15.0]], np.float32)
    assert inside_boxes(pts, boxes).tolist() == [False, True, False]
    assert inside_boxes(pts, grown_boxes(boxes, 1.0)).tolist() == [True, True, False]


def test_non_finite_mask_boxes_mask_nothing() -> None:
    boxes = check_boxes(
        [[10, 10, 20, 20], [np.nan, 0, 5, 5], [0, -np.inf, 5, 5], [0, 0, np.inf, 5]]
    )
    np.testing.assert_array_equal(boxes, [[10, 10, 20, 20]])
    mask = half_size_corner_mask((40, 60), np.zeros((0, 2), np.float32), boxes, 2, 1)
    assert mask[5:11, 5:11].max() == 0 and mask[20, 30] == 255
    assert check_boxes(None).shape == (0, 4) and check_boxes([]).shape == (0, 4)
