"""Box readers: round trips under hypothesis, clear errors naming file, line and field."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from slopedist.core.errors import InputFileError, MissingInputError
from slopedist.io.detections import (
    BoxTable,
    box_problems,
    iou_matrix,
    read_box_csv,
    read_box_file,
    read_kitti_labels,
    read_pointrcnn,
    read_rrc,
)

coord = st.floats(-2000, 4000, allow_nan=False, allow_infinity=False)
size = st.floats(2, 500, allow_nan=False)
# left, top, right, bottom: a file of mostly inverted or all-normalised boxes is refused whole
corners = st.tuples(coord, coord, size, size).map(lambda b: (b[0], b[1], b[0] + b[2], b[1] + b[3]))
row = st.tuples(
    st.integers(0, 10_000),
    corners,
    st.integers(-1, 500),
    st.floats(0, 100, allow_nan=False),
    st.sampled_from(["Car", "Van", "Truck"]),
)
TMP = settings(suppress_health_check=[HealthCheck.function_scoped_fixture], max_examples=40)


@TMP
@given(rows=st.lists(row, max_size=20))
def test_csv_round_trip(tmp_path: Path, rows: list[tuple]) -> None:
    path = tmp_path / "boxes.csv"
    lines = ["frame,left,top,right,bottom,track_id,score,class"]
    lines += [f"{f},{a!r},{b!r},{c!r},{d!r},{t},{s!r},{k}" for f, (a, b, c, d), t, s, k in rows]
    path.write_text("\n".join(lines) + "\n")
    table = read_box_csv(path)
    assert len(table) == len(rows)
    for i, (f, (a, b, c, d), t, s, k) in enumerate(rows):
        assert table.frame[i] == f and table.track_id[i] == t and table.cls[i] == k
        assert list(table.boxes[i]) == [a, b, c, d] and table.score[i] == s


@TMP
@given(
    bad=st.text(alphabet="abcxyz!?", min_size=1, max_size=5),
    col=st.sampled_from(["left", "top", "right", "bottom"]),
)
def test_csv_bad_number_names_line_and_field(tmp_path: Path, bad: str, col: str) -> None:
    path = tmp_path / "boxes.csv"
    values = {"left": "1", "top": "2", "right": "30", "bottom": "40", col: bad}
    path.write_text(
        "frame,left,top,right,bottom\n0,1,2,3,4\n1,{left},{top},{right},{bottom}\n".format(**values)
    )
    with pytest.raises(InputFileError, match=rf"line 3, field '{col}'"):
        read_box_csv(path)


def test_csv_optional_columns_and_header_error(tmp_path: Path) -> None:
    path = tmp_path / "boxes.csv"
    path.write_text("frame,left,top,right,bottom,track_id,score,class\n3,1,2,3,4,,,\n")
    t = read_box_csv(path)
    assert t.track_id[0] == -1 and math.isnan(t.score[0]) and t.cls[0] == "Car"
    path.write_text("frame,x1,y1\n0,1,2\n")
    with pytest.raises(InputFileError, match="header lacks column"):
        read_box_csv(path)
    path.write_text("Frame,Left,top,right,bottom\n0,1,2,3,4\n")  # named, in another case
    with pytest.raises(InputFileError, match="lower case: 'Frame' is 'frame', 'Left' is 'left'\\)"):
        read_box_csv(path)


@TMP
@given(
    truth=st.lists(
        st.one_of(st.none(), st.floats(0.01, 500, allow_nan=False)), min_size=1, max_size=10
    )
)
def test_csv_ground_truth_column_round_trips(tmp_path: Path, truth: list[float | None]) -> None:
    from slopedist.io.detections.writers import write_box_csv

    path = tmp_path / "boxes.csv"
    lines = ["frame,left,top,right,bottom,gt_distance_m"]
    lines += [f"{k},1,2,30,40,{'' if g is None else repr(g)}" for k, g in enumerate(truth)]
    path.write_text("\n".join(lines) + "\n")
    t = read_box_csv(path)
    expected = np.array([np.nan if g is None else g for g in truth])
    np.testing.assert_array_equal(t.extra["gt_distance_m"], expected)
    back = read_box_csv(write_box_csv(t, tmp_path / "again.csv"))
    np.testing.assert_allclose(back.extra["gt_distance_m"], expected, rtol=1e-5)
    assert (
        "gt_distance_m"
        not in read_box_csv(
            write_box_csv(BoxTable.build([0], [[1, 2, 3, 4]]), tmp_path / "none.csv")
        ).extra
    )


@pytest.mark.parametrize("bad", ["-3", "0", "inf", "nan", "far"])
def test_csv_bad_ground_truth_names_line_and_field(tmp_path: Path, bad: str) -> None:
    path = tmp_path / "boxes.csv"
    path.write_text(f"frame,left,top,right,bottom,gt_distance_m\n0,1,2,3,4,5\n1,1,2,3,4,{bad}\n")
    with pytest.raises(InputFileError, match=r"line 3, field 'gt_distance_m'"):
        read_box_csv(path)


def test_csv_of_normalised_boxes_is_refused_naming_the_first_line(tmp_path: Path) -> None:
    # boxes 0..1 of the image, not pixels: every one would be a sub-pixel box at the top-left
    path = tmp_path / "boxes.csv"
    path.write_text(
        "frame,left,top,right,bottom\n0,nan,2,3,4\n0,0.46,0.48,0.52,0.64\n1,0.1,0.5,0.2,0.6\n"
    )
    with pytest.raises(InputFileError, match=r"line 3, field 'left'.*normalised"):
        read_box_file(path)


def test_csv_of_xywh_boxes_is_refused_naming_the_first_inverted_one(tmp_path: Path) -> None:
    # x, y, width, height read as left, top, right, bottom: most boxes are inverted, and the
    # near car's (300, 150, +400, +200) would pass with its bottom at 200 instead of 350
    path = tmp_path / "boxes.csv"
    rows = ["0,571,179,75,62", "0,527,176,39,25", "0,300,150,400,200", "1,570,180,75,62"]
    path.write_text("frame,left,top,right,bottom\n" + "\n".join(rows) + "\n")
    with pytest.raises(InputFileError, match=r"line 2, field 'right': 3 of 4 boxes .* width"):
        read_box_file(path)


def test_csv_nan_box_is_read_then_rejected_per_box(tmp_path: Path) -> None:
    path = tmp_path / "boxes.csv"
    path.write_text("frame,left,top,right,bottom\n0,nan,2,3,4\n0,10,20,5,40\n0,1,2,3,4\n")
    t = read_box_csv(path)
    assert list(box_problems(t.boxes)) == ["non_finite_box", "inverted_box", ""]


LABEL = "0 3 Car 0 1 -1.79 296.74 161.75 455.23 292.37 2.0 1.82 4.43 -4.55 1.86 13.41 -2.12"


def test_kitti_labels(tmp_path: Path) -> None:
    path = tmp_path / "0000.txt"
    path.write_text(LABEL + "\n" + LABEL.replace("0 3 Car", "1 -1 DontCare") + "\n")
    t = read_kitti_labels(path)
    assert list(t.frame) == [0, 1] and t.track_id[0] == 3 and t.extra["z"][0] == 13.41
    assert t.extra["occluded"][0] == 1 and t.cls[1] == "DontCare"
    assert read_box_file(path).extra["z"][0] == 13.41


@pytest.mark.parametrize(
    ("replacement", "match"),
    [
        ("0 3 Car 0 1 -1.79 296.74 oops", "expected 17 fields"),
        (
            "0 3 Car 0 x -1.79 296.74 161.75 455.23 292.37 2.0 1.82 4.43 -4.55 1.86 13.41 -2.12",
            "line 2, field 'occluded'",
        ),
        (
            "0 3 Car 0 1 -1.79 296.74 161.75 455.23 292.37 2.0 1.82 4.43 -4.55 1.86 z13 -2.12",
            "line 2, field 'z'",
        ),
    ],
)
def test_kitti_label_errors(tmp_path: Path, replacement: str, match: str) -> None:
    path = tmp_path / "0000.txt"
    path.write_text(LABEL + "\n" + replacement + "\n")
    with pytest.raises(InputFileError, match=match):
        read_kitti_labels(path)


def test_pointrcnn_score_filter_and_error(tmp_path: Path) -> None:
    path = tmp_path / "0000.txt"
    path.write_text(
        "0,2,298.3,165.2,458.2,293.4,8.3,1.96,1.81,4.75,-4.57,1.84,13.53,-2.11,-1.79\n"
        "0,2,364.7,137.9,453.8,172.6,-0.45,1.48,1.6,3.87,-9.09,-0.01,32.8,-1.0,-0.8\n"
    )
    assert len(read_pointrcnn(path)) == 2
    kept = read_box_file(path, min_score=2.0)
    assert len(kept) == 1 and kept.score[0] == pytest.approx(8.3)
    path.write_text("0,2,298.3,165.2,458.2,bad,8.3,1.96,1.81,4.75,-4.57,1.84,13.53,-2.11,-1.79\n")
    with pytest.raises(InputFileError, match="line 1, field 'y2'"):
        read_pointrcnn(path)


def test_rrc_reader_crlf_score_filter_and_error(tmp_path: Path) -> None:
    path = tmp_path / "0000.txt"
    path.write_bytes(
        b"0,296.021000,160.173000,452.297000,288.372000,0.529230\r\n"
        b"3,290.742000,144.753000,448.155000,269.477000,0.993477\r\n"
    )
    table = read_rrc(path)
    assert table.frame.tolist() == [0, 3] and list(table.cls) == ["Car", "Car"]
    assert table.boxes[1].tolist() == [290.742, 144.753, 448.155, 269.477]
    kept = read_rrc(path, min_score=0.6)
    assert len(kept) == 1 and kept.score[0] == pytest.approx(0.993477)
    path.write_text("0,296.0,160.1,452.2\n1,1,2,3,4,0.5\n")
    with pytest.raises(InputFileError, match=r"line 1.*6 comma-separated fields, found 4"):
        read_rrc(path)
    path.write_text("0,296.0,160.1,452.2,288.3,0.5\n-1,1,2,3,4,0.5\n")
    with pytest.raises(InputFileError, match="line 2, field 'frame'"):
        read_rrc(path)


def test_missing_and_unrecognised_files(tmp_path: Path) -> None:
    with pytest.raises(MissingInputError, match="not found"):
        read_box_file(tmp_path / "none.csv")
    path = tmp_path / "weird.txt"
    path.write_text("1 2 3\n")
    with pytest.raises(InputFileError, match="unrecognised box file layout"):
        read_box_file(path)


def test_iou_hand_computed() -> None:
    a = np.array([[0, 0, 10, 10]])
    b = np.array([[5, 0, 15, 10], [20, 20, 30, 30], [0, 0, 10, 10]])
    np.testing.assert_allclose(iou_matrix(a, b), [[50 / 150, 0.0, 1.0]])


def test_box_table_by_frame_groups_in_order() -> None:
    t = BoxTable.build([2, 0, 2, 1], np.arange(16.0).reshape(4, 4))
    groups = dict(t.by_frame())
    assert list(groups) == [0, 1, 2]
    np.testing.assert_array_equal(groups[2].boxes, [[0, 1, 2, 3], [8, 9, 10, 11]])


def test_real_labels_parse(kitti_tracking_dir: Path) -> None:
    t = read_kitti_labels(kitti_tracking_dir / "label_02" / "0000.txt")
    assert t.frame.max() == 153 and "Van" in set(t.cls)


PRCNN_ROW = "0,2,298.3,165.1,458.2,293.4,8.29,1.96,1.81,4.75,-4.57,1.84,13.53,-2.11,-1.78"


def test_negative_frames_are_errors_naming_the_line(tmp_path: Path) -> None:
    path = tmp_path / "labels.txt"
    path.write_text(f"# comment\n{LABEL}\n\n{LABEL.replace('0 3 Car', '-1 3 Car')}\n")
    with pytest.raises(InputFileError, match=r"line 4, field 'frame': -1 is outside 0\.\."):
        read_kitti_labels(path)
    path.write_text(f"{PRCNN_ROW}\n-2{PRCNN_ROW[1:]}\n")
    with pytest.raises(InputFileError, match=r"line 2, field 'frame': -2 is outside"):
        read_pointrcnn(path)
    path.write_text(f"{LABEL.replace('0 3 Car', '0 -2 Car')}\n")
    with pytest.raises(InputFileError, match=r"line 1, field 'track_id': -2 is outside -1\.\."):
        read_kitti_labels(path)


@pytest.mark.parametrize("value", ["1e23", "-2e6", "1e308"])
def test_absurd_box_coordinates_are_errors(tmp_path: Path, value: str) -> None:
    path = tmp_path / "boxes.csv"
    path.write_text(f"frame,left,top,right,bottom\n0,1,2,3,4\n1,1,2,{value},4\n")
    with pytest.raises(InputFileError, match=r"line 3, field 'right'.*not a pixel coordinate"):
        read_box_csv(path)
    path.write_text(PRCNN_ROW.replace("458.2", value) + "\n")
    with pytest.raises(InputFileError, match=r"line 1, field 'x2'"):
        read_pointrcnn(path)


@pytest.mark.parametrize(
    ("name", "text", "field"),
    [
        ("b.csv", "frame,left,top,right,bottom,score\n0,1,2,30,40,inf\n", "score"),
        ("rrc.txt", "0,1,2,30,40,-inf\n", "score"),
        ("det.txt", "1,-1,1,2,29,38,1e400\n", "conf"),
    ],
)
def test_an_infinite_score_is_refused(tmp_path: Path, name: str, text: str, field: str) -> None:
    """An infinite score would pass every ``--score`` threshold; an empty one is unknown."""
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    read = read_rrc if name == "rrc.txt" else read_box_file
    with pytest.raises(InputFileError, match=rf"line \d+, field '{field}': .* a finite number"):
        read(path)


def test_a_coco_score_that_overflows_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "results.json"
    path.write_text('[{"image_id": 0, "category_id": 3, "bbox": [1, 2, 30, 40], "score": 1e400}]')
    with pytest.raises(InputFileError, match=r"field '\[0\].score': 'inf' is not a finite number"):
        read_box_file(path)
