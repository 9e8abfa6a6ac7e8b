"""The box table: an empty table (no vehicle seen, every score filtered) is a normal case;
concatenation keeps the rows in order and the columns every part has; box overlap: the sweep
that finds overlapping pairs against testing every pair; box checks against the image."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist.core.errors import DataMismatchError
from slopedist.io.detections import BoxTable, read_box_csv, read_box_file, read_kitti_labels
from slopedist.io.detections.boxes import (
    concat_boxes,
    iou_matrix,
    overlapping_pairs,
    pair_iou,
)

LABEL = "0 3 Car 0 1 -1.79 296.74 161.75 455.23 292.37 2.0 1.82 4.43 -4.55 1.86 13.41 -2.12"
DONTCARE = "1 -1 DontCare -1 -1 -10 100 150 200 190 -1 -1 -1 -1000 -1000 -1000 -10"


def _assert_empty(table: BoxTable) -> None:
    assert len(table) == 0
    assert list(table.by_frame()) == []
    assert table.frame_index() == {}
    assert table.frames().shape == (0,)
    assert table.boxes.shape == (0, 4)
    assert len(table.select(np.zeros(0, bool))) == 0


def test_empty_table_iterates_to_nothing() -> None:
    _assert_empty(BoxTable.empty())
    _assert_empty(BoxTable.build([], []))


def test_header_only_csv_is_an_empty_table(tmp_path: Path) -> None:
    path = tmp_path / "boxes.csv"
    path.write_text("frame,left,top,right,bottom,track_id,score,class\n")
    _assert_empty(read_box_csv(path))
    _assert_empty(read_box_file(path))


def test_score_above_every_detection_is_an_empty_table(tmp_path: Path) -> None:
    path = tmp_path / "boxes.csv"
    path.write_text("frame,left,top,right,bottom,score\n0,1,2,30,40,0.5\n2,1,2,30,40,0.9\n")
    _assert_empty(read_box_file(path, min_score=2.0))
    prcnn = tmp_path / "prcnn.txt"
    prcnn.write_text(
        "0,2,298.3,165.1,458.2,293.4,8.29,1.96,1.81,4.75,-4.57,1.84,13.53,-2.11,-1.78\n"
    )
    _assert_empty(read_box_file(prcnn, min_score=100.0))


def test_dontcare_only_labels_filter_to_an_empty_table(tmp_path: Path) -> None:
    path = tmp_path / "labels.txt"
    path.write_text(f"{DONTCARE}\n{DONTCARE}\n")
    labels = read_kitti_labels(path)
    assert len(labels) == 2
    _assert_empty(labels.select(labels.cls != "DontCare"))


def test_by_frame_groups_in_frame_order() -> None:
    t = BoxTable.build([3, 1, 3, 0], np.arange(16.0).reshape(4, 4))
    groups = [(k, list(b.boxes[:, 0])) for k, b in t.by_frame()]
    assert groups == [(0, [12.0]), (1, [4.0]), (3, [0.0, 8.0])]


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


def test_concat_of_nothing_keeps_the_columns_of_like() -> None:
    like = BoxTable.build([4], [[1, 2, 3, 4]], row=np.array([7]))
    out = concat_boxes([], like=like)
    assert len(out) == 0 and set(out.extra) == {"row"} and out.extra["row"].shape == (0,)
    _assert_empty(out)


def test_empty_table_has_no_frames() -> None:
    empty = BoxTable.empty()
    assert list(empty.by_frame()) == [] and empty.frame_index() == {}
    lookup = empty.frame_lookup()
    assert len(lookup) == 0 and 0 not in lookup and lookup.get(0) is None


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 6), max_size=30))
def test_frame_lookup_is_the_frame_index(frames: list[int]) -> None:
    n = len(frames)
    table = BoxTable.build(
        frames,
        np.arange(4 * n, dtype=float).reshape(n, 4),
        track_id=np.arange(n),
        classes=[f"c{i}" for i in range(n)],
        z=np.arange(n) * 0.5,
    )
    index, lookup = table.frame_index(), table.frame_lookup()
    assert list(lookup) == list(index) and len(lookup) == len(index)
    for k in range(-1, 8):
        assert (k in lookup) == (k in index)
        assert lookup.count(k) == (len(index[k]) if k in index else 0)
        if k in index:
            got, want = lookup[k], index[k]
            for column in ("frame", "boxes", "track_id", "score", "cls"):
                np.testing.assert_array_equal(getattr(got, column), getattr(want, column))
            np.testing.assert_array_equal(got.extra["z"], want.extra["z"])
    assert "1" not in lookup and lookup.get(99) is None


# --- box checks against the image (hand-computed, 1242 × 375 image) ---------------------------

from slopedist.io.detections.boxes import (  # noqa: E402
    BORDER_TOLERANCE_PX,
    border_cut_limits,
    border_cuts,
    box_problems,
    cut_labels,
    cuts_at,
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


@settings(max_examples=300, deadline=None)
@given(st.lists(st.lists(COORD, min_size=4, max_size=4), min_size=1, max_size=6))
def test_border_cuts_are_each_edge_against_its_own_border(boxes: list[list[float]]) -> None:
    """The cut flags (one comparison with two limit rows, NaN where an edge has no limit) are
    left/top within 1 px of 0 and right/bottom within 1 px of the last column/row, whatever
    the coordinates (infinite, NaN), without a warning."""
    import warnings

    b = np.asarray(boxes, dtype=float)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cut = border_cuts(b, SIZE)
        assert np.array_equal(cut, cuts_at(b, border_cut_limits(SIZE)))
    tol = BORDER_TOLERANCE_PX
    expected = np.stack(
        [
            b[:, 0] <= tol,
            b[:, 1] <= tol,
            b[:, 2] >= SIZE[0] - 1 - tol,
            b[:, 3] >= SIZE[1] - 1 - tol,
        ],
        axis=1,
    )
    assert np.array_equal(cut, expected)


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


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"frame": [0, 1], "boxes": [[1, 2, 3, 4]]}, "'boxes' has 4 values for 2 boxes"),
        ({"frame": [0], "boxes": [[1, 2, 3]]}, "'boxes' has 3 values for 1 boxes"),
        ({"frame": [0, 1], "boxes": [[1, 2, 3, 4]] * 2, "track_id": [1]}, "'track_id' has 1"),
        ({"frame": [0, 1], "boxes": [[1, 2, 3, 4]] * 2, "score": [0.5] * 3}, "'score' has 3"),
        ({"frame": [0], "boxes": [[1, 2, 3, 4]], "classes": ["Car", "Van"]}, "'classes' has 2"),
        ({"frame": [float("nan")], "boxes": [[1, 2, 3, 4]]}, "column 'frame'"),
        ({"frame": [0], "boxes": [["a", 2, 3, 4]]}, "column 'boxes'"),
        ({"frame": [0.5], "boxes": [[1, 2, 3, 4]]}, "'frame': 0.5 \\(entry 0\\) is not a whole"),
        (
            {"frame": [0], "boxes": [[1, 2, 3, 4]], "track_id": [2.5]},
            "'track_id': 2.5 \\(entry 0\\)",
        ),
    ],
)
def test_build_with_columns_that_do_not_fit_is_a_data_mismatch(
    kwargs: dict[str, object], message: str
) -> None:
    """They failed with numpy's bare ValueError ('cannot reshape array of size 4 ...')."""
    with pytest.raises(DataMismatchError, match=message):
        BoxTable.build(**kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf, 1e300, 2.0**63])
