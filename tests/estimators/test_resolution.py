"""The resolution rule (``beyond_resolution``), hand-computed and as a property of every method.

Camera f = 720 px, c_y = 180 px, h = 1.65 m, image 1240 × 375: eq. 1 on a level road reads
``d = 1188 / (u − 180)`` metres for a box bottom at row ``u``; the image resolves a distance up
to ``f·h / 2 px = 594 m`` and a box from 2 px tall (a row of error moves either by ≤ 50 %).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist.core.camera import Camera
from slopedist.estimators import make_estimator
from slopedist.estimators.base import (
    MAX_ROW_SHARE,
    MIN_RESOLVED_PX,
    FrameEstimates,
    unresolved_distances,
)
from slopedist.evaluation.metrics import cap_estimates
from slopedist.io.detections.boxes import BoxTable
from slopedist.streaming.step import FrameStep

W, H = 1240, 375
CAMERA = Camera(720.0, 620.0, 180.0, height_m=1.65).with_image_size(W, H)
FH = 720.0 * 1.65
GROUND_CONTACT = ("flat", "ego", "paper", "imu", "imu-ego")


def settled(method: str, boxes: list[list[float]], depth_m: float | None = None) -> FrameEstimates:
    """A frame through :class:`FrameStep` (θ = 0, level camera; a uniform depth map)."""
    step = FrameStep(make_estimator(method, CAMERA))
    table = BoxTable.build(np.zeros(len(boxes)), boxes)
    depth = None if depth_m is None else np.full((H, W), depth_m, dtype=np.float32)
    return step.estimate(0, 0.0, 0.0, np.eye(3), table, None, depth)


def test_the_threshold_is_one_row_over_half_the_distance() -> None:
    assert MIN_RESOLVED_PX == pytest.approx(1.0 / MAX_ROW_SHARE) == pytest.approx(2.0)


def test_unresolved_distances_by_hand() -> None:
    """594 m is where a vehicle's contact is 2 px below the horizon; 1.9 px is too short a box."""
    tall = [600.0, 200.0, 640.0, 240.0]
    boxes = np.array([tall, tall, [600, 200, 640, 201.9], [600, 200, 640, 202.1], tall, tall])
    d = np.array([FH / 2.01, FH / 1.99, 54.0, 54.0, np.nan, -3.0])
    flagged = unresolved_distances(d, boxes, CAMERA)
    assert flagged.tolist() == [False, True, True, False, False, False]


@pytest.mark.parametrize("method", GROUND_CONTACT)
def test_a_box_either_side_of_two_pixels_tall(method: str) -> None:
    """Bottoms at rows 201.9 and 202.1 (eq. 1: 54.2 and 53.8 m, well resolved by their gap);
    the 1.9 px box is not located by its own rows: ``missing``, ``beyond_resolution``."""
    est = settled(method, [[600.0, 200.0, 620.0, 201.9], [600.0, 200.0, 620.0, 202.1]])
    assert est.status.tolist() == ["missing", "ok"]
    assert est.reason.tolist() == ["beyond_resolution", ""]
    assert np.isnan(est.distance_m[0])
    assert est.distance_m[1] == pytest.approx(FH / 22.1)


def test_a_depth_either_side_of_the_resolved_range() -> None:
    """A depth map of 590 m is resolved (contact 2.01 px below the horizon); 600 m is not."""
    box = [[580.0, 170.0, 660.0, 230.0]]
    assert settled("depthmap", box, 590.0).status.tolist() == ["ok"]
    far = settled("depthmap", box, 600.0)
    assert (far.status[0], far.reason[0]) == ("missing", "beyond_resolution")
    assert np.isnan(far.distance_m[0])


@pytest.mark.parametrize("method", ["ours", "ours-offline"])
def test_ours_has_no_ok_distance_for_a_one_pixel_box(method: str) -> None:
    """A 1 px box 1.5 rows below the horizon (its size cue reads over 1000 m)."""
    step = FrameStep(make_estimator(method, CAMERA))
    table = BoxTable.build(np.zeros(1), [[600.0, 180.5, 601.5, 181.5]], track_ids=[1])
    est = step.estimate(0, 0.0, 0.0, np.eye(3), table)
    if method == "ours-offline":
        (est,) = step.finish()
    assert est.status[0] == "missing" and np.isnan(est.distance_m[0])
    assert est.reason[0] in ("beyond_resolution", "too_uncertain", "near_horizon")


def test_beyond_resolution_is_counted_at_the_cap() -> None:
    capped, scored = cap_estimates([np.nan, 30.0], ["beyond_resolution", ""])
    assert capped.tolist() == [80.0, 30.0] and scored.all()


@settings(max_examples=60, deadline=None)
@given(
    method=st.sampled_from(["flat", "ego", "paper", "ours", "depthmap"]),
    top=st.floats(150.0, 300.0),
    height=st.floats(0.0, 8.0),
    width=st.floats(1.0, 60.0),
    depth_m=st.floats(1.0, 1000.0),
)
def test_no_ok_distance_moves_by_more_than_half_for_a_row(
    method: str, top: float, height: float, width: float, depth_m: float
) -> None:
    """Small boxes near the horizon: every ``ok`` distance is resolved — a row of error moves it
    by at most half, read at the vehicle's contact (``f·h/d`` ≥ 2 px) and the box's height;
    for eq. 1 the row is the box bottom against the method's own vanishing line."""
    box = [600.0, top, 600.0 + width, top + height]
    est = settled(method, [box], depth_m if method == "depthmap" else None)
    if est.status[0] != "ok":
        return
    d = est.distance_m[0]
    assert d / FH <= MAX_ROW_SHARE  # one row of contact gap: Δd = d² / (f·h)
    assert 1.0 / height <= MAX_ROW_SHARE
    if method in GROUND_CONTACT:
        assert 1.0 / (box[3] - est.v_px[0]) <= MAX_ROW_SHARE
