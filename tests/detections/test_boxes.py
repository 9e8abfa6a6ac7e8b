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
