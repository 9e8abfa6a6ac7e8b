"""Calibration files in the forms people have: KITTI, K text, OpenCV YAML/JSON, ROS camera_info."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from slopedist.core.errors import DataMismatchError, InputFileError, MissingInputError
from slopedist.io.calibration import read_calibration, read_intrinsics

K = np.array([[700.0, 0.0, 640.5], [0.0, 650.0, 360.25], [0.0, 0.0, 1.0]])
DIST = np.array([-0.2, 0.05, 0.001, -0.002, 0.01])

ROS_YAML = """image_width: 1280
image_height: 720
camera_name: dashcam
camera_matrix:
  rows: 3
  cols: 3
  data: [700.0, 0.0, 640.5, 0.0, 650.0, 360.25, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.2, 0.05, 0.001, -0.002, 0.01]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
"""


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _check(path: Path, dist: np.ndarray = DIST, size: tuple[int, int] | None = (1280, 720)) -> None:
    intr = read_intrinsics(path)
    np.testing.assert_allclose(intr.K, K)
    np.testing.assert_allclose(intr.dist, dist)
    assert intr.image_size == size


def test_kitti_calib_keeps_fy(tmp_path: Path) -> None:
    p2 = "721.5 0 609.6 44.9 0 700.0 172.9 0.2 0 0 1 0.003"
    path = _write(tmp_path / "calib.txt", f"P0: {p2}\nP2: {p2}\n")
    cal = read_calibration(path, height_m=1.5)
    assert cal.intrinsics.K[0, 0] == 721.5 and cal.intrinsics.K[1, 1] == 700.0
    assert cal.camera.f == 700.0 and cal.camera.c_x == 609.6 and cal.camera.height_m == 1.5
    assert not cal.intrinsics.is_ideal  # fx ≠ fy: boxes must be mapped


def test_k_text_three_lines_with_distortion_line(tmp_path: Path) -> None:
    text = "# K\n700 0 640.5\n0 650 360.25\n0 0 1\n-0.2 0.05 0.001 -0.002 0.01\n"
    _check(_write(tmp_path / "K.txt", text), size=None)
    one_line = _write(tmp_path / "k1.txt", "[700, 0, 640.5, 0, 650, 360.25, 0, 0, 1]\n")
    _check(one_line, dist=np.zeros(0), size=None)


def test_opencv_filestorage_yaml_and_json(tmp_path: Path) -> None:
    for name in ("cam.yaml", "cam.json"):
        fs = cv2.FileStorage(str(tmp_path / name), cv2.FILE_STORAGE_WRITE)
        fs.write("image_width", 1280)
        fs.write("image_height", 720)
        fs.write("camera_matrix", K)
        fs.write("distortion_coefficients", DIST.reshape(1, 5))
        fs.release()
        _check(tmp_path / name)


def test_ros_camera_info_yaml_and_message_dump(tmp_path: Path) -> None:
    _check(_write(tmp_path / "ost.yaml", ROS_YAML))
    msg = {"width": 1280, "height": 720, "K": K.reshape(-1).tolist(), "D": DIST.tolist()}
    _check(_write(tmp_path / "info.json", json.dumps(msg)))
    no_ext = _write(tmp_path / "camera_info", ROS_YAML)  # content, not the name, decides
    _check(no_ext)


def test_ros_equidistant_is_fisheye(tmp_path: Path) -> None:
    text = ROS_YAML.replace("plumb_bob", "equidistant").replace(
        "cols: 5\n  data: [-0.2, 0.05, 0.001, -0.002, 0.01]", "cols: 4\n  data: [0.1, 0.01, 0, 0]"
    )
    intr = read_intrinsics(_write(tmp_path / "fe.yaml", text))
    assert intr.fisheye and intr.dist.tolist() == [0.1, 0.01, 0, 0]


@pytest.mark.parametrize(
    ("name", "text", "line", "field"),
    [
        ("K.txt", "700 0 640\n0 x 360\n0 0 1\n", 2, "K[1]"),
        ("K.txt", "700 0 640\n0 650 360\n", None, "K"),
        ("K.txt", "700 0 640\n0 650 360\n0 0 1\n0.1 0.2 0.3\n", None, "distortion"),
        ("c.yaml", "camera_matrix:\n  data: [1, 2, 3, 4, 5, 6]\n", None, "camera_matrix"),
        (
            "c.yaml",
            ROS_YAML.replace("data: [-0.2, 0.05, 0.001,", "data: [0.001,"),
            None,
            "distortion_coefficients",
        ),
        ("c.yaml", "camera_matrix: [1, 2\nb: 3\n", 2, None),
        ("c.yaml", "image_width: 5\n", None, None),
        ("calib.txt", "P2: 1 2 3\n", 1, "P2"),
        ("K.txt", "-700 0 640\n0 650 360\n0 0 1\n", None, "K"),
        (
            "c.yaml",
            "camera_matrix:\n  data: [700, 0, 640, 0, -650, 360, 0, 0, 1]\n",
            None,
            "camera_matrix",
        ),
    ],
)
def test_errors_name_file_line_field(
    tmp_path: Path, name: str, text: str, line: int | None, field: str | None
) -> None:
    with pytest.raises(InputFileError) as err:
        read_calibration(_write(tmp_path / name, text))
    assert err.value.line == line and err.value.field == field
    assert name in str(err.value)


@pytest.mark.parametrize(
    ("name", "text", "field"),
    [
        ("K.txt", "700 0 0\n0 650 0\n640.5 360.25 1\n", "K"),  # transposed (MATLAB)
        ("K.txt", "1400 0 1281\n0 1300 720.5\n0 0 2\n", "K"),  # not normalised
        ("c.yaml", ROS_YAML.replace("0.0, 0.0, 1.0]", "640.5, 360.25, 1.0]"), "camera_matrix"),
        ("info.json", json.dumps({"K": K.T.reshape(-1).tolist()}), "K"),
    ],
)
def test_k_whose_last_row_is_not_0_0_1_is_refused(
    tmp_path: Path, name: str, text: str, field: str
) -> None:
    """A transposed or unnormalised K was read as if its last row were 0 0 1: a principal
    point of (0, 0) made every distance `ok` and several times too short."""
    with pytest.raises(InputFileError, match="last row must be 0 0 1") as err:
        read_calibration(_write(tmp_path / name, text))
    assert err.value.field == field and name in str(err.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(MissingInputError, match="calibration file not found"):
        read_calibration(tmp_path / "none.yaml")


def test_real_kitti_calibration(kitti_tracking_dir: Path) -> None:
    from slopedist.core.camera import Camera

    path = next(iter(sorted(kitti_tracking_dir.rglob("calib/*.txt"))))
    cal = read_calibration(path)
    assert cal.camera.f == pytest.approx(Camera.from_kitti_calib(path).f)


@pytest.mark.parametrize(
    ("k1", "refused"),
    [(1e6, True), (1000.0, True), (0.3, False), (-0.1, False), (5.0, False), (-28.0, False)],
)
def test_a_lens_model_that_moves_the_image_edge_absurdly_is_refused(
    tmp_path: Path, k1: float, refused: bool
) -> None:
    """k1 = 1000 moves the left edge of a 1242 px image (609.6 px from the principal point)
    to 66 px from it (0.108×): a coefficient in other units, not a lens. Real radial terms
    pass; one whose model folds inside the image (k1 = −28) leaves those points to the boxes'
    ``non_finite_box`` state."""
    path = tmp_path / "k.txt"
    path.write_text(f"721.5 0 609.6\n0 721.5 172.9\n0 0 1\n{k1} 0 0 0\n")
    if refused:
        with pytest.raises(InputFileError, match=r"k.txt, field 'distortion': .* not a lens"):
            read_calibration(path)
    else:
        assert read_calibration(path).camera.f == 721.5


@pytest.mark.parametrize(
    ("size", "message"),
    [
        (
            (300, 200),
            r"k.txt with --image-size 300x200: .* c_x = 609.6 px lies outside .* "
            r"probably for another resolution \(about 1219×346 px",
        ),
        ((5000, 5000), r"k.txt with --image-size 5000x5000: .* c_x = 609.6 px is far from"),
        ((1242, 1000), r"k.txt with --image-size 1242x1000: .* c_y = 172.9 px is far from"),
        ((1242, 375), None),
    ],
)
def test_an_image_size_the_calibration_cannot_belong_to_is_refused(
    tmp_path: Path, size: tuple[int, int], message: str | None
) -> None:
    """A KITTI or K-text calibration (no size of its own) with ``--image-size 5000x5000``: the
    principal point (609.6, 172.9) px is inside the image but nowhere near its centre, so the
    size is not the calibrated images' (the border test would flag no cut box); the frames of
    ``run`` were checked by this rule, a typed size was not."""
    path = _write(tmp_path / "k.txt", "721.5 0 609.6\n0 721.5 172.9\n0 0 1\n")
    if message is None:
        assert read_calibration(path, image_size=size).camera.image_width == size[0]
        return
    with pytest.raises(DataMismatchError, match=message):
        read_calibration(path, image_size=size)


@pytest.mark.parametrize("key", ["R0_rect", "R_rect"])
def test_a_kitti_file_without_its_p_lines_says_so(tmp_path: Path, key: str) -> None:
    """A KITTI calib file lacking its ``P2:`` line (only ``R0_rect``, ``Tr_velo_to_cam``) was read
    as YAML: "not a readable YAML/JSON/XML file: Incorrect indentation"."""
    path = _write(
        tmp_path / "calib.txt",
        f"{key}: 1 0 0 0 1 0 0 0 1\nTr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 0 0\n",
    )
    with pytest.raises(InputFileError, match=rf"calib.txt: no 'P2:' line \(found: {key}, Tr_velo"):
        read_calibration(path)
