"""``slopedist run`` on drive logs: the same records as on the image folder, camera_info as the
calibration, an IMU topic as the rotation source, and the MCAP / TUM exports."""

from __future__ import annotations

import csv
import math
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

pytest.importorskip("rosbags")
pytest.importorskip("mcap")

from slopedist.cli import main
from slopedist.core.camera import Camera
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.writers import write_box_csv
from slopedist.io.frames import ImageFolderSource
from slopedist.io.rosbag_write import ImageEncoding, LogFormat, LogFrame, LogTopics, write_log
from slopedist.odometry import read_tum_poses
from slopedist.streaming.mcap_export import FRAME_TOPIC, read_mcap_export

W, H, N = 320, 200, 14
CALIB = "P2: 500 0 160 0 0 500 100 0 0 0 1 0\n"
CAMERA = Camera(500.0, 160.0, 100.0).with_image_size(W, H)
TIMING = {"odometry_ms", "estimation_ms", "depth_ms", "source"}
PITCH_RATE = math.radians(0.8)
"""Nose-up pitch rate of the synthetic IMU, rad/s."""
EGO_SPEED_MPS = 12.5
"""Ego speed of the synthetic odometry topic, m/s."""


def textured_frames(folder: Path, n: int = N) -> Path:
    """Frames of a blurred noise texture panning right, so the odometry has features."""
    folder.mkdir(parents=True)
    rng = np.random.default_rng(1)
    base = cv2.GaussianBlur(rng.integers(0, 255, (H, W + 4 * n, 3), dtype=np.uint8), (0, 0), 2)
    for k in range(n):
        cv2.imwrite(str(folder / f"{k:06d}.png"), base[:, 4 * k : 4 * k + W])
    return folder


def boxes_file(tmp_path: Path, n: int = N) -> Path:
    boxes = BoxTable.build(
        np.repeat(np.arange(n), 2),
        np.tile([[140.0, 110.0, 180.0, 140.0], [20.0, 105.0, 60.0, 125.0]], (n, 1)),
        np.tile([1, 2], n),
    )
    return write_box_csv(boxes, tmp_path / "boxes.csv")


def imu_quaternion(t_s: float) -> tuple[float, float, float, float]:
    """Body orientation pitching nose-up at PITCH_RATE (a negative angle about body y, left)."""
    q = Rotation.from_euler("ZY", [0.3, -PITCH_RATE * t_s]).as_quat()
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def write_frames_log(folder: Path, path: Path, fmt: LogFormat, enc: ImageEncoding) -> Path:
    frames = [
        LogFrame(f.index * 100_000_000, f.image, imu_quaternion(f.index / 10), EGO_SPEED_MPS)
        for f in ImageFolderSource(folder)
        if f.image is not None
    ]
    return write_log(path, frames, CAMERA, fmt, enc)


