"""Strict text reading: every text reader names file and line of a bad byte, and no mutation of
a valid file ends in anything but a valid result or a SlopedistError."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from slopedist.core.camera import Camera, read_kitti_calib
from slopedist.core.errors import InputFileError, MissingInputError, SlopedistError
from slopedist.core.limits import MAX_INDEX
from slopedist.core.textfiles import (
    MAX_LINE_BYTES,
    CsvRows,
    decoded_lines,
    numbered_lines,
    read_json,
    read_text,
)
from slopedist.io.calibration import read_intrinsics
from slopedist.io.detections import (
    BoxTable,
    read_box_csv,
    read_box_file,
    read_kitti_labels,
    read_pointrcnn,
)
from slopedist.io.detections.formats import read_coco, read_mot
from slopedist.io.frames import read_timestamps
from slopedist.io.intrinsics import Intrinsics
from slopedist.odometry import read_kitti_poses, read_oxts_rotations, read_pose_file, read_tum_poses

CALIB = "\n".join(
    [
        "P0: 721.5 0 609.5 0 0 721.5 172.8 0 0 0 1 0",
        "P2: 721.5 0 609.5 44.8 0 721.5 172.8 0.2 0 0 1 0.003",
        "R0_rect: 1 0 0 0 1 0 0 0 1",
        "Tr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 0 0",
        "Tr_imu_to_velo: 1 0 0 0 0 1 0 0 0 0 1 0",
    ]
)
LABELS = "\n".join(
    [
        "0 3 Car 0 1 -1.79 296.74 161.75 455.23 292.37 2.0 1.82 4.43 -4.55 1.86 13.41 -2.12",
        "1 -1 DontCare -1 -1 -10 100 150 200 190 -1 -1 -1 -1000 -1000 -1000 -10",
        "2 3 Car 0 0 -1.70 300.00 160.00 460.00 295.00 2.0 1.82 4.43 -4.50 1.86 13.0 -2.10",
    ]
)
PRCNN = "\n".join(
    [
        "0,2,298.3,165.1,458.2,293.4,8.29,1.96,1.81,4.75,-4.57,1.84,13.53,-2.11,-1.78",
        "1,2,1050.4,177.0,1241.0,239.3,1.31,1.49,1.62,4.06,13.66,1.60,18.41,-0.10,-0.73",
        "2,2,364.7,137.8,453.8,172.5,-0.45,1.47,1.59,3.86,-9.09,-0.01,32.82,-1.02,-0.75",
    ]
)
BOX_CSV = "\n".join(
    [
        "frame,left,top,right,bottom,track_id,score,class,gt_distance_m",
        "0,296.7,161.7,455.2,292.3,3,0.9,Car,13.4",
        "1,300,160,460,295,3,0.8,Van,",
        "2,10,20,30,40,,,,",
    ]
)
KITTI_POSES = "\n".join(
    [
        "1 0 0 0 0 1 0 0 0 0 1 0",
        "1 0 0 0.1 0 1 0 0 0 0 1 1.0",
        "0.99995 0 0.01 0.2 0 1 0 0 -0.01 0 0.99995 2.0",
    ]
)
TUM_POSES = "\n".join(
    [
        "0.0 0 0 0 0 0 0 1",
        "0.1 0 0 1 0 0.005 0 0.9999875",
        "0.2 0 0 2 0 0.010 0 0.99995",
    ]
)
TIMES = "\n".join(["# seconds", "0.0", "0.1", "0.2", "0.31"])
MOT = "\n".join(
    ["1,-1,296.7,161.7,158.5,130.6,0.9", "2,-1,300,160,160,135,0.8", "3,-1,10,20,20,20,0.5"]
)
COCO = "\n".join(
    [
        "[",
        '{"image_id": 0, "category_id": 3, "bbox": [296.7, 161.7, 158.5, 130.6], "score": 0.9},',
        '{"image_id": 1, "category_id": 3, "bbox": [300, 160, 160, 135], "score": 0.8},',
        '{"image_id": 2, "category_id": 3, "bbox": [10, 20, 20, 20], "score": 0.5}',
        "]",
    ]
)
K_TEXT = "\n".join(["721.5 0 609.5", "0 721.5 172.8", "0 0 1", "0.01 -0.02 0 0 0"])


def _calib_camera(path: Path) -> Any:
    return Camera.from_kitti_calib(path)


def _oxts(path: Path) -> Any:
    return read_oxts_rotations(path)


READERS: dict[str, tuple[str, Callable[[Path], Any]]] = {
    "calib": (CALIB, read_kitti_calib),
    "calib camera": (CALIB, _calib_camera),
    "kitti labels": (LABELS, read_kitti_labels),
    "pointrcnn": (PRCNN, read_pointrcnn),
    "box csv": (BOX_CSV, read_box_csv),
    "box file (labels)": (LABELS, read_box_file),
    "box file (pointrcnn)": (PRCNN, read_box_file),
    "box file (csv)": (BOX_CSV, read_box_file),
    "kitti poses": (KITTI_POSES, read_kitti_poses),
    "tum poses": (TUM_POSES, read_tum_poses),
    "oxts poses": (TUM_POSES, _oxts),
    "pose file (auto)": (TUM_POSES, read_pose_file),
    "timestamps": (TIMES, read_timestamps),
    "mot": (MOT, read_mot),
    "coco json": (COCO, read_coco),
    "intrinsics (kitti)": (CALIB, read_intrinsics),
    "intrinsics (K text)": (K_TEXT, read_intrinsics),
}


def _write(folder: Path, data: bytes) -> Path:
    path = folder / "input.txt"
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("name", sorted(READERS))
def test_every_reader_reads_its_valid_sample(tmp_path: Path, name: str) -> None:
    text, reader = READERS[name]
    result = reader(_write(tmp_path, text.encode() + b"\n"))
    assert result is not None
    if isinstance(result, BoxTable):
        assert len(result) == 3


@pytest.mark.parametrize("name", sorted(READERS))
@pytest.mark.parametrize("bad", [b"\xff", b"\xe9", b"\xc3("])
def test_every_reader_names_the_line_of_a_non_utf8_byte(
    tmp_path: Path, name: str, bad: bytes
) -> None:
    text, reader = READERS[name]
    lines = text.encode().split(b"\n")
    lines[1] = lines[1][:3] + bad + lines[1][3:]
    path = _write(tmp_path, b"\n".join(lines) + b"\n")
    with pytest.raises(InputFileError, match=r"input\.txt, line 2: not UTF-8 text \(byte 0x"):
        reader(path)


@pytest.mark.parametrize("name", sorted(READERS))
def test_every_reader_rejects_an_empty_file_or_missing_file(tmp_path: Path, name: str) -> None:
    _, reader = READERS[name]
    with pytest.raises(MissingInputError):
        reader(tmp_path / "absent.txt")
    try:
        result = reader(_write(tmp_path, b""))
    except SlopedistError:
        return
    assert isinstance(result, BoxTable) and len(result) == 0


def test_decoded_lines_drops_a_bom_and_counts_every_line(tmp_path: Path) -> None:
    path = _write(tmp_path, b"\xef\xbb\xbf# head\r\n\r\n  x 1 \r\n#c\ny\n")
    assert next(iter(decoded_lines(path, "t"))) == "# head\r\n"
    assert list(numbered_lines(path, "t")) == [(3, "x 1"), (5, "y")]
    assert next(iter(numbered_lines(path, "t", comment=None))) == (1, "# head")
    assert read_text(path, "t").startswith("# head")


def test_an_overlong_line_is_an_error_not_a_memory_hog(tmp_path: Path) -> None:
    path = _write(tmp_path, b"ok\n" + b"1" * (MAX_LINE_BYTES + 10) + b"\n")
    with pytest.raises(InputFileError, match=r"line 2: line longer than"):
        list(decoded_lines(path, "t"))


def test_csv_rows_real_lines_and_bad_csv(tmp_path: Path) -> None:
    path = _write(tmp_path, b'a, b\n1,"x\ny"\n\n2,z, \n3\n')
    rows = CsvRows(path, "t")
    assert rows.header == ["a", "b"]
    assert list(rows) == [
        (3, {"a": "1", "b": "x\ny"}),
        (5, {"a": "2", "b": "z"}),  # an empty field past the header (a trailing comma)
        (6, {"a": "3", "b": None}),
    ]
    shifted = _write(tmp_path, b"frame,left,top,right,bottom,class\n0,1,2,3,4,Car,van\n")
    with pytest.raises(InputFileError, match=r"line 2: row has 7 fields, the header has 6"):
        read_box_csv(shifted)
    twice = _write(tmp_path, b"frame,left,top,right,bottom,left\n0,1,2,3,4,5\n")
    with pytest.raises(InputFileError, match=r"line 1: column\(s\) left named twice"):
        read_box_csv(twice)
    big = _write(
        tmp_path, b"frame,left,top,right,bottom\n0,1,2,3,4\n0," + b"9" * 1_000_000 + b",2,3,4\n"
    )
    with pytest.raises(InputFileError, match=r"line 3: not a valid CSV row \(field larger"):
        read_box_csv(big)
    nul = _write(tmp_path, b"frame,left,top,right,bottom\n0,1,2,3,4\x00\n")
    try:
        read_box_csv(nul)
    except InputFileError as exc:
        assert "line 2" in str(exc)


@pytest.mark.parametrize("tok", ["1e308", "nan", "inf", "-inf", "1e10", "99999999999999999999"])
@pytest.mark.parametrize("field", ["frame", "track_id"])
def test_huge_or_nan_ids_are_clear_errors(tmp_path: Path, tok: str, field: str) -> None:
    path = _write(tmp_path, b"frame,left,top,right,bottom,track_id\n0,1,2,3,4,5\n0,1,2,3,4,5\n")
    text = path.read_text().splitlines()
    cells = text[2].split(",")
    cells[0 if field == "frame" else 5] = tok
    text[2] = ",".join(cells)
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(InputFileError, match=rf"line 3, field '{field}'"):
        read_box_csv(path)
    labels = LABELS.split("\n")
    cells = labels[1].split()
    cells[0 if field == "frame" else 1] = tok
    labels[1] = " ".join(cells)
    path.write_text("\n".join(labels) + "\n")
    with pytest.raises(InputFileError, match=rf"line 2, field '{field}'"):
        read_kitti_labels(path)


def test_largest_id_is_accepted(tmp_path: Path) -> None:
    path = _write(
        tmp_path,
        f"frame,left,top,right,bottom,track_id\n{MAX_INDEX},1,2,3,4,{MAX_INDEX}\n".encode(),
    )
    assert read_box_csv(path).frame[0] == MAX_INDEX


MUTATIONS = st.sampled_from(["truncate", "bytes", "token", "drop_field", "add_field", "dup_line"])
BAD_TOKENS = st.sampled_from(
    ["nan", "inf", "-inf", "1e308", "-1e308", "1e-320", "", "-1", "0", "x", "1e23", "'", '"', ","]
)
FUZZ = settings(
    max_examples=int(os.environ.get("SLOPEDIST_FUZZ_EXAMPLES", "150")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)


def _mutate(data: bytes, kind: str, draw: st.DrawFn) -> bytes:
    lines = data.split(b"\n")
    i = draw(st.integers(0, len(lines) - 1))
    if kind == "truncate":
        return data[: draw(st.integers(0, len(data)))]
    if kind == "bytes":
        pos = draw(st.integers(0, len(data) - 1))
        junk = draw(st.binary(min_size=1, max_size=4))
        return data[:pos] + junk + data[pos + 1 :]
    sep = b"," if b"," in lines[i] else b" "
    cells = lines[i].split(sep)
    j = draw(st.integers(0, len(cells) - 1))
    if kind == "token":
        cells[j] = draw(BAD_TOKENS).encode()
    elif kind == "drop_field":
        del cells[j]
    elif kind == "add_field":
        cells.insert(j, b"1")
    else:
        lines.insert(i, lines[i])
        return b"\n".join(lines)
    lines[i] = sep.join(cells)
    return b"\n".join(lines)


@st.composite
def mutated_inputs(draw: st.DrawFn) -> tuple[str, bytes]:
    name = draw(st.sampled_from(sorted(READERS)))
    data = READERS[name][0].encode() + b"\n"
    for _ in range(draw(st.integers(1, 3))):
        data = _mutate(data, draw(MUTATIONS), draw) if data else data
    return name, data


def _check_valid(result: Any) -> None:
    if isinstance(result, BoxTable):
        assert np.all(result.frame >= 0) and np.all(result.frame <= MAX_INDEX)
        assert np.all(result.track_id >= -1)
        finite = np.isfinite(result.boxes)
        assert np.all(np.abs(result.boxes[finite]) <= 1e6)
    elif isinstance(result, dict):
        assert all(np.all(np.isfinite(v)) for v in result.values())
    elif isinstance(result, Intrinsics):
        assert np.all(np.isfinite(result.K))
    elif isinstance(result, Camera):
        assert np.isfinite([result.f, result.c_x, result.c_y]).all()
    elif isinstance(result, np.ndarray):
        assert np.all(np.isfinite(result)) and np.all(np.diff(result) > 0)
    else:  # a RotationTrack
        assert np.all(np.isfinite(result.R_world_cam))


@FUZZ
@given(case=mutated_inputs())
def test_mutated_inputs_give_a_valid_result_or_a_slopedist_error(case: tuple[str, bytes]) -> None:
    name, data = case
    with tempfile.TemporaryDirectory() as folder:
        path = _write(Path(folder), data)
        try:
            result = READERS[name][1](path)
        except SlopedistError:
            return
        _check_valid(result)


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (b'{"a": 1,\n "b": }\n', r"line 2: not valid JSON"),
        (b'{"a": NaN}\n', r"not valid JSON \(NaN is not a JSON number\)"),
        (b'{"a": "caf\xe9"}\n', r"line 1: not UTF-8"),
        (b"[" * 100_000 + b"]" * 100_000, r"not valid JSON"),
    ],
)
def test_read_json_errors_name_the_line(tmp_path: Path, data: bytes, match: str) -> None:
    with pytest.raises(InputFileError, match=match):
        read_json(_write(tmp_path, data), "run summary")


def test_read_json_reads_strict_json(tmp_path: Path) -> None:
    assert read_json(_write(tmp_path, b'\xef\xbb\xbf{"a": [1, null]}'), "t") == {"a": [1, None]}
