"""Layout sniffing, read_box_file's new layouts, and round trips through every writable layout."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist.core.errors import ConfigurationError, InputFileError
from slopedist.io.detections import read_box_file
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.convert import (
    BoxFileOptions,
    BoxFormat,
    read_boxes,
    sniff_format,
    write_boxes,
)

SIZE = (1280, 720)


def _table() -> BoxTable:
    return BoxTable.build(
        [0, 0, 2, 5],
        [[100, 200, 300, 260], [640.5, 300.25, 700, 350], [0, 0, 1280, 720], [10, 20, 30, 40]],
        [3, -1, 3, 8],
        [0.9, 0.75, 0.5, 0.25],
        ["Car", "Truck", "Car", "Bus"],
    )


def _assert_same(a: BoxTable, b: BoxTable, classes: bool = True) -> None:
    assert a.frame.tolist() == b.frame.tolist() and a.track_id.tolist() == b.track_id.tolist()
    np.testing.assert_allclose(a.boxes, b.boxes, atol=2e-3)
    np.testing.assert_allclose(a.score, b.score, atol=1e-6)
    if classes:
        assert list(a.cls) == list(b.cls)


@pytest.mark.parametrize("fmt", [BoxFormat.CSV, BoxFormat.MOT, BoxFormat.COCO, BoxFormat.YOLO])
def test_round_trip_through_each_layout(tmp_path: Path, fmt: BoxFormat) -> None:
    target = tmp_path / ("out.json" if fmt is BoxFormat.COCO else "out")
    options = BoxFileOptions(image_size=SIZE)
    assert write_boxes(_table(), target, fmt, options) == 0
    assert sniff_format(target) is fmt if fmt is not BoxFormat.CSV else True
    back = read_boxes(target, fmt, options)
    _assert_same(_table(), back, classes=fmt is not BoxFormat.MOT)


def test_classes_without_an_index_are_left_out(tmp_path: Path) -> None:
    table = BoxTable.build([0, 0, 1], [[0, 0, 5, 5]] * 3, classes=["Van", "DontCare", "Car"])
    assert write_boxes(table, tmp_path / "r.json", BoxFormat.COCO) == 1
    back = read_boxes(tmp_path / "r.json")
    assert list(back.cls) == ["Car", "Car"] and back.frame.tolist() == [0, 1]
    assert write_boxes(table, tmp_path / "y", BoxFormat.YOLO, BoxFileOptions((10, 10))) == 1


def test_read_box_file_reads_mot_and_coco(tmp_path: Path) -> None:
    mot = tmp_path / "det.txt"
    mot.write_text("1,-1,10,20,30,40,0.9,-1,-1,-1\n2,-1,10,20,30,40,0.2,-1,-1,-1\n")
    assert read_box_file(mot, min_score=0.5).frame.tolist() == [0]
    coco = tmp_path / "res.json"
    coco.write_text(json.dumps([{"image_id": 1, "category_id": 3, "bbox": [1, 2, 3, 4]}]))
    assert read_box_file(coco).boxes.tolist() == [[1, 2, 4, 6]]
    bad = tmp_path / "bad.txt"
    bad.write_text("1 2 3\n")
    with pytest.raises(InputFileError, match="unrecognised box file layout"):
        read_box_file(bad)


def test_a_header_of_other_column_names_is_named_not_read_as_mot(tmp_path: Path) -> None:
    # seven columns: it was read as MOTChallenge, "line 1, field 'left': 'y1' is not a number"
    path = tmp_path / "mine.csv"
    path.write_text("frame_id,x1,y1,x2,y2,conf,label\n0,1,2,30,40,0.9,car\n")
    with pytest.raises(InputFileError, match=r"line 1: the header 'frame_id,x1.*frame,left,top"):
        read_box_file(path)


def test_a_box_csv_with_its_columns_in_another_order_is_read(tmp_path: Path) -> None:
    # read_box_csv finds the columns by name; the sniffer refused a header not starting 'frame,'
    path = tmp_path / "reordered.csv"
    path.write_text("track_id,class,frame,left,top,right,bottom\n3,Car,0,1,2,30,40\n")
    table = read_box_file(path)
    assert table.frame.tolist() == [0] and table.track_id.tolist() == [3]
    assert table.boxes.tolist() == [[1.0, 2.0, 30.0, 40.0]]
    path.write_text('"frame","left","top","right","bottom"\n0,1,2,30,40\n')  # a quoting writer
    assert read_box_file(path).boxes.tolist() == [[1.0, 2.0, 30.0, 40.0]]


def test_a_foreign_header_after_comment_lines_is_named_at_its_line(tmp_path: Path) -> None:
    path = tmp_path / "mine.csv"
    path.write_text("# exported by my detector\n\nframe_id,x1,y1,x2,y2\n0,1,2,30,40\n")
    with pytest.raises(InputFileError, match=r"line 3: the header 'frame_id"):
        read_box_file(path)


def test_yolo_needs_an_image_size_and_kitti_is_not_writable(tmp_path: Path) -> None:
    with pytest.raises(ConfigurationError, match="image size"):
        write_boxes(_table(), tmp_path / "y", BoxFormat.YOLO)
    with pytest.raises(ConfigurationError, match="image size"):
        read_boxes(tmp_path, BoxFormat.YOLO)
    with pytest.raises(ConfigurationError, match="cannot write 'kitti'"):
        write_boxes(_table(), tmp_path / "k.txt", BoxFormat.KITTI)


quarter_px = st.integers(0, 4 * 1000).map(lambda v: v / 4)


@settings(max_examples=30, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.integers(0, 500), quarter_px, quarter_px, quarter_px, quarter_px, st.integers(-1, 99)
        ),
        min_size=1,
        max_size=8,
    )
)
def test_mot_round_trip_of_any_boxes(tmp_path_factory: pytest.TempPathFactory, rows: list) -> None:
    path = tmp_path_factory.mktemp("mot") / "det.txt"
    frames = [r[0] for r in rows]
    boxes = [[r[1], r[2], r[1] + r[3] + 0.25, r[2] + r[4] + 0.25] for r in rows]
    table = BoxTable.build(frames, boxes, [r[5] for r in rows], np.full(len(rows), 0.5))
    write_boxes(table, path, BoxFormat.MOT)
    back = read_boxes(path, BoxFormat.MOT)
    order = np.argsort(table.frame, kind="stable")
    _assert_same(table.select(order), back)


def test_yolo_is_not_written_into_a_folder_of_label_files(tmp_path: Path) -> None:
    """Writing into a YOLO folder of an earlier conversion kept its files for the frames the new
    table has no boxes for: reading the folder back mixed two box sets."""
    table = BoxTable.build([0, 5], [[10, 20, 30, 40], [1, 2, 3, 4]])
    folder = tmp_path / "labels"
    write_boxes(table, folder, "yolo", BoxFileOptions(image_size=(100, 50)))
    with pytest.raises(ConfigurationError, match=r"already holds 2 \.txt files"):
        write_boxes(
            table.select([True, False]), folder, "yolo", BoxFileOptions(image_size=(100, 50))
        )
    assert sorted(p.name for p in folder.iterdir()) == ["000000.txt", "000005.txt"]


any_px = st.floats(1.0, 1000.0, allow_nan=False).map(lambda v: round(v, 4))


@settings(max_examples=40, deadline=None)
@given(
    st.lists(
        st.tuples(any_px, any_px, any_px, any_px, st.floats(0.0, 1.0).map(lambda v: round(v, 9))),
        min_size=1,
        max_size=5,
    ),
    st.sampled_from([BoxFormat.CSV, BoxFormat.MOT, BoxFormat.COCO, BoxFormat.YOLO]),
)
def test_boxes_come_back_as_written_not_rounded_to_6_digits(
    tmp_path_factory: pytest.TempPathFactory, rows: list, fmt: BoxFormat
) -> None:
    """Box corners like 1234.5678 px and scores like 0.123456789 were written with 6
    significant digits (1234.57, 0.123457): a conversion moved every box by up to 5 mpx."""
    folder = tmp_path_factory.mktemp("exact")
    target = folder / ("b.json" if fmt is BoxFormat.COCO else "b")
    boxes = [[x, y, x + 1 + w, y + 1 + h] for x, y, w, h, _ in rows]
    table = BoxTable.build([0] * len(rows), boxes, None, [r[4] for r in rows])
    options = BoxFileOptions(image_size=(2100, 2100))
    write_boxes(table, target, fmt, options)
    back = read_boxes(target, fmt, options)
    np.testing.assert_allclose(back.boxes, table.boxes, rtol=0, atol=2e-9)
    np.testing.assert_array_equal(back.score, table.score)


def test_conversions_say_what_the_target_does_not_keep(tmp_path: Path) -> None:
    """csv → mot turned a Truck and a Pedestrian into Cars, unknown scores into -1 and dropped
    gt_distance_m; csv → yolo dropped every score and track id when one score was unknown;
    all without a word."""
    from slopedist.io.detections.convert import convert_boxes, unkept

    source = tmp_path / "b.csv"
    source.write_text(
        "frame,left,top,right,bottom,track_id,score,class,gt_distance_m\n"
        "0,10,20,110,80,3,0.9,Truck,12.5\n0,200,30,260,90,,,Car,\n"
        "1,300,100,400,200,-1,0.5,Pedestrian,\n",
        encoding="utf-8",
    )
    table = read_boxes(source)
    mot = unkept(table, "mot")
    assert "Pedestrian, Truck read back as Car" in mot[0] and "2 boxes" in mot[0]
    assert mot[1].startswith("score: 1 unknown") and "gt_distance_m" in mot[2]
    yolo = unkept(table, "yolo")
    assert yolo[0].startswith("score: 1 of 2 boxes") and yolo[1].startswith("track_id")
    assert unkept(table, "coco") == ["column(s) gt_distance_m: not in the 'coco' layout"]
    assert unkept(table, "csv") == []
    n_read, n_left, notes = convert_boxes(source, tmp_path / "det.txt", target_format="mot")
    assert (n_read, n_left, notes) == (3, 0, mot)