def run(args: list[str], out: Path, capsys: pytest.CaptureFixture[str]) -> Path:
    code = main(["run", *args, "--out", str(out), "--quiet"])
    assert code == 0, capsys.readouterr().err
    return out


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def comparable(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    return [{k: v for k, v in r.items() if k not in TIMING} for r in rows]


@pytest.mark.parametrize(
    ("fmt", "enc", "odometry"),
    [
        (LogFormat.ROS1, ImageEncoding.RAW, "builtin"),
        (LogFormat.ROS2_SQLITE3, ImageEncoding.RAW, "builtin"),
        (LogFormat.ROS2_MCAP, ImageEncoding.RAW, "builtin"),
        (LogFormat.ROS2_MCAP, ImageEncoding.JPEG, "none"),  # lossy pixels: no odometry
    ],
)
def test_log_gives_the_records_of_the_folder(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    fmt: LogFormat,
    enc: ImageEncoding,
    odometry: str,
) -> None:
    folder = textured_frames(tmp_path / "frames")
    (tmp_path / "calib.txt").write_text(CALIB)
    boxes = boxes_file(tmp_path)
    log = write_frames_log(
        folder, tmp_path / ("log.bag" if fmt is LogFormat.ROS1 else "log"), fmt, enc
    )
    method = "ego" if odometry == "builtin" else "flat"
    common = ["--boxes", str(boxes), "--method", method, "--odometry", odometry]
    a = run([str(folder), "--calib", str(tmp_path / "calib.txt"), *common], tmp_path / "a", capsys)
    # no --calib: the log's camera_info
    b = run([str(log), "--image-topic", LogTopics().image, *common], tmp_path / "b", capsys)
    rec_a, rec_b = read_csv(a / "records.csv"), read_csv(b / "records.csv")
    assert len(rec_a) == 2 * N
    assert rec_a == rec_b
    assert comparable(read_csv(a / "frames.csv")) == comparable(read_csv(b / "frames.csv"))
    if odometry == "builtin":
        assert sum(r["status"] == "ok" for r in rec_a) > N


def test_imu_topic_is_the_rotation_source_and_exports_read_back(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = textured_frames(tmp_path / "frames")
    boxes = boxes_file(tmp_path)
    log = write_frames_log(folder, tmp_path / "log", LogFormat.ROS2_MCAP, ImageEncoding.RAW)
    out = run(
        [
            str(log),
            "--image-topic",
            LogTopics().image,
            "--rotation-topic",
            LogTopics().imu,
            "--speed-topic",
            LogTopics().odometry,
            "--boxes",
            str(boxes),
            "--method",
            "imu",
            "--export",
            "mcap",
            "--export",
            "tum",
            "--overlay",
        ],
        tmp_path / "out",
        capsys,
    )
    frames = read_csv(out / "frames.csv")
    assert {r["odometry_state"] for r in frames} == {"ok"}
    # a steady nose-up pitch: θ over the one-second look-back is the pitch in one second
    theta = [float(r["theta_deg"]) for r in frames if float(r["timestamp_s"]) >= 1.0 - 1e-9]
    assert len(theta) == N - 10
    assert theta == pytest.approx([math.degrees(PITCH_RATE)] * len(theta), abs=1e-4)
    # the trajectory: one rotation per frame at the frame times
    track = read_tum_poses(out / "trajectory.tum")
    np.testing.assert_allclose(track.timestamps_s, np.arange(N) / 10)
    # the export: every frame with its image reference, boxes and distances
    exported = read_mcap_export(out / "run.mcap")[FRAME_TOPIC]
    records = read_csv(out / "records.csv")
    assert [f["frame"] for _, f in exported] == list(range(N))
    assert [f["image"] for _, f in exported] == [f"{LogTopics().image}#{k}" for k in range(N)]
    distances = [t["distance_m"] for _, f in exported for t in f["targets"]]
    assert distances == pytest.approx(
        [float(r["distance_m"]) if r["distance_m"] else None for r in records], rel=1e-5
    )
    assert exported[0][0] == 1_317_000_000 * 10**9  # log time of the first image stamp
    assert (out / "overlay.mp4").stat().st_size > 1000
    tracks = read_csv(out / "tracks.csv")
    assert [(r["track_id"], r["frames"]) for r in tracks] == [("1", str(N)), ("2", str(N))]
    # headway time = distance / ego speed, averaged over the track's frames
    for track in tracks:
        z = [float(r["distance_m"]) for r in records if r["track_id"] == track["track_id"]]
        assert float(track["mean_headway_s"]) == pytest.approx(np.mean(z) / EGO_SPEED_MPS, rel=1e-5)


def test_log_needs_an_image_topic_and_folders_a_calib(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = textured_frames(tmp_path / "frames", 3)
    boxes = boxes_file(tmp_path, 3)
    log = write_frames_log(folder, tmp_path / "log.bag", LogFormat.ROS1, ImageEncoding.RAW)
    assert main(["run", str(log), "--boxes", str(boxes), "--quiet"]) == 2
    assert "--image-topic" in capsys.readouterr().err
    assert main(["run", str(folder), "--boxes", str(boxes), "--quiet"]) == 2
    assert "--calib" in capsys.readouterr().err
    args = ["run", str(folder), "--boxes", str(boxes), "--method", "imu", "--quiet"]
    assert main([*args, "--calib", str(tmp_path / "c.txt")]) == 2
    capsys.readouterr()


def test_real_frames_from_a_log_give_the_folder_records(
    kitti_raw_lead_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from slopedist.io.kitti.raw import (
        KittiRawDrive,
        lidar_vehicle_boxes,
        link_tracks,
        read_velodyne,
    )

    n = 12
    drive = KittiRawDrive.open(kitti_raw_lead_dir)
    folder = tmp_path / "image_02"
    folder.mkdir()
    for k in range(n):
        shutil.copy(drive.image_dir / f"{k:010d}.png", folder)
    truth = link_tracks(
        [
            lidar_vehicle_boxes(read_velodyne(drive.velodyne_paths[k]), drive.calib, (1242, 375), k)
            for k in range(n)
        ]
    )
    boxes = write_box_csv(truth, tmp_path / "boxes.csv")
    camera = drive.calib.camera().with_image_size(1242, 375)
    frames = [
        LogFrame(f.index * 100_000_000, f.image)
        for f in ImageFolderSource(folder)
        if f.image is not None
    ]
    log = write_log(tmp_path / "drive", frames, camera, LogFormat.ROS2_MCAP, ImageEncoding.RAW)
    common = ["--boxes", str(boxes), "--method", "ego"]
    a = run([str(folder), "--calib", str(drive.calib_path), *common], tmp_path / "a", capsys)
    b = run([str(log), "--image-topic", LogTopics().image, *common], tmp_path / "b", capsys)
    rec_a = read_csv(a / "records.csv")
    assert len(rec_a) == len(truth)
    assert rec_a == read_csv(b / "records.csv")
