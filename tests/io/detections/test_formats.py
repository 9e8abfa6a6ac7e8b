"""MOTChallenge, COCO JSON and YOLO folder readers: values, frames, file/line/field errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist.core.errors import ConfigurationError, InputFileError, MissingInputError
from slopedist.io.detections.formats import (
    read_coco,
    read_coco_image_map,
    read_mot,
    read_yolo_folder,
)


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def test_mot_det_txt_is_one_based_and_keeps_scores(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "det.txt",
        "1,-1,100.5,200,50,40,0.9,-1,-1,-1\n3,-1,10,20,30,40,-2.5,-1,-1,-1\n"
        "4,-1,10,20,30,40,-1,-1,-1,-1\n",
    )
    table = read_mot(path)
    assert table.frame.tolist() == [0, 2, 3] and table.track_id.tolist() == [-1, -1, -1]
    np.testing.assert_allclose(table.boxes[:2], [[100.5, 200, 150.5, 240], [10, 20, 40, 60]])
    np.testing.assert_allclose(table.score, [0.9, -2.5, np.nan])  # -1: MOT's "no score"
    assert list(table.cls) == ["Car", "Car", "Car"]


def test_mot_gt_txt_drops_ignored_rows_and_names_classes(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "gt.txt",
        "1,5,10,20,30,40,1,3,0.8\n1,6,10,20,30,40,0,3,1\n2,7,1,2,3,4,1,1,1\n2,8,1,2,3,4,1,12,1\n",
    )
    table = read_mot(path)
    assert table.track_id.tolist() == [5, 7] and list(table.cls) == ["Car", "Pedestrian"]
    assert np.all(np.isnan(table.score))


@pytest.mark.parametrize(
    ("text", "line", "field"),
    [
        ("1,-1,10,20,30,40,0.9,-1,-1,-1\n1,-1,x,20,30,40,0.9,-1,-1,-1\n", 2, "left"),
        ("1.5,-1,10,20,30,40,0.9\n", 1, "frame"),
        ("0,-1,10,20,30,40,0.9\n", 1, "frame"),
        ("1,-1,10,20,30,40,0.9\n2,-1,1e308,161.7,158.5,130.6,0.9\n", 2, "left,top,width,height"),
        ("1,-1,9e5,20,2e5,40,0.9\n", 1, "left,top,width,height"),
        ("1,2,3\n", 1, None),
    ],
)
def test_mot_errors_name_line_and_field(
    tmp_path: Path, text: str, line: int, field: str | None
) -> None:
    with pytest.raises(InputFileError) as err:
        read_mot(_write(tmp_path / "det.txt", text))
    assert err.value.line == line and err.value.field == field
    assert "det.txt" in str(err.value)


def test_coco_results_with_identity_and_given_image_map(tmp_path: Path) -> None:
    items = [
        {"image_id": 4, "category_id": 3, "bbox": [10, 20, 30, 40], "score": 0.5},
        {"image_id": 5, "category_id": 8, "bbox": [1, 2, 3, 4], "score": 0.7, "track_id": 9},
        {"image_id": 5, "category_id": 1, "bbox": [1, 2, 3, 4], "score": 0.9},  # person
        {"image_id": 5, "category_id": 3, "bbox": [0, 0, 90, 40], "iscrowd": 1},  # a group
    ]
    path = _write(tmp_path / "res.json", json.dumps(items))
    table = read_coco(path)
    assert table.frame.tolist() == [4, 5] and list(table.cls) == ["Car", "Truck"]
    assert table.track_id.tolist() == [-1, 9]
    np.testing.assert_allclose(table.boxes, [[10, 20, 40, 60], [1, 2, 4, 6]])
    assert read_coco(path, image_frames={4: 0, 5: 1}).frame.tolist() == [0, 1]
    with pytest.raises(InputFileError, match=r"image id 4 is not in") as err:
        read_coco(path, image_frames={5: 0})
    assert err.value.field == "[0].image_id"


def test_coco_dataset_file_maps_images_by_file_name_and_categories_by_name(tmp_path: Path) -> None:
    data = {
        "images": [{"id": 11, "file_name": "b.png"}, {"id": 10, "file_name": "a.png"}],
        "categories": [{"id": 1, "name": "car"}, {"id": 2, "name": "person"}],
        "annotations": [
            {"image_id": 11, "category_id": 1, "bbox": [0, 0, 2, 2]},
            {"image_id": 10, "category_id": 2, "bbox": [0, 0, 2, 2]},
        ],
    }
    path = _write(tmp_path / "gt.json", json.dumps(data))
    assert read_coco_image_map(path) == {10: 0, 11: 1}
    table = read_coco(path)
    assert table.frame.tolist() == [1] and list(table.cls) == ["Car"] and np.isnan(table.score[0])


@pytest.mark.parametrize(
    ("items", "field"),
    [
        ([{"image_id": 1, "category_id": 3, "bbox": [0, 0, 1]}], "[0].bbox"),
        ([{"image_id": 1, "category_id": 3, "bbox": [0, "a", 1, 1]}], "[0].bbox"),
        ([{"image_id": 1.5, "category_id": 3, "bbox": [0, 0, 1, 1]}], "[0].image_id"),
        ([{"image_id": 1, "bbox": [0, 0, 1, 1]}], "[0].category_id"),
        ([{"image_id": 1, "category_id": 3, "bbox": [0, 0, 1, 1], "score": "x"}], "[0].score"),
        ([7], "[0]"),
        ([{"image_id": 1, "category_id": 3, "bbox": [0, 0, 1e300, 1]}], "[0].bbox"),
    ],
)
def test_coco_errors_name_the_element_and_field(tmp_path: Path, items: list, field: str) -> None:
    with pytest.raises(InputFileError) as err:
        read_coco(_write(tmp_path / "r.json", json.dumps(items)))
    assert err.value.field == field


_CAR = {"image_id": 0, "category_id": 3, "bbox": [0, 0, 1, 1]}


@pytest.mark.parametrize(
    ("data", "field"),
    [
        ([{**_CAR, "image_id": -3}], "[0].image_id"),
        ([{**_CAR, "image_id": 10**11}], "[0].image_id"),
        ([{**_CAR, "track_id": -5}], "[0].track_id"),
        ({"images": [{"id": 0, "frame_id": "abc"}], "annotations": [_CAR]}, "images[0].frame_id"),
        ({"images": [{"id": 0, "frame_id": None}], "annotations": [_CAR]}, "images[0].frame_id"),
        ({"images": [{"id": 0, "frame_id": 2.7}], "annotations": [_CAR]}, "images[0].frame_id"),
        ({"images": [{"id": 0, "frame_id": -7}], "annotations": [_CAR]}, "images[0].frame_id"),
        ({"images": [{"frame_id": 0}], "annotations": [_CAR]}, "images[0].id"),
        ({"images": [{"file_name": "a.png", "id": "x"}], "annotations": [_CAR]}, "images[0].id"),
        (
            {
                "images": [{"id": 0, "file_name": "a.png"}],
                "categories": [{"name": "car"}],
                "annotations": [_CAR],
            },
            "categories[0].id",
        ),
        (
            {
                "images": [{"id": 0, "file_name": "a.png"}],
                "categories": [{"id": [3], "name": "car"}],
                "annotations": [_CAR],
            },
            "categories[0].id",
        ),
    ],
)
def test_coco_frames_ids_and_dataset_fields_are_checked(
    tmp_path: Path, data: object, field: str
) -> None:
    """A frame or track id out of range, or a dataset file's image or category id / frame that
    is not a whole number, is a named error, not a silently unused box or an internal error."""
    with pytest.raises(InputFileError) as err:
        read_coco(_write(tmp_path / "r.json", json.dumps(data)))
    assert err.value.field == field and "r.json" in str(err.value)


def test_coco_bad_json_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="not valid JSON") as err:
        read_coco(_write(tmp_path / "r.json", "[\n{\n"))
    assert err.value.line is not None
    with pytest.raises(MissingInputError):
        read_coco(tmp_path / "none.json")


def test_yolo_folder_frames_from_names_and_denormalised(tmp_path: Path) -> None:
    _write(tmp_path / "lab" / "video_1.txt", "2 0.5 0.5 0.25 0.5\n0 0.1 0.1 0.1 0.1\n")
    _write(tmp_path / "lab" / "video_3.txt", "7 0.25 0.75 0.1 0.2 0.8 12\n")
    table = read_yolo_folder(tmp_path / "lab", (800, 400), frame_base=1)
    assert table.frame.tolist() == [0, 2] and list(table.cls) == ["Car", "Truck"]
    np.testing.assert_allclose(table.boxes, [[300, 100, 500, 300], [160, 260, 240, 340]])
    assert table.track_id.tolist() == [-1, 12]
    np.testing.assert_allclose(table.score, [np.nan, 0.8])


def test_yolo_errors(tmp_path: Path) -> None:
    _write(tmp_path / "a" / "000001.txt", "2 0.5 0.5 0.25\n")
    with pytest.raises(InputFileError, match=r"000001\.txt, line 1: expected 5 to 7 fields"):
        read_yolo_folder(tmp_path / "a", (10, 10))
    _write(tmp_path / "b" / "000001.txt", "car 0.5 0.5 0.25 0.5\n")
    with pytest.raises(InputFileError, match="field 'class'"):
        read_yolo_folder(tmp_path / "b", (10, 10))
    _write(tmp_path / "c" / "frame.txt", "2 0.5 0.5 0.25 0.5\n")
    with pytest.raises(InputFileError, match="must end with the frame number"):
        read_yolo_folder(tmp_path / "c", (10, 10))
    _write(tmp_path / "d" / "000001.txt", "2 0.5 0.5 1e300 0.5\n")
    with pytest.raises(InputFileError, match=r"line 1.*not a pixel coordinate"):
        read_yolo_folder(tmp_path / "d", (10, 10))
    with pytest.raises(ConfigurationError, match="image size"):
        read_yolo_folder(tmp_path / "a", (0, 10))
    with pytest.raises(MissingInputError):
        read_yolo_folder(tmp_path / "none", (10, 10))


json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-5, 5)
    | st.floats(allow_nan=False)
    | st.text(max_size=3),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=3), inner, max_size=3)
    ),
    max_leaves=8,
)
coco_items = st.lists(
    st.fixed_dictionaries(
        {},
        optional={
            "image_id": json_values,
            "category_id": st.sampled_from([3, 8, 1]) | json_values,
            "bbox": st.lists(st.integers(0, 50) | json_values, max_size=5),
            "score": json_values,
            "track_id": json_values,
        },
    )
    | json_values,
    max_size=4,
)


@settings(max_examples=60, deadline=None)
@given(coco_items)
def test_coco_reader_fails_only_with_a_named_error(
    tmp_path_factory: pytest.TempPathFactory, items: list
) -> None:
    path = tmp_path_factory.mktemp("coco") / "r.json"
    path.write_text(json.dumps(items))
    try:
        table = read_coco(path)
    except InputFileError as exc:
        assert "r.json" in str(exc)
    else:
        assert table.boxes.shape == (len(table), 4)  # non-finite boxes: flagged by estimators


def test_coco_file_names_that_are_frame_numbers_give_those_frames(tmp_path: Path) -> None:
    """A CVAT export of images 9.png, 10.png and 8.png (folders in the names) gave frames 2, 0
    and 1 (file names sorted as text, renumbered from 0), where `slopedist run` on the image
    folder numbers them 9, 10 and 8: every box was estimated with another frame's rotation."""
    from slopedist.io.detections.formats import read_coco_image_map

    images = [
        {"id": 1, "file_name": "seq/9.png"},
        {"id": 2, "file_name": "seq\\000010.png"},
        {"id": 3, "file_name": "8.jpg"},
    ]
    path = tmp_path / "cvat.json"
    path.write_text(json.dumps({"images": images, "annotations": [], "categories": []}))
    assert read_coco_image_map(path) == {1: 9, 2: 10, 3: 8}
    images.append({"id": 4, "file_name": "other/0009.png"})
    path.write_text(json.dumps({"images": images}))
    with pytest.raises(InputFileError, match=r"images\[3\].file_name.*frame number 9 also used"):
        read_coco_image_map(path)
    images[3]["file_name"] = "seq/b.png"  # not all numbered: the file-name order, as before
    path.write_text(json.dumps({"images": images}))
    assert read_coco_image_map(path) == {3: 0, 1: 1, 4: 2, 2: 3}


def test_yolo_folder_with_a_labelimg_classes_txt(tmp_path: Path) -> None:
    """labelImg writes classes.txt beside the labels: the folder failed ('YOLO label file name
    must end with the frame number'), and without it a custom model's class 0 'car' was read as
    COCO's person and dropped: zero boxes, no word."""
    (tmp_path / "classes.txt").write_text("car\r\nperson\r\nTruck\r\n", encoding="utf-8")
    (tmp_path / "img_000001.txt").write_text(
        "0 0.5 0.5 0.1 0.1\n1 0.2 0.2 0.1 0.1\n2 0.5 0.5 0.2 0.2\n"
    )
    (tmp_path / "img_000002.txt").write_text("")
    table = read_yolo_folder(tmp_path, (1000, 500))
    assert table.frame.tolist() == [1, 1] and list(table.cls) == ["Car", "Truck"]
    np.testing.assert_allclose(table.boxes[0], [450, 225, 550, 275])
    # an explicit class map is used as given
    assert list(read_yolo_folder(tmp_path, (1000, 500), {1: "Car"}).cls) == ["Car"]
