"""Label layout: no two labels overlap, on hand-made crowds and on the real kitti_raw_lead boxes."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist import viz
from slopedist.labels import Rect, box_rect, candidate_spots, place_labels

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
    spots = candidate_spots(Rect(100, 100, 150, 140), 60, 30)
    assert spots[0].left == 153 and spots[1].bottom == 97  # right of it, then above it


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
    assert all(r is None or r.inside(W, H) for r in rects)


def test_real_lidar_boxes_labels_never_overlap(kitti_raw_lead_dir: Path) -> None:
    from slopedist.datasets.kitti_raw import (
        KittiRawDrive,
        lidar_vehicle_boxes,
        link_tracks,
        read_velodyne,
    )

    drive = KittiRawDrive.open(kitti_raw_lead_dir)
    ks = range(0, 78, 6)
    boxes = link_tracks(
        [
            lidar_vehicle_boxes(read_velodyne(drive.velodyne_paths[k]), drive.calib, (W, H), k)
            for k in ks
        ]
    )
    by_frame = boxes.frame_index()
    placed = total = 0
    for k in ks:
        fb = by_frame[k]
        texts = [
            [f"#{int(t)} {float(z):.1f} m  cut", "dy +12 px"]
            for t, z in zip(fb.track_id, fb.extra["z"])
        ]
        sizes = [viz._text_block_size(t, viz.LABEL_SCALE)[:2] for t in texts]
        order = np.argsort(fb.extra["z"])
        rects = place_labels(fb.boxes[order], [sizes[i] for i in order], (W, H))
        assert_no_overlap(rects)
        placed += sum(r is not None for r in rects)
        total += len(rects)
    assert total >= 9 * len(ks)  # about ten boxes per frame
    assert placed / total > 0.9, f"only {placed} of {total} labels found room"
