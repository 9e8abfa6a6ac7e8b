"""Rows a box reader leaves out are counted by reason and reported once per file."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest

from slopedist.io.detections.convert import BoxFileOptions, read_boxes
from slopedist.io.detections.dropped import DroppedBoxes
from slopedist.io.detections.formats import read_coco, read_mot, read_yolo_folder
from slopedist.io.detections.readers import read_box_file

LOGGER = "slopedist.io.detections.dropped"


def test_mot_gt_rows_left_out_are_counted_by_reason(tmp_path: Path) -> None:
    path = tmp_path / "gt.txt"
    path.write_text(
        "1,5,10,20,30,40,1,3,0.8\n1,6,10,20,30,40,0,3,1\n2,7,1,2,3,4,1,12,1\n2,8,1,2,3,4,1,12,1\n"
    )
    dropped = DroppedBoxes()
    assert len(read_mot(path, dropped=dropped)) == 1
    assert dropped.reasons == {
        "flag 0 (to be ignored)": 1,
        "class 12 (not a MOT17 object class)": 2,
    }


def test_coco_annotations_left_out_are_counted_by_reason(tmp_path: Path) -> None:
    items = [
        {"image_id": 4, "category_id": 3, "bbox": [10, 20, 30, 40]},
        {"image_id": 5, "category_id": 1, "bbox": [1, 2, 3, 4]},  # person
        {"image_id": 6, "category_id": 1, "bbox": [1, 2, 3, 4]},
        {"image_id": 5, "category_id": 3, "bbox": [0, 0, 90, 40], "iscrowd": 1},
    ]
    path = tmp_path / "res.json"
    path.write_text(json.dumps(items))
    dropped = DroppedBoxes()
    assert len(read_coco(path, dropped=dropped)) == 1
    assert dropped.reasons == {
        "category_id 1 (not in the class map)": 2,
        "crowd annotations (iscrowd 1)": 1,
    }
    assert dropped.count == 3


def test_yolo_labels_of_classes_not_in_classes_txt_are_counted(tmp_path: Path) -> None:
    (tmp_path / "classes.txt").write_text("car\nperson\n")
    (tmp_path / "f_000001.txt").write_text("0 0.5 0.5 0.1 0.1\n1 0.2 0.2 0.1 0.1\n")
    dropped = DroppedBoxes()
    assert len(read_yolo_folder(tmp_path, (100, 100), dropped=dropped)) == 1
    assert dropped.reasons == {"class 1 (not in the class map)": 1}


def test_read_boxes_and_read_box_file_warn_once_per_file(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    items = [
        {"image_id": k, "category_id": 3 if k < 7 else 1, "bbox": [1, 2, 3, 4], "score": k / 10}
        for k in range(10)
    ]
    path = tmp_path / "res.json"
    path.write_text(json.dumps(items))
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        dropped = DroppedBoxes()
        table = read_box_file(path, min_score=None, dropped=dropped)
    assert len(table) == 7 and dropped.reasons == {"category_id 1 (not in the class map)": 3}
    assert [r.getMessage() for r in caplog.records] == [
        f"warning: {path}: dropped 3 of 10 box rows (30 %): 3 category_id 1 (not in the class map)"
    ]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        # the 5 cars scored below 0.5 are left out as asked, not counted
        assert len(read_boxes(path, options=BoxFileOptions(min_score=0.5))) == 2
        items = [{"image_id": 0, "category_id": 3, "bbox": [1, 2, 3, 4]}]
        path.write_text(json.dumps(items))
        read_boxes(path)  # nothing left out: no warning
    assert len(caplog.records) == 1 and "dropped 3 of 10" in caplog.records[0].getMessage()


def test_a_warning_names_the_most_frequent_reasons() -> None:
    dropped = DroppedBoxes()
    for k in range(7):
        for _ in range(k + 1):
            dropped.add(f"class {k}")
    message = dropped.message("f.txt", kept=72)
    assert message.startswith("f.txt: dropped 28 of 100 box rows (28 %): 7 class 6, 6 class 5, ")
    assert message.endswith("3 class 2 and 2 more reason(s)")
