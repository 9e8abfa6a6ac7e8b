"""Depth files: KITTI depth PNG and .npy readers, the per-frame folder source, LiDAR maps."""

from __future__ import annotations

import struct
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from slopedist.core.camera import Camera, read_kitti_calib
from slopedist.core.errors import (
    ConfigurationError,
    DataMismatchError,
    InputFileError,
    MissingInputError,
)
from slopedist.estimators import DepthMapEstimator, FrameInput
from slopedist.io.depth import (
    FileDepthSource,
    read_depth_file,
    read_kitti_depth_png,
    read_npy_depth,
    write_kitti_depth_png,
)
from slopedist.io.detections.boxes import BoxTable
from tests.conftest import shared_data_path


def test_kitti_png_is_uint16_over_256_with_zero_and_its_largest_value_as_no_value(
    tmp_path: Path,
) -> None:
    """65535 (255.996 m) is what writers clip every depth beyond the format to: it was read as
    a depth, which the depth-map method then capped to 80 m and marked ``ok``."""
    raw = np.array([[0, 256, 2560], [65535, 1, 65534]], dtype=np.uint16)
    cv2.imwrite(str(tmp_path / "0000000000.png"), raw)
    d = read_kitti_depth_png(tmp_path / "0000000000.png")
    assert d.dtype == np.float32
    np.testing.assert_allclose(d[0, 1:], [1.0, 10.0])
    np.testing.assert_allclose(d[1, 1:], [1 / 256, 65534 / 256])
    assert np.isnan(d[0, 0]) and np.isnan(d[1, 0])
    write_kitti_depth_png(tmp_path / "far.png", np.full((2, 2), 300.0))  # beyond the format
    assert np.isnan(read_kitti_depth_png(tmp_path / "far.png")).all()


@settings(max_examples=30, deadline=None)
@given(arrays(np.float64, (7, 9), elements=st.one_of(st.just(np.nan), st.floats(0.01, 255.0))))
def test_png_round_trip_within_quantisation(
    tmp_path_factory: pytest.TempPathFactory, depth: np.ndarray
) -> None:
    path = tmp_path_factory.mktemp("png") / "1.png"
    write_kitti_depth_png(path, depth)
    back = read_kitti_depth_png(path)
    valid = np.isfinite(depth)
    assert np.array_equal(np.isfinite(back), valid)
    np.testing.assert_allclose(back[valid], depth[valid], atol=0.5 / 256 + 1e-6)


