"""The box table: an empty table (no vehicle seen, every score filtered) is a normal case;
concatenation keeps the rows in order and the columns every part has."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from slopedist.detections import BoxTable, read_box_csv, read_box_file, read_kitti_labels
from slopedist.detections.boxes import concat_boxes

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
