"""Drives for the batch tests: short ``slopedist simulate`` scenarios and a few real frames."""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from slopedist.cli import main
from slopedist.io.rosbag_write import ImageEncoding, LogFormat, LogFrame, write_log

SIM_FRAMES = 5


def simulate(scenario: str, out: Path, frames: int = SIM_FRAMES) -> Path:
    """A ``slopedist simulate`` folder of ``frames`` frames (no depth maps)."""
    code = main(
        ["simulate", scenario, "--out", str(out), "--frames", str(frames), "--depth", "none"]
    )
    assert code == 0
    return out


def real_drive(kitti_raw_lead_dir: Path, out: Path, frames: int = 8) -> Path:
    """The first ``frames`` frames of the shared KITTI raw drive with LiDAR boxes whose
    distance is written as ``gt_distance_m`` (folder layout: image_02, calib.txt, boxes.csv)."""
    from slopedist.io.detections.readers import CSV_TRUTH_COLUMN
    from slopedist.io.detections.writers import write_box_csv
    from slopedist.io.kitti.raw import (
        KittiRawDrive,
        lidar_vehicle_boxes,
        link_tracks,
        read_velodyne,
    )

    drive = KittiRawDrive.open(kitti_raw_lead_dir)
    (out / "image_02").mkdir(parents=True)
    for k in range(frames):
        name = f"{k:010d}.png"
        shutil.copy(drive.image_dir / name, out / "image_02" / name)
    shutil.copy(drive.calib_path, out / "calib.txt")
    boxes = link_tracks(
        [
            lidar_vehicle_boxes(read_velodyne(drive.velodyne_paths[k]), drive.calib, (1242, 375), k)
            for k in range(frames)
        ]
    )
    boxes.extra[CSV_TRUTH_COLUMN] = boxes.extra["z"]
    write_box_csv(boxes, out / "boxes.csv", extra=(CSV_TRUTH_COLUMN,))
    return out


def run_alone(frames: Path, calib: Path, boxes: Path, method: str, out: Path, *extra: str) -> Path:
    """``slopedist run`` of one drive into ``out``; returns its records.csv."""
    args = ["run", str(frames), "--calib", str(calib), "--boxes", str(boxes)]
    code = main([*args, "--method", method, "--out", str(out), "--quiet", *extra])
    assert code == 0
    return out / "records.csv"


def write_drive_log(
    folder: Path,
    log: Path,
    fmt: LogFormat,
    times_s: Sequence[float],
    speeds_mps: Sequence[float],
    orientations: Sequence[Sequence[float]] | None = None,
) -> Path:
    """A drive log of a drive folder (``image_02``, ``calib.txt``): its frames at ``times_s``,
    its camera as camera_info, ``speeds_mps`` on the odometry topic and ``orientations``
    (body-to-world x y z w, body x forward, y left, z up) on the IMU topic (topics of
    :class:`~slopedist.io.rosbag_write.LogTopics`)."""
    from slopedist.io.calibration import read_calibration
    from slopedist.io.frames import ImageFolderSource

    images = [f.image for f in ImageFolderSource(folder / "image_02") if f.image is not None]
    height, width = images[0].shape[:2]
    camera = read_calibration(folder / "calib.txt").camera.with_image_size(width, height)
    quats = orientations if orientations is not None else [None] * len(images)
    frames = [
        LogFrame(round(t * 1e9), image, tuple(map(float, q)) if q is not None else None, v)  # type: ignore[arg-type]
        for t, image, q, v in zip(times_s, images, quats, speeds_mps, strict=True)
    ]
    return write_log(log, frames, camera, fmt, ImageEncoding.RAW)


def simulated_log(sim: Path, log: Path, fmt: LogFormat) -> tuple[Path, list[float]]:
    """A drive log of a ``slopedist simulate`` folder (:func:`write_drive_log`) with the true
    ego speed (m/s, from the camera positions of ``poses.txt``; returned per frame) and the true
    body orientation (from the camera rotations)."""
    from scipy.spatial.transform import Rotation

    from slopedist.io.frames import read_timestamps
    from slopedist.odometry.posefiles import R_CAM_VEHICLE_NOMINAL

    times = np.asarray(read_timestamps(sim / "times.txt"), dtype=float)
    poses = np.loadtxt(sim / "poses.txt").reshape(-1, 3, 4)  # camera-to-world [R | t]
    speeds = np.linalg.norm(np.diff(poses[:, :, 3], axis=0), axis=1) / np.diff(times)
    speeds = np.concatenate([speeds[:1], speeds])  # m/s; the first frame takes the second's
    C = R_CAM_VEHICLE_NOMINAL  # body (x forward, y left, z up) to camera axes
    body = Rotation.from_matrix(C.T @ poses[:, :, :3] @ C).as_quat()  # body-to-world x y z w
    n = len(list((sim / "image_02").iterdir()))
    speed_list = [float(v) for v in speeds[:n]]
    return write_drive_log(sim, log, fmt, times[:n], speed_list, body[:n]), speed_list
