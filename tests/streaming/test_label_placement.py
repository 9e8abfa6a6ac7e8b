"""Label layout: no two labels overlap, on hand-made crowds and on the real kitti_raw_lead boxes."""

from __future__ import annotations

import itertools
from pathlib import Path
from unittest import mock

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist.streaming import drawing as viz
from slopedist.streaming.label_placement import (
    COVER_COST_PX,
    LINE_COST_PX,
    Placement,
    Rect,
    SpotGrid,
    box_rect,
    candidate_grid,
    grid_costs,
    layout_labels,
    place_labels,
)

W, H = 1242, 375


def assert_no_overlap(rects: list[Rect | None]) -> None:
    placed = [r for r in rects if r is not None]
    for a, b in itertools.combinations(placed, 2):
        assert not a.intersects(b), (a, b)


def test_rect_geometry() -> None:
    a = Rect(0, 0, 10, 10)
    assert a.intersects(Rect(9, 9, 20, 20))
    assert not a.intersects(Rect(10, 0, 20, 10))  # right edge exclusive
    assert a.overlap_area(Rect(5, 5, 20, 20)) == 25
    assert box_rect([1.2, 2.7, 3.1, 4.0]) == Rect(1, 2, 4, 4)
    assert Rect(0, 0, W, H).inside(W, H) and not Rect(-1, 0, 5, 5).inside(W, H)


def test_first_choice_is_right_of_the_box() -> None:
    (rect,) = place_labels([[100, 100, 150, 140]], [(60, 30)], (W, H))
    assert rect == Rect(153, 100, 213, 130)


def test_identical_boxes_get_stacked_labels() -> None:
    boxes = np.tile([600.0, 180.0, 660.0, 230.0], (8, 1))
    rects = place_labels(boxes, [(70, 34)] * 8, (W, H))
    assert all(r is not None for r in rects)
    assert_no_overlap(rects)


def test_reserved_areas_are_avoided() -> None:
    header = Rect(0, 0, W, 60)
    rects = place_labels([[10, 5, 60, 50]], [(60, 30)], (W, H), [header])
    assert rects[0] is not None and not rects[0].intersects(header)


def test_spots_start_next_to_the_box() -> None:
    grid = candidate_grid(Rect(100, 100, 150, 140), 60, 30)
    assert (grid.xs[0], grid.ys[0]) == (153, 100)  # right of it, top-aligned first
    assert {37, 153} <= set(grid.xs) and {67, 143} <= set(grid.ys)  # left, right; above, below
    assert 110 in grid.ys  # slid down the side by half the label's height
    assert max(grid.xs) == 153 + 6 * 33 and min(grid.ys) == 67 - 6 * 33  # pushed 6 steps out


def test_costs_hand_computed() -> None:
    own = Rect(100, 100, 150, 140)
    other = Rect(153, 100, 183, 130)  # covers half of a 60×30 label right of the box
    boxes = np.array([[*vars(own).values()], [*vars(other).values()]], float)
    weights = np.array([0.0, COVER_COST_PX / 1800])
    grid = SpotGrid([153, 173], [100])  # touching; 20 px further right
    cost = grid_costs(grid, (60, 30), own, boxes, weights, None)
    np.testing.assert_allclose(cost, [[COVER_COST_PX / 2, 20 + COVER_COST_PX / 6]])
    crossed = grid_costs(grid, (60, 30), own, boxes, weights, 129)  # row 129 crosses both
    np.testing.assert_allclose(crossed - cost, LINE_COST_PX)


def test_first_label_takes_the_best_spot() -> None:
    boxes = [[100, 100, 150, 140], [100, 100, 150, 140]]
    first, second = layout_labels(boxes, [[(60, 30)], [(60, 30)]], (W, H))
    assert first is not None and second is not None
    assert first.rect == Rect(153, 100, 213, 130) and first.gap_px == 0.0
    assert not second.rect.intersects(first.rect)


