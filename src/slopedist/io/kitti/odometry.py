"""KITTI-odometry-style sequence folders: grey frames, ground-truth poses, calibration.

Layout of one sequence folder::

    image_l/000000.png ...   grey frames of the left camera (cam 0), in name order
    poses.txt                ground truth, one row-major 3×4 camera-to-world [R | t] per line
    calib.txt                first line P0 (12 numbers, with or without a ``P0:`` name)
    times.txt                optional: one timestamp in seconds per frame

When every frame's name is a number (``000020.png``), the number is the frame: its pose and
timestamp are line 20 of ``poses.txt`` and ``times.txt`` (KITTI's numbering, line 0 = frame
``000000``), so a file missing from the numbering, the first one included, is a dropped frame,
not a shift of every later frame against its ground truth. Other names are frames 0, 1, ... in
name order. Without ``times.txt`` frame k has timestamp ``k × 0.1 s`` (KITTI records at 10 Hz).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.core.errors import DataMismatchError, InputFileError, MissingInputError
from slopedist.core.textfiles import numbered_lines
from slopedist.io.images import read_image_file
from slopedist.odometry.base import RotationTrack
from slopedist.odometry.posefiles import KITTI_FRAME_PERIOD_S, read_kitti_poses

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm")


@dataclass(frozen=True)
class KittiOdometrySequence:
    """One KITTI-odometry-style sequence.

    Attributes:
        root: the sequence folder.
        camera: intrinsics of ``P0``, with the image size of the first frame.
        image_paths: frame files in time order.
        timestamps_s: ``(N,)`` seconds of each file of ``image_paths``, increasing.
        ground_truth: camera-to-world rotations relative to the first frame, or None when the
            folder has no ``poses.txt``.
    """

    root: Path
    camera: Camera
    image_paths: tuple[Path, ...]
    timestamps_s: NDArray[np.float64]
    ground_truth: RotationTrack | None

    def __len__(self) -> int:
        return len(self.image_paths)

    def frames(self) -> Iterator[tuple[int, float, NDArray[np.uint8]]]:
        """Yield ``(index, timestamp_s, grey image)`` in time order, decoding one at a time."""
        for k, path in enumerate(self.image_paths):
            yield k, float(self.timestamps_s[k]), read_gray_image(path)


def read_gray_image(path: str | Path) -> NDArray[np.uint8]:
    """Decode an image file as 8-bit grey ``(H, W)``.

    Raises:
        MissingInputError: the file does not exist.
        InputFileError: it cannot be decoded as an image.
    """
    image = read_image_file(path, cv2.IMREAD_GRAYSCALE, "image", "cannot be decoded as an image")
    return np.asarray(image, dtype=np.uint8)


def _read_times(path: Path) -> NDArray[np.float64]:
    values: list[float] = []
    for lineno, line in numbered_lines(path, "times file", comment=None):
        try:
            value = float(line)
        except ValueError:
            raise InputFileError(
                path, f"'{line}' is not a number", line=lineno, field="time"
            ) from None
        if not np.isfinite(value):
            raise InputFileError(path, "non-finite time", line=lineno, field="time")
        if values and value <= values[-1]:
            raise InputFileError(
                path, f"time {value} s does not follow {values[-1]} s", line=lineno, field="time"
            )
        values.append(value)
    return np.asarray(values)


def _frame_numbers(paths: tuple[Path, ...]) -> tuple[tuple[Path, ...], NDArray[np.intp]]:
    """``paths`` in frame order and each one's frame (its line in ``poses.txt`` and
    ``times.txt``): the number in its name when every name is a number (ASCII digits), else its
    position in name order."""
    if not all(p.stem.isascii() and p.stem.isdigit() for p in paths):
        return paths, np.arange(len(paths))
    numbered = sorted(paths, key=lambda p: (int(p.stem), p.name))
    numbers = np.array([int(p.stem) for p in numbered])
    if np.any(np.diff(numbers) == 0):
        k = int(np.argmax(np.diff(numbers) == 0))
        raise InputFileError(
            numbered[k + 1], f"frame number {numbers[k]} also used by {numbered[k].name}"
        )
    return tuple(numbered), numbers


def _too_few_lines(
    path: Path, lines: int, what: str, paths: tuple[Path, ...], index: NDArray[np.intp]
) -> str:
    """The error for a ``poses.txt`` or ``times.txt`` with fewer lines than the frames need;
    when the frames are numbered from above 0 and the lines would cover them counted from the
    first file, say that this reading is not taken (line k is the frame numbered k)."""
    first, last = int(index[0]), int(index[-1])
    message = f"{path} has {lines} {what} for {last + 1} frames in {paths[0].parent}"
    if first > 0 and lines >= last - first + 1:
        message += (
            f": the frames are numbered {paths[0].name} to {paths[-1].name} and line k is the "
            f"frame numbered k (line 0 = frame 0); if line 0 is {paths[0].name}, number the "
            "frames from 0"
        )
    return message


def read_kitti_odometry(
    root: str | Path, frame_period_s: float = KITTI_FRAME_PERIOD_S, require_poses: bool = True
) -> KittiOdometrySequence:
    """Open a KITTI-odometry-style sequence folder (see the module docstring for the layout).

    Frames are listed, not decoded; the first frame is decoded to learn the image size. A
    numbered frame file is paired with the line of its number in ``poses.txt`` and
    ``times.txt``: a gap in the numbering, also before the first file, is dropped frames.

    Raises:
        MissingInputError: the folder, ``image_l/``, its frames, ``calib.txt`` or (when
            ``require_poses``) ``poses.txt`` is missing.
        InputFileError: a malformed line in ``calib.txt``, ``poses.txt`` or ``times.txt``, or
            two frame files with one number (``5.png``, ``005.png``).
        DataMismatchError: fewer poses or timestamps than frames, or a principal point outside
            the frames.
    """
    root = Path(root)
    if not root.is_dir():
        raise MissingInputError(f"sequence folder not found: {root}")
    image_dir = root / "image_l"
    if not image_dir.is_dir():
        raise MissingInputError(f"no image_l/ folder in {root} (expected grey frames there)")
    paths = tuple(sorted(p for p in image_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES))
    if not paths:
        raise MissingInputError(f"no image files (.png, .jpg, ...) in {image_dir}")
    paths, index = _frame_numbers(paths)
    n_frames = int(index[-1]) + 1  # lines of poses.txt and times.txt the frames need
    calib_path = root / "calib.txt"
    camera = Camera.from_kitti_calib(calib_path, key="P0")
    first = read_gray_image(paths[0])
    height, width = first.shape
    if not (0 < camera.c_x < width and 0 < camera.c_y < height):
        raise DataMismatchError(
            f"{calib_path}: principal point ({camera.c_x:.1f}, {camera.c_y:.1f}) px lies outside "
            f"the {width}×{height} frames of {image_dir}: calibration and frames do not match"
        )
    camera = camera.with_image_size(width, height)
    times_path = root / "times.txt"
    if times_path.is_file():
        times = _read_times(times_path)
        if len(times) < n_frames:
            raise DataMismatchError(
                _too_few_lines(times_path, len(times), "timestamps", paths, index)
            )
        timestamps = times[index]
    else:
        timestamps = index.astype(np.float64) * frame_period_s
    poses_path = root / "poses.txt"
    ground_truth: RotationTrack | None = None
    if poses_path.is_file():
        track = read_kitti_poses(poses_path)
        if len(track) < n_frames:
            raise DataMismatchError(_too_few_lines(poses_path, len(track), "poses", paths, index))
        ground_truth = RotationTrack.from_arrays(timestamps, track.R_world_cam[index])
    elif require_poses:
        raise MissingInputError(f"ground-truth poses not found: {poses_path}")
    return KittiOdometrySequence(root, camera, paths, timestamps, ground_truth)
