"""Drives for the batch tests: short ``slopedist simulate`` scenarios and a few real frames."""

from __future__ import annotations

import shutil
from pathlib import Path

from slopedist.cli import main

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
    from slopedist.datasets.kitti_raw import (
        KittiRawDrive,
        lidar_vehicle_boxes,
        link_tracks,
        read_velodyne,
    )
    from slopedist.detections.readers import CSV_TRUTH_COLUMN
    from slopedist.detections.writers import write_box_csv

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