def test_png_of_wrong_type_is_named(tmp_path: Path) -> None:
    path = tmp_path / "5.png"
    cv2.imwrite(str(path), np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(InputFileError, match=r"5\.png.*16-bit.*3 channel"):
        read_kitti_depth_png(path)


def test_corrupt_png_and_npy_are_input_errors(tmp_path: Path) -> None:
    (tmp_path / "1.png").write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    (tmp_path / "2.npy").write_bytes(b"not numpy at all")
    with pytest.raises(InputFileError, match=r"1\.png.*does not decode"):
        read_depth_file(tmp_path / "1.png")
    with pytest.raises(InputFileError, match=r"2\.npy.*not a readable"):
        read_depth_file(tmp_path / "2.npy")
    with pytest.raises(MissingInputError, match=r"3\.npy"):
        read_depth_file(tmp_path / "3.npy")
    with pytest.raises(ConfigurationError, match=r"\.tif"):
        read_depth_file(tmp_path / "4.tif")


def test_npy_values_and_shape_checks(tmp_path: Path) -> None:
    np.save(tmp_path / "0.npy", np.array([[1.5, -1.0], [np.inf, 0.0]]))
    d = read_npy_depth(tmp_path / "0.npy")
    assert d[0, 0] == pytest.approx(1.5)
    assert np.isnan(d[0, 1]) and np.isnan(d[1, 0]) and np.isnan(d[1, 1])
    np.save(tmp_path / "1.npy", np.ones((2, 2, 2)))
    with pytest.raises(InputFileError, match="2-D"):
        read_npy_depth(tmp_path / "1.npy")
    np.save(tmp_path / "2.npy", np.array([["a", "b"]]))
    with pytest.raises(InputFileError, match="dtype"):
        read_npy_depth(tmp_path / "2.npy")


def test_folder_source_indexes_by_frame_number(tmp_path: Path) -> None:
    write_kitti_depth_png(tmp_path / "0000000003.png", np.full((4, 6), 12.0))
    np.save(tmp_path / "000007.npy", np.full((4, 6), 30.0, np.float32))
    (tmp_path / "notes.txt").write_text("ignored")
    src = FileDepthSource(tmp_path, expected_shape=(4, 6))
    assert sorted(src.files) == [3, 7]
    d3, d7 = src.depth(3), src.depth(7)
    assert d3 is not None and d7 is not None
    assert float(d3[0, 0]) == 12.0 and float(d7[2, 2]) == 30.0
    assert src.calls == 2 and src.seconds > 0
    with pytest.raises(MissingInputError, match=r"frame 4 .*3\.\.7"):
        src.depth(4)
    assert FileDepthSource(tmp_path, missing_ok=True).depth(4) is None
    with pytest.raises(DataMismatchError, match=r"6×4 pixels but the image is 8×4"):
        FileDepthSource(tmp_path, expected_shape=(4, 8)).depth(3)


def test_folder_errors(tmp_path: Path) -> None:
    with pytest.raises(MissingInputError, match="not found"):
        FileDepthSource(tmp_path / "nope")
    with pytest.raises(MissingInputError, match="no depth files"):
        FileDepthSource(tmp_path)
    write_kitti_depth_png(tmp_path / "5.png", np.ones((2, 2)))
    np.save(tmp_path / "000005.npy", np.ones((2, 2)))
    with pytest.raises(ConfigurationError, match="frame 5 has two depth files"):
        FileDepthSource(tmp_path)


# --- real data: LiDAR of kitti_raw_lead projected into cam 2 -------------------------------------

LEAD_FRAMES = (0, 40, 77)


def _lidar_depth(root: Path, k: int, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Sparse cam-2 depth map of frame k (nearest point per pixel), and the lead car's box and
    LiDAR distance from the points in the ego lane (|y| < 0.9 m, above the road, 2–25 m ahead).

    A minimal projection (``P2 · R0_rect · Tr_velo_to_cam · X``) written for this test.
    """
    calib = read_kitti_calib(root / "calib.txt")
    P2 = calib["P2"].reshape(3, 4)
    R0 = np.eye(4)
    R0[:3, :3] = calib["R0_rect"].reshape(3, 3)
    Tr = np.eye(4)
    Tr[:3, :] = calib["Tr_velo_to_cam"].reshape(3, 4)
    pts = np.fromfile(root / "velodyne_front" / f"{k:010d}.bin", np.float32).reshape(-1, 4)
    p = (P2 @ R0 @ Tr @ np.c_[pts[:, :3], np.ones(len(pts))].T).T
    z = p[:, 2]
    u, v = p[:, 0] / z, p[:, 1] / z
    h, w = shape
    inside = (z > 0.5) & (u >= 0) & (u < w - 0.5) & (v >= 0) & (v < h - 0.5)
    depth = np.full(shape, np.inf)
    rows, cols = np.rint(v[inside]).astype(int), np.rint(u[inside]).astype(int)
    np.minimum.at(depth, (rows, cols), z[inside])
    depth[~np.isfinite(depth)] = np.nan
    lane = (
        inside & (np.abs(pts[:, 1]) < 0.9) & (pts[:, 2] > -1.4) & (pts[:, 0] > 2) & (pts[:, 0] < 25)
    )
    near = lane & (z < z[lane].min() + 2.0)
    box = np.array([u[near].min(), v[near].min(), u[near].max(), v[near].max()])
    return depth, np.r_[box, np.median(z[near])]


@pytest.mark.kitti
def test_lidar_depth_png_gives_the_lead_car_distance(tmp_path: Path) -> None:
    root = shared_data_path("kitti_raw_lead")
    image = cv2.imread(str(root / "image_02" / "0000000000.png"))
    shape = image.shape[:2]
    camera = Camera.from_kitti_calib(root / "calib.txt").with_image_size(shape[1], shape[0])
    truth, boxes = [], []
    for k in LEAD_FRAMES:
        depth, box_and_z = _lidar_depth(root, k, shape)
        write_kitti_depth_png(tmp_path / f"{k:010d}.png", depth)
        boxes.append(box_and_z[:4])
        truth.append(box_and_z[4])
    source = FileDepthSource(tmp_path, expected_shape=shape)
    est = DepthMapEstimator(camera, sample="lower")
    got = []
    for k, box in zip(LEAD_FRAMES, boxes):
        frame = FrameInput(
            k, 0.1 * k, float("nan"), BoxTable.build([k], box[None]), depth_m=source.depth(k)
        )
        out = est.estimate(frame)
        assert out.reason[0] == ""
        got.append(out.distance_m[0])
    # README of the data: the lead car closes from about 8 m to about 4.4 m.
    assert 7.0 < got[0] < 9.0 and 3.8 < got[-1] < 5.0
    np.testing.assert_allclose(got, truth, atol=0.3)


def _npy_with_header(path: Path, header: str) -> Path:
    text = header.encode("latin1")
    pad = 64 - (10 + len(text) + 1) % 64
    path.write_bytes(
        b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text) + pad + 1) + text + b" " * pad + b"\n"
    )
    return path


@pytest.mark.parametrize(
    ("header", "match"),
    [
        ("{'descr': '<f8', 'fortran_order': False, 'shape': (100000, 100000), }", "over the limit"),
        ("{'descr': '<f8', 'fortran_order': False, 'shape': (10, 10, 10), }", "2-D"),
        (
            "{'descr': '|O', 'fortran_order': False, 'shape': (2, 2), }",
            "not a readable|float metres",
        ),
        ("{'descr': '<f8', 'fortran_order': False, 'shape': (2, 2), }", "not a readable"),
        ("{'descr': '<f8', 'shape': (1e308, 2), }", "not a readable"),
    ],
)
def test_npy_header_is_checked_before_loading(tmp_path: Path, header: str, match: str) -> None:
    path = _npy_with_header(tmp_path / "000000.npy", header)  # header only, no data
    with pytest.raises(InputFileError, match=match):
        read_npy_depth(path)


def test_npy_limit_is_configurable(tmp_path: Path) -> None:
    np.save(tmp_path / "0.npy", np.ones((30, 40)))
    assert read_npy_depth(tmp_path / "0.npy").shape == (30, 40)
    with pytest.raises(InputFileError, match=r"40×30 depth map, over the limit"):
        read_npy_depth(tmp_path / "0.npy", max_pixels=1000)
