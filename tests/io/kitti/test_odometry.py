"""KITTI-odometry-style folders: layout, timestamps, ground truth and bad input."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from slopedist.core.errors import DataMismatchError, InputFileError, MissingInputError
from slopedist.io.kitti.odometry import read_gray_image, read_kitti_odometry
from slopedist.odometry import twoview as tv

P0 = "7.0e+02 0 3.0e+02 0 0 7.0e+02 1.0e+02 0 0 0 1 0"


def make_sequence(
    root: Path,
    n: int = 4,
    size: tuple[int, int] = (320, 200),
    poses: int | None = None,
    calib: str = P0,
) -> Path:
    """A folder with ``n`` grey frames, ``poses`` ground-truth lines (default n) and calib."""
    (root / "image_l").mkdir(parents=True)
    rng = np.random.default_rng(0)
    for k in range(n):
        image = rng.integers(0, 255, (size[1], size[0]), dtype=np.uint8)
        cv2.imwrite(str(root / "image_l" / f"{k:06d}.png"), image)
    lines = []
    for k in range(n if poses is None else poses):
        R = tv.so3_exp(np.radians([0.1 * k, 2.0 * k, 0.0]))
        lines.append(" ".join(f"{v:.9e}" for v in np.c_[R, [0.0, 0.0, k]].ravel()))
    (root / "poses.txt").write_text("\n".join(lines) + "\n")
    (root / "calib.txt").write_text(calib + "\n" + P0 + "\n")
    return root


def test_reads_frames_calibration_and_ground_truth(tmp_path: Path) -> None:
    seq = read_kitti_odometry(make_sequence(tmp_path / "s"))
    assert len(seq) == 4
    assert seq.camera.f == 700.0 and seq.camera.c_x == 300.0 and seq.camera.c_y == 100.0
    assert (seq.camera.image_width, seq.camera.image_height) == (320, 200)
    assert np.allclose(seq.timestamps_s, [0.0, 0.1, 0.2, 0.3])
    assert seq.ground_truth is not None
    expected = tv.so3_exp(np.radians([0.3, 6.0, 0.0]))
    assert np.allclose(seq.ground_truth.R_world_cam[3], expected, atol=1e-8)
    frames = list(seq.frames())
    assert [k for k, _, _ in frames] == [0, 1, 2, 3]
    assert frames[2][2].shape == (200, 320) and frames[2][2].dtype == np.uint8


def test_named_calibration_and_times_file(tmp_path: Path) -> None:
    root = make_sequence(tmp_path / "s", calib="P0: " + P0)
    (root / "times.txt").write_text("0.0\n0.103\n0.207\n0.31\n")
    seq = read_kitti_odometry(root)
    assert seq.camera.f == 700.0
    assert np.allclose(seq.timestamps_s, [0.0, 0.103, 0.207, 0.31])
    assert seq.ground_truth is not None
    assert np.allclose(seq.ground_truth.timestamps_s, seq.timestamps_s)


def test_extra_poses_are_ignored(tmp_path: Path) -> None:
    seq = read_kitti_odometry(make_sequence(tmp_path / "s", poses=6))
    assert seq.ground_truth is not None and len(seq.ground_truth) == 4


def test_a_gap_in_the_numbering_is_a_dropped_frame(tmp_path: Path) -> None:
    """Frame 000002.png missing: frame 000003.png keeps line 3 of poses.txt and times.txt (it
    was paired with line 2, and every later frame with the line before its own)."""
    root = make_sequence(tmp_path / "s", n=5)
    (root / "times.txt").write_text("0.0\n0.1\n0.2\n0.3\n0.4\n")
    (root / "image_l" / "000002.png").unlink()
    seq = read_kitti_odometry(root)
    assert [p.name for p in seq.image_paths] == [
        "000000.png",
        "000001.png",
        "000003.png",
        "000004.png",
    ]
    assert np.allclose(seq.timestamps_s, [0.0, 0.1, 0.3, 0.4])
    assert seq.ground_truth is not None
    assert np.allclose(seq.ground_truth.R_world_cam[2], tv.so3_exp(np.radians([0.3, 6.0, 0.0])))
    (root / "poses.txt").write_text("\n".join((root / "poses.txt").read_text().split("\n")[:4]))
    with pytest.raises(DataMismatchError, match="4 poses for 5 frames"):
        read_kitti_odometry(root)


def test_a_missing_first_frame_keeps_the_numbering(tmp_path: Path) -> None:
    """000000.png missing: 000001.png is line 1 of poses.txt and times.txt (it was paired with
    line 0, every later frame with the line before its own)."""
    root = make_sequence(tmp_path / "s", n=5)
    (root / "times.txt").write_text("0.0\n0.1\n0.2\n0.3\n0.4\n")
    (root / "image_l" / "000000.png").unlink()
    seq = read_kitti_odometry(root)
    assert np.allclose(seq.timestamps_s, [0.1, 0.2, 0.3, 0.4])
    assert seq.ground_truth is not None
    for k in range(4):
        expected = tv.so3_exp(np.radians([0.1 * (k + 1), 2.0 * (k + 1), 0.0]))
        assert np.allclose(seq.ground_truth.R_world_cam[k], expected, atol=1e-8)
    (root / "times.txt").unlink()
    assert np.allclose(read_kitti_odometry(root).timestamps_s, [0.1, 0.2, 0.3, 0.4])


@pytest.mark.parametrize("name", ["poses.txt", "times.txt"])
def test_frames_numbered_from_above_0_need_lines_up_to_their_numbers(
    tmp_path: Path, name: str
) -> None:
    """Frames 000002–000004 with three poses (or times): line k is frame k, so the file is short
    (not read as starting at 000002.png), and the error says which reading was not taken."""
    root = make_sequence(tmp_path / "s", n=5)
    (root / "times.txt").write_text("0.0\n0.1\n0.2\n0.3\n0.4\n")
    for k in (0, 1):
        (root / "image_l" / f"{k:06d}.png").unlink()
    lines = (root / name).read_text().splitlines()[:3]
    (root / name).write_text("\n".join(lines) + "\n")
    what = "poses" if name == "poses.txt" else "timestamps"
    message = f"has 3 {what} for 5 frames .* numbered 000002.png to 000004.png .* frame numbered k"
    with pytest.raises(DataMismatchError, match=message):
        read_kitti_odometry(root)


@pytest.mark.parametrize(
    ("change", "error", "message"),
    [
        (
            lambda r: (r / "poses.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n"),
            DataMismatchError,
            "1 poses for 4 frames",
        ),
        (lambda r: (r / "poses.txt").unlink(), MissingInputError, "ground-truth poses"),
        (
            lambda r: (r / "calib.txt").write_text("7e2 0 3e2 0 0 7e2 1e2 0 0 0 1\n"),
            InputFileError,
            "line 1",
        ),
        (
            lambda r: (r / "calib.txt").write_text(P0.replace("3.0e+02", "9.0e+02") + "\n"),
            DataMismatchError,
            "principal point",
        ),
        (lambda r: (r / "calib.txt").unlink(), MissingInputError, "calib"),
        (lambda r: (r / "times.txt").write_text("0\n0.1\n0.1\n0.3\n"), InputFileError, "line 3"),
        (
            lambda r: (r / "times.txt").write_text("0\n0.1\n"),
            DataMismatchError,
            "2 timestamps for 4 frames",
        ),
        (
            lambda r: (r / "image_l" / "000000.png").write_bytes(b"not a png"),
            InputFileError,
            "cannot be decoded",
        ),
    ],
)
def test_bad_input_is_reported(
    tmp_path: Path, change: Callable[[Path], object], error: type[Exception], message: str
) -> None:
    root = make_sequence(tmp_path / "s")
    change(root)
    with pytest.raises(error, match=message):
        read_kitti_odometry(root)


def test_missing_folders(tmp_path: Path) -> None:
    with pytest.raises(MissingInputError, match="sequence folder not found"):
        read_kitti_odometry(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(MissingInputError, match="no image_l/"):
        read_kitti_odometry(tmp_path / "empty")
    (tmp_path / "empty" / "image_l").mkdir()
    with pytest.raises(MissingInputError, match="no image files"):
        read_kitti_odometry(tmp_path / "empty")


def test_poses_optional_when_not_required(tmp_path: Path) -> None:
    root = make_sequence(tmp_path / "s")
    (root / "poses.txt").unlink()
    assert read_kitti_odometry(root, require_poses=False).ground_truth is None


def test_read_gray_image_errors(tmp_path: Path) -> None:
    with pytest.raises(MissingInputError):
        read_gray_image(tmp_path / "x.png")


@pytest.mark.parametrize(
    ("sequence", "size"), [("seq06_000-050", (1226, 370)), ("unknown_000-050", (1241, 376))]
)
def test_real_sequences(kitti_odometry_dir: Path, sequence: str, size: tuple[int, int]) -> None:
    seq = read_kitti_odometry(kitti_odometry_dir / sequence)
    assert len(seq) == 51
    assert (seq.camera.image_width, seq.camera.image_height) == size
    assert seq.ground_truth is not None and len(seq.ground_truth) == 51
    assert np.allclose(seq.ground_truth.R_world_cam[0], np.eye(3), atol=1e-6)