def test_a_frame_array_that_is_not_whole_numbers_fails_cleanly_without_a_warning(
    bad: float,
) -> None:
    """A NaN in a float frame array printed numpy's "RuntimeWarning: invalid value encountered
    in cast" before the error."""
    frame = np.array([0.0, 1.0, bad])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(DataMismatchError, match=r"'frame': \S+ \(entry 2\) is not a whole"):
            BoxTable.build(frame, np.zeros((3, 4)))
        with pytest.raises(DataMismatchError, match=r"'track_id': \S+ \(entry 2\)"):
            BoxTable.build(np.arange(3), np.zeros((3, 4)), track_id=frame)


@pytest.mark.parametrize(
    ("mask", "message"),
    [
        ([5], "index 5 is outside a table of 3 boxes"),
        (np.array([0, -4]), "index -4 is outside a table of 3 boxes"),
        ([True, False], "mask has 2 values for a table of 3 boxes"),
        ([0.5], "boolean mask or an array of row indices, got float64"),
        (np.int64(1), "of shape \\(\\)"),
    ],
)
def test_a_selection_that_does_not_fit_the_table_is_a_data_mismatch(
    mask: object, message: str
) -> None:
    """They failed with numpy's bare IndexError (or, for a scalar, gave a table of single
    values instead of columns)."""
    table = BoxTable.build([0, 1, 2], np.zeros((3, 4)))
    with pytest.raises(DataMismatchError, match=message):
        table.select(mask)  # type: ignore[arg-type]


def test_a_selection_by_valid_indices_or_mask_keeps_working() -> None:
    table = BoxTable.build([0, 1, 2], np.arange(12.0).reshape(3, 4), z=[1.0, 2.0, 3.0])
    assert table.select([2, -3]).frame.tolist() == [2, 0]
    assert table.select([True, False, True]).extra["z"].tolist() == [1.0, 3.0]
    assert len(table.select([])) == 0


def test_an_extra_column_that_is_not_one_value_per_box_is_a_data_mismatch() -> None:
    """It was accepted, and the table failed later, in a select, with numpy's IndexError."""
    with pytest.raises(DataMismatchError, match="column 'z' has 1 value\\(s\\) for 2 boxes"):
        BoxTable.build([0, 1], np.zeros((2, 4)), z=[1.0])