def test_shorter_form_when_the_full_one_has_no_room() -> None:
    box = [100, 40, 140, 60]  # free room only in a 50×20 strip right of the box
    reserved = [Rect(0, 0, 300, 40), Rect(0, 60, 300, 100), Rect(0, 40, 100, 60)]
    reserved.append(Rect(190, 40, 300, 60))
    (p,) = layout_labels([box], [[(80, 34), (45, 16)]], (300, 100), reserved)
    assert p == Placement(Rect(143, 40, 188, 56), 1, 0.0)


def test_anywhere_in_the_image_when_nothing_near_the_box_is_free() -> None:
    (p,) = layout_labels([[10, 40, 50, 60]], [[(40, 16)]], (400, 100), [Rect(0, 0, 300, 100)])
    assert p is not None and p.rect.left == 300 and p.gap_px > 240  # a leader line's job
    (none,) = layout_labels([[10, 40, 50, 60]], [[(40, 16)]], (400, 100), [Rect(0, 0, 400, 100)])
    assert none is None  # only a full image leaves a label out


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.integers(0, W - 40), st.integers(0, H - 40), st.integers(5, 200), st.integers(5, 150)
        ),
        min_size=1,
        max_size=25,
    )
)
def test_random_crowds_never_overlap(raw: list[tuple[int, int, int, int]]) -> None:
    boxes = [[x, y, min(x + w, W - 1), min(y + h, H - 1)] for x, y, w, h in raw]
    rects = place_labels(boxes, [(74, 34)] * len(boxes), (W, H))
    assert_no_overlap(rects)
    assert all(r is not None and r.inside(W, H) for r in rects)  # room is left: all placed


def test_every_label_on_the_real_lidar_boxes(kitti_raw_lead_dir: Path) -> None:
    """All 78 kitti_raw_lead frames with their LiDAR boxes through the real overlay: every box
    with a distance (ok or upper bound) gets a label inside the image, none overlap, the lead
    vehicle's label touches its box, and few labels need a leader line or a shorter form."""
    from slopedist.estimators import make_estimator
    from slopedist.estimators.base import FrameInput
    from slopedist.io.kitti.raw import KittiRawDrive

    drive = KittiRawDrive.open(kitti_raw_lead_dir)
    camera = drive.calib.camera().with_image_size(W, H)
    by_frame = drive.lidar_boxes((W, H)).frame_index()
    estimator = make_estimator("ours", camera)
    image = np.zeros((H, W, 3), np.uint8)
    layouts: list[list[Placement | None]] = []
    real = viz._draw_labels

    def keep(*args: object) -> list[Placement | None]:
        layouts.append(real(*args))  # type: ignore[arg-type]
        return layouts[-1]

    statuses: list[str] = []
    lead_gaps: list[float] = []
    with mock.patch.object(viz, "_draw_labels", keep):
        for k in range(78):
            boxes = by_frame[k]
            est = estimator.estimate(FrameInput(k, 0.1 * k, 0.0, boxes))
            viz.draw_fig3_overlay(image, camera, boxes, est, 0.0, f"frame {k}", "ours")
            statuses += list(est.status)
            lead = viz.lead_index(camera, boxes, est)
            if lead is not None:
                placement = layouts[-1][lead]
                assert placement is not None
                lead_gaps.append(placement.gap_px)
    placements = [p for layout in layouts for p in layout]
    assert len(placements) >= 9 * 78  # about ten boxes per frame
    assert {"ok", "upper_bound"} <= set(statuses)
    for layout in layouts:
        assert_no_overlap([p.rect if p else None for p in layout])
    missing = [s for p, s in zip(placements, statuses) if p is None]
    assert not [s for s in missing if s in ("ok", "upper_bound")], f"unlabelled: {missing}"
    assert all(p is None or p.rect.inside(W, H) for p in placements)
    assert len(lead_gaps) > 70 and max(lead_gaps) == 0.0  # the lead's label touches its box
    detached = sum(p is not None and p.gap_px > viz.LEADER_MIN_PX for p in placements)
    short = sum(p is not None and p.form > 0 for p in placements)
    assert detached < 0.3 * len(placements) and short < 0.1 * len(placements)
