"""``slopedist estimate``: one sequence of precomputed rotations and boxes → per-target CSV."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click
import numpy as np

from slopedist.camera import Camera
from slopedist.cli.options import (
    alphas_option,
    check_methods,
    height_option,
    lookback_option,
    mount_option,
    paper_options,
    thresholds_option,
)
from slopedist.detections.boxes import BoxTable
from slopedist.detections.readers import read_box_file
from slopedist.errors import DataMismatchError
from slopedist.estimators import make_estimator
from slopedist.io.calibration import read_calibration
from slopedist.odometry.base import RotationTrack
from slopedist.odometry.posefiles import PoseFormat, read_oxts_rotations, read_pose_file
from slopedist.pipeline import RecordWriter, StreamingEstimator, iter_records


def read_sequence_inputs(
    calib: Path,
    poses: Path,
    boxes_path: Path,
    pose_format: str,
    frame_period: float,
    score: float | None,
    height_m: float,
    mount_angle_deg: float,
) -> tuple[Camera, RotationTrack, BoxTable]:
    """Camera, rotations and boxes of one sequence as the ``estimate`` options describe them.

    Raises:
        DataMismatchError: the poses do not cover the boxes' frames.
    """
    calibration = read_calibration(calib, height_m, math.radians(mount_angle_deg))
    camera = calibration.camera
    if pose_format == "oxts":
        track = read_oxts_rotations(poses, calib, frame_period)
    elif pose_format == "auto":
        track = read_pose_file(poses, None, frame_period)
    else:
        track = read_pose_file(poses, PoseFormat(pose_format), frame_period)
    boxes = calibration.intrinsics.rectify_table(read_box_file(boxes_path, score))
    if len(boxes) and int(boxes.frame.max()) >= len(track):
        raise DataMismatchError(
            f"{poses}: {len(track)} poses do not cover the boxes of {boxes_path}, which go up "
            f"to frame {int(boxes.frame.max())}"
        )
    return camera, track, boxes


def sequence_input_options(func: Callable[..., Any]) -> Callable[..., Any]:
    """The options read by :func:`read_sequence_inputs` (shared with ``calibrate``)."""
    for option in reversed(
        (
            click.option(
                "--calib",
                required=True,
                type=click.Path(dir_okay=False, path_type=Path),
                help="Calibration: KITTI (P2; P0 for odometry calib.txt), 3×3 K text, OpenCV "
                "or ROS camera_info YAML/JSON; lens distortion and fx ≠ fy are removed from "
                "the boxes (docs/calibration.md).",
            ),
            click.option(
                "--poses",
                required=True,
                type=click.Path(dir_okay=False, path_type=Path),
                help="Pose file: KITTI 3x4 per line, TUM, or OXTS (see --pose-format).",
            ),
            click.option(
                "--boxes",
                "boxes_path",
                required=True,
                type=click.Path(dir_okay=False, path_type=Path),
                help="Boxes: slopedist CSV, KITTI labels or PointRCNN file.",
            ),
            click.option(
                "--pose-format",
                type=click.Choice(["auto", "kitti", "tum", "oxts"]),
                default="auto",
                show_default=True,
                help="Pose layout; 'oxts' = vehicle-frame TUM poses (x forward, y left, z up).",
            ),
            click.option(
                "--frame-period",
                type=click.FloatRange(min=0, min_open=True),
                default=0.1,
                show_default=True,
                help="Seconds between frames (KITTI and OXTS poses).",
            ),
            click.option(
                "--score", type=float, default=None, help="Keep boxes with score >= SCORE."
            ),
        )
    ):
        func = option(func)
    return func


@click.command("estimate")
@sequence_input_options
@click.option("--method", default="paper", show_default=True, help="Estimator name.")
@click.option(
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the records CSV here (default: standard output).",
)
@height_option
@mount_option
@lookback_option
@alphas_option
@thresholds_option
def estimate(
    calib: Path,
    poses: Path,
    boxes_path: Path,
    method: str,
    out: Path | None,
    pose_format: str,
    frame_period: float,
    score: float | None,
    height_m: float,
    mount_angle_deg: float,
    lookback_s: float,
    alphas: str,
    thresholds: str,
) -> None:
    """Estimate per-target distances for one sequence, streaming frame by frame."""
    check_methods([method])
    camera, track, boxes = read_sequence_inputs(
        calib, poses, boxes_path, pose_format, frame_period, score, height_m, mount_angle_deg
    )
    options = paper_options(alphas, thresholds) if method == "paper" else {}
    stream = StreamingEstimator(make_estimator(method, camera, **options), lookback_s)
    by_frame = boxes.frame_index()
    empty = boxes.select(np.zeros(len(boxes), dtype=bool))
    writer = RecordWriter.open(out) if out else RecordWriter(sys.stdout)
    n = 0
    try:
        for k in range(len(track)):
            R = track.R_world_cam[k] if track.valid[k] else None
            frame_boxes = by_frame.get(k, empty)
            est = stream.update(k, float(track.timestamps_s[k]), R, frame_boxes)
            writer.write(iter_records(frame_boxes, track.timestamps_s, est, method))
            n += len(frame_boxes)
    finally:
        if out:
            writer.close()
    if out:
        click.echo(f"wrote {n} records to {out}", err=True)
