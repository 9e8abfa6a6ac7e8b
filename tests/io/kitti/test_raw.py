"""KITTI raw: LiDAR projection, ground plane, clustering, LiDAR vehicle boxes and their writer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slopedist.core.errors import InputFileError, MissingInputError
from slopedist.io.detections.readers import read_box_csv
from slopedist.io.detections.writers import write_box_csv
from slopedist.io.kitti.raw import (
    KittiRawCalib,
    KittiRawDrive,
    cluster_bev,
    fit_ground_plane,
    lidar_vehicle_boxes,
    link_tracks,
    project_velo_to_image,
    read_velodyne,
)

F, CX, CY = 700.0, 600.0, 180.0
LIDAR_HEIGHT = 1.73
# LiDAR (x fwd, y left, z up) → camera (x right, y down, z fwd), same origin
T_AXES = np.array([[0.0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]])
CALIB = KittiRawCalib(np.array([[F, 0, CX, 0], [0, F, CY, 0], [0, 0, 1, 0]]), np.eye(3), T_AXES)
SIZE = (1200, 375)


def test_projection_of_hand_made_points() -> None:
    pts = np.array([[10.0, 0, 0], [10, 2, -1], [-5, 0, 0]])
    uv, z = project_velo_to_image(pts, CALIB)
    assert z == pytest.approx([10, 10, -5])
    assert uv[0] == pytest.approx([CX, CY])
    assert uv[1] == pytest.approx([CX - F * 0.2, CY + F * 0.1])
    assert np.isnan(uv[2]).all(), "points behind the camera have no pixel"


def test_projection_uses_p2_r0_and_tr_in_that_order() -> None:
    rng = np.random.default_rng(1)
    P2 = np.hstack([np.array([[F, 0, CX], [0, F, CY], [0, 0, 1]]), rng.normal(0, 1, (3, 1))])
    a = 0.1
    R0 = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    Tr = T_AXES.copy()
    Tr[:3, 3] = [0.1, -0.2, 0.3]
    calib = KittiRawCalib(P2, R0, Tr)
    X = np.array([12.0, -1.5, 0.4, 1.0])
    R0h = np.eye(4)
    R0h[:3, :3] = R0
    uvw = P2 @ R0h @ Tr @ X
    uv, _ = project_velo_to_image(X[None, :3], calib)
    assert uv[0] == pytest.approx(uvw[:2] / uvw[2])


def test_calib_file_and_camera(tmp_path: Path) -> None:
    path = tmp_path / "calib.txt"
    path.write_text(
        "P2: 700 0 600 45 0 700 180 0.2 0 0 1 0.003\n"
        "R0_rect: 1 0 0 0 1 0 0 0 1\n"
        "Tr_velo_to_cam: 0 -1 0 0 0 0 -1 -0.08 1 0 0 -0.27\n"
    )
    calib = KittiRawCalib.from_file(path)
    assert calib.camera().f == 700 and calib.camera().c_y == 180
    assert calib.T_rect_velo[:3, 3] == pytest.approx([0, -0.08, -0.27])
    path.write_text("P2: 700 0 600 45 0 700 180 0.2 0 0 1 0.003\n")
    with pytest.raises(InputFileError, match="Tr_velo_to_cam"):
        KittiRawCalib.from_file(path)


def test_read_velodyne_checks_the_size(tmp_path: Path) -> None:
    good = tmp_path / "a.bin"
    np.arange(8, dtype=np.float32).tofile(good)
    assert read_velodyne(good).shape == (2, 4)
    bad = tmp_path / "b.bin"
    np.arange(7, dtype=np.float32).tofile(bad)
    with pytest.raises(InputFileError, match="16-byte rows"):
        read_velodyne(bad)
    with pytest.raises(MissingInputError):
        read_velodyne(tmp_path / "c.bin")


def _face(
    x: tuple[float, float], y: tuple[float, float], z: tuple[float, float], step: float = 0.1
) -> np.ndarray:
    """Points on an axis-aligned rectangle (one of the ranges has zero length)."""
    axes = [np.arange(a, b + step / 2, step) if b > a else np.array([a]) for a, b in (x, y, z)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def _car(x0: float, length: float = 4.0, half_width: float = 0.9) -> np.ndarray:
    """What the LiDAR sees of a car ahead: its rear face and its roof."""
    low, top = -LIDAR_HEIGHT + 0.3, -LIDAR_HEIGHT + 1.5
    return np.vstack(
        [
            _face((x0, x0), (-half_width, half_width), (low, top)),
            _face((x0, x0 + length), (-half_width, half_width), (top, top)),
        ]
    )


def synthetic_scan() -> np.ndarray:
    """Flat ground 1.73 m below the LiDAR, a car 10–14 m ahead, a pole, a long wall."""
    ground = np.mgrid[3:40:0.3, -10:10:0.3].reshape(2, -1).T
    ground = np.c_[ground, np.full(len(ground), -LIDAR_HEIGHT)]
    pole = _face((8.0, 8.0), (3.0, 3.2), (-LIDAR_HEIGHT + 0.3, -LIDAR_HEIGHT + 3.0), 0.05)
    wall = _face((5.0, 35.0), (-6.0, -6.0), (-LIDAR_HEIGHT + 0.3, -LIDAR_HEIGHT + 2.0), 0.2)
    return np.vstack([ground, pole, wall])


def test_ground_plane_of_a_flat_scan() -> None:
    n, d = fit_ground_plane(synthetic_scan())
    assert n == pytest.approx([0, 0, 1], abs=1e-6)
    assert d == pytest.approx(LIDAR_HEIGHT, abs=1e-6)


def test_cluster_bev_joins_touching_cells_only() -> None:
    labels = cluster_bev(np.array([[0, 0], [0.2, 0.2], [0.5, 0.4], [3, 3], [3.1, 3.0]]), 0.3)
    assert labels[0] == labels[1] == labels[2] != labels[3] == labels[4]


def test_vehicle_box_of_a_synthetic_car() -> None:
    table = lidar_vehicle_boxes(np.vstack([synthetic_scan(), _car(10.0)]), CALIB, SIZE, frame=7)
    assert len(table) == 1, "the pole (too small) and the wall (too long) are not vehicles"
    assert table.frame[0] == 7
    assert table.extra["z"][0] == pytest.approx(10.0, abs=0.05)
    left, top, right, bottom = table.boxes[0]
    # box bottom = ground under the nearest face: row c_y + f·h/z
    assert bottom == pytest.approx(CY + F * LIDAR_HEIGHT / 10.0, abs=1.0)
    assert top == pytest.approx(CY + F * (LIDAR_HEIGHT - 1.5) / 14.0, abs=1.0)  # far roof edge
    assert (left, right) == pytest.approx((CX - F * 0.9 / 10, CX + F * 0.9 / 10), abs=2.0)
    assert table.extra["truncated"][0] == 0 and abs(table.extra["x"][0]) < 0.1


def test_link_tracks_follows_a_moving_cluster() -> None:
    scans = [np.vstack([synthetic_scan(), _car(x0)]) for x0 in (10.0, 10.8)]
    tables = [lidar_vehicle_boxes(s, CALIB, SIZE, frame=k) for k, s in enumerate(scans)]
    linked = link_tracks(tables)
    assert list(linked.frame) == [0, 1] and linked.track_id[0] == linked.track_id[1]
    assert linked.extra["z"] == pytest.approx([10.0, 10.8], abs=0.05)


def test_box_csv_round_trip(tmp_path: Path) -> None:
    table = lidar_vehicle_boxes(np.vstack([synthetic_scan(), _car(10.0)]), CALIB, SIZE, frame=3)
    path = write_box_csv(table, tmp_path / "boxes.csv")
    back = read_box_csv(path)
    assert back.boxes == pytest.approx(table.boxes, rel=1e-5)
    assert list(back.frame) == [3]
    assert "z" in path.read_text().splitlines()[0].split(",")


def test_real_lead_car_box_and_distance(kitti_raw_lead_dir: Path) -> None:
    drive = KittiRawDrive.open(kitti_raw_lead_dir)
    assert drive.frames() == list(range(78))
    calib = drive.calib
    cam = calib.camera()
    table = lidar_vehicle_boxes(read_velodyne(drive.velodyne_paths[0]), calib, (1242, 375))
    in_lane = table.select(np.abs(table.extra["x"]) < 1.0)
    lead = in_lane.select([int(np.argmin(in_lane.extra["z"]))])
    z = float(lead.extra["z"][0])
    assert 7.0 < z < 8.5  # the README: the lead car starts at about 8 m
    left, _top, right, bottom = lead.boxes[0]
    assert 530 < left < 580 and 680 < right < 720 and 300 < bottom < 345
    # its ground-contact row agrees with its LiDAR distance on this level street (eq. 1)
    assert cam.f * 1.65 / (bottom - cam.c_y) == pytest.approx(z, rel=0.06)
    assert lead.extra["truncated"][0] == 0


def test_real_lead_car_is_cut_by_the_image_at_the_end(kitti_raw_lead_dir: Path) -> None:
    drive = KittiRawDrive.open(kitti_raw_lead_dir)
    table = lidar_vehicle_boxes(read_velodyne(drive.velodyne_paths[77]), drive.calib, (1242, 375))
    in_lane = table.select(np.abs(table.extra["x"]) < 1.0)
    lead = in_lane.select([int(np.argmin(in_lane.extra["z"]))])
    assert 4.0 < float(lead.extra["z"][0]) < 4.8  # about 4.4 m at the end
    assert lead.extra["truncated"][0] == 1, "ground under a car 4.4 m ahead is below the image"


def test_missing_drive_parts(tmp_path: Path) -> None:
    with pytest.raises(MissingInputError, match=r"calib\.txt"):
        KittiRawDrive.open(tmp_path)
