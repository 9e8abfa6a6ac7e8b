"""One sequence given as files: a KITTI calibration, a pose file and a box file.

The inputs of ``slopedist estimate`` and ``slopedist calibrate``. Convention: rotations
camera-to-world relative to the first frame, timestamps ``k × frame_period_s`` seconds (pose
files without timestamps), angles in radians inside.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from pathlib import Path

import numpy as np

from slopedist.core.camera import KITTI_CAMERA_HEIGHT_M, Camera
from slopedist.core.errors import ConfigurationError, DataMismatchError, MissingInputError
from slopedist.io.calibration import read_calibration
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.readers import read_box_file
from slopedist.io.intrinsics import Intrinsics
from slopedist.odometry.base import RotationTrack
from slopedist.odometry.posefiles import PoseFormat, read_oxts_rotations, read_pose_file


class PoseFileLayout(str, Enum):
    """Layout of a pose file: detected, KITTI 3×4 rows, TUM, or OXTS (vehicle-frame TUM)."""

    AUTO = "auto"
    KITTI = "kitti"
    TUM = "tum"
    OXTS = "oxts"


@dataclass(frozen=True)
class SequenceFiles:
    """Where one sequence's inputs are and how to read them.

    Attributes:
        calib: calibration file in any form :func:`~slopedist.io.calibration.read_calibration`
            reads (KITTI ``P2``, K text, OpenCV/ROS YAML/JSON), or the intrinsics as values;
            boxes are mapped into its ideal camera (lens distortion and fx ≠ fy removed).
        poses: pose file; ``pose_layout`` says its layout (None: not given, e.g. the rotations
            come from the frames).
        boxes: box file (any form :func:`~slopedist.io.detections.readers.read_box_file` reads;
            None: not given, e.g. a detector finds them).
        frame_period_s: seconds between frames (pose files without timestamps).
        frame_period_given: ``frame_period_s`` was given by the user: a pose file with its own
            timestamps (TUM) must then be at that period (:func:`check_pose_times`).
        min_score: keep boxes with score ≥ this (None: all).
        height_m: camera height above the road, metres.
        mount_angle_rad: camera mount angle θ0, radians.
        image_size: the images' (width, height) in pixels when the calibration states none
            (None: unknown, or the calibration's own).
    """

    calib: Path | Intrinsics
    poses: Path | None
    boxes: Path | None
    pose_layout: PoseFileLayout = PoseFileLayout.AUTO
    frame_period_s: float = 0.1
    min_score: float | None = None
    height_m: float = KITTI_CAMERA_HEIGHT_M
    mount_angle_rad: float = 0.0
    image_size: tuple[int, int] | None = None
    frame_period_given: bool = False

    @property
    def input_files(self) -> list[Path]:
        """The files given (the calibration only when it is a file)."""
        given = (self.calib, self.poses, self.boxes)
        return [p for p in given if isinstance(p, Path)]


@dataclass(frozen=True)
class SequenceInputs:
    """Camera, rotations and boxes of one sequence (box frame indices index the track)."""

    camera: Camera
    track: RotationTrack
    boxes: BoxTable


def read_sequence_files(files: SequenceFiles) -> SequenceInputs:
    """Read the camera, the rotations and the boxes of ``files``.

    Raises:
        MissingInputError: no pose or box file given.
        DataMismatchError: the poses do not cover the boxes' frames, or (``frame_period_given``)
            their own times are not at the frame period (:func:`check_pose_times`).
    """
    if files.poses is None or files.boxes is None:
        missing = "pose" if files.poses is None else "box"
        raise MissingInputError(f"no {missing} file given")
    calibration = read_calibration(
        files.calib, files.height_m, files.mount_angle_rad, image_size=files.image_size
    )
    layout = PoseFileLayout(files.pose_layout)
    if layout is PoseFileLayout.OXTS:
        if isinstance(files.calib, Intrinsics):
            raise ConfigurationError(
                "OXTS poses need the KITTI calibration file (Tr_imu_to_velo, Tr_velo_to_cam): "
                "give --calib, not --fx/--fy/--cx/--cy"
            )
        track = read_oxts_rotations(files.poses, files.calib, files.frame_period_s)
    elif layout is PoseFileLayout.AUTO:
        track = read_pose_file(files.poses, None, files.frame_period_s)
    else:
        track = read_pose_file(files.poses, PoseFormat(layout.value), files.frame_period_s)
    if files.frame_period_given:
        check_pose_times(files.poses, track, files.frame_period_s)
    boxes = calibration.intrinsics.rectify_table(read_box_file(files.boxes, files.min_score))
    if len(boxes) and int(boxes.frame.max()) >= len(track):
        beyond = int(np.count_nonzero(boxes.frame >= len(track)))
        raise DataMismatchError(
            f"{files.poses}: {len(track)} poses do not cover the boxes of {files.boxes}, which "
            f"go up to frame {int(boxes.frame.max())}: {beyond} of {len(boxes)} boxes are in "
            f"frames {len(track)} to {int(boxes.frame.max())}, past the last pose (frame "
            f"{len(track) - 1})"
        )
    return SequenceInputs(calibration.camera, track, boxes)


POSE_STEP_TOLERANCE = 0.25
"""Largest relative difference of one step of a TUM pose file's times from ``--frame-period``:
poses at twice the rate (a step of half the period) or a missing pose (twice the period) are
beyond it, a camera clock's jitter and a rate a few per cent off the nominal one (0.104 s for a
nominal 0.1) within it."""


def check_pose_times(path: Path, track: RotationTrack, frame_period_s: float) -> None:
    """Refuse a pose file whose own timestamps (TUM; KITTI and OXTS poses are timed by the
    period itself) do not step by ``frame_period_s`` seconds (within
    :data:`POSE_STEP_TOLERANCE`): pose k is frame k's, so poses at another rate, or with a gap,
    would be paired with the wrong frames. Each step is checked on its own, so that a period a
    little off the poses' own (0.1 for 0.104 s) does not add up over a long drive.

    Raises:
        DataMismatchError: naming the file, the first pose off its step, and both times.
    """
    steps = np.diff(track.timestamps_s)
    off = np.abs(steps - frame_period_s) > POSE_STEP_TOLERANCE * frame_period_s
    if off.any():
        k = int(np.argmax(off))
        t0, t1 = track.timestamps_s[k], track.timestamps_s[k + 1]
        raise DataMismatchError(
            f"{path}: the pose times do not follow --frame-period {frame_period_s:g} s: frame "
            f"{k + 1}'s pose is at {t1:.6f} s, {t1 - t0:.3g} s after frame {k}'s at {t0:.6f} s "
            "(poses at another rate than the frames, or a missing pose?)"
        )
