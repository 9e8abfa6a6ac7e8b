"""The box table: concatenation keeps the rows in order and the columns every part has."""

from __future__ import annotations

import numpy as np

from slopedist.detections.boxes import BoxTable, concat_boxes


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


# --- box checks against the image (hand-computed, 1242 × 375 image) ---------------------------

from slopedist.detections.boxes import (  # noqa: E402
    border_cuts,
    box_problems,
    cut_labels,
    vehicle_mask,
)

SIZE = (1242, 375)


def test_box_problems_name_each_unusable_box() -> None:
    boxes = [
        [100, 100, 200, 200],  # fine
        [np.nan, 0, 1, 1],
        [10, 10, 5, 20],  # right < left
        [10, 10, 10, 20],  # zero width
        [10, 10, 10.5, 50],  # sub-pixel width
        [10, 10, 50, 10.9],  # sub-pixel height
        [1e23, 0, 1e24, 5],  # absurd
        [1300, 10, 1400, 50],  # right of the image
        [-60, 10, -0.5, 50],  # left of it (right edge on the border of pixel 0)
        [10, 375, 50, 400],  # below it
        [-200, -100, 1500, 500],  # larger than the image: usable
    ]
    assert list(box_problems(boxes, SIZE)) == [
        "",
        "non_finite_box",
        "inverted_box",
        "degenerate_box",
        "degenerate_box",
        "degenerate_box",
        "degenerate_box",
        "outside_image",
        "outside_image",
        "outside_image",
        "",
    ]
    # without an image size nothing is outside, but absurd is still absurd
    assert list(box_problems(boxes)[6:]) == ["degenerate_box", "", "", "", ""]
    assert list(box_problems([[0, 0, 12000, 3750]], SIZE)) == [""]
    assert list(box_problems([[0, 0, 13700, 100]], SIZE)) == ["degenerate_box"]


def test_border_cuts_per_edge_within_one_pixel() -> None:
    boxes = [
        [100, 100, 200, 373.0],  # bottom: 375 − 1 − 1 = 373 is within 1 px
        [100, 100, 200, 372.9],  # not cut
        [1.0, 100, 200, 300],  # left
        [1.1, 100, 200, 300],  # not cut
        [100, 1.0, 200, 300],  # top
        [100, 100, 1240.0, 300],  # right (1242 − 2)
        [100, 100, 1239.9, 300],  # not cut
        [-50, 100, 200, 400],  # left and bottom, beyond the image
        [0, 0, 1241, 374],  # every edge
    ]
    assert list(cut_labels(border_cuts(boxes, SIZE))) == [
        "bottom",
        "",
        "left",
        "",
        "top",
        "right",
        "",
        "left+bottom",
        "left+top+right+bottom",
    ]
    assert not border_cuts(boxes, None).any()


def test_vehicle_mask_is_case_insensitive_and_configurable() -> None:
    names = ["Car", " van", "TRUCK", "bus", "DontCare", "Misc", "Pedestrian", "Cyclist", "Tram"]
    assert list(vehicle_mask(names)) == [True] * 4 + [False] * 5
    assert list(vehicle_mask(names, ["tram"])) == [False] * 8 + [True]


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

COORD = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-2000, 2000),
    st.sampled_from([0.0, 1.0, 373.0, 374.0, 375.0, 1240.0, 1241.0, 1242.0, -0.5]),
)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.lists(COORD, min_size=4, max_size=4), min_size=1, max_size=6))
def test_a_usable_box_has_a_size_and_overlaps_the_image(boxes: list[list[float]]) -> None:
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        reasons = box_problems(boxes, SIZE)
        labels = cut_labels(border_cuts(boxes, SIZE))
    b = np.asarray(boxes)
    for r, (left, top, right, bottom), label in zip(reasons, b, labels):
        assert isinstance(label, str)
        if r == "":
            assert right - left >= 1 and bottom - top >= 1
            assert right > -0.5 and bottom > -0.5 and left < SIZE[0] - 0.5 and top < SIZE[1] - 0.5
