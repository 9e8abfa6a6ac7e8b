"""Pose-file readers, the OXTS conversion and the look-back rule."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from slopedist.core import geometry as geo
from slopedist.core.errors import DataMismatchError, InputFileError, MissingInputError
from slopedist.odometry import (
    RotationTrack,
    lookback_indices,
    read_kitti_poses,
    read_oxts_rotations,
    read_pose_file,
    read_tum_poses,
)
from slopedist.odometry.posefiles import (
    R_CAM_VEHICLE_NOMINAL,
    PoseFormat,
    vehicle_frame_evidence,
)


def write_kitti(path: Path, rotations: np.ndarray) -> None:
    lines = []
    for k, R in enumerate(rotations):
        T = np.hstack([R, [[0.0], [0.0], [float(k)]]])
        lines.append(" ".join(f"{v:.12f}" for v in T.ravel()))
    path.write_text("\n".join(lines) + "\n")


def test_kitti_poses_relative_to_first(tmp_path: Path) -> None:
    R = Rotation.from_euler("xyz", [[0.1, 0.2, 0.3], [0.15, 0.25, 0.3]]).as_matrix()
    path = tmp_path / "poses.txt"
    write_kitti(path, R)
    track = read_kitti_poses(path)
    np.testing.assert_allclose(track.R_world_cam[0], np.eye(3), atol=1e-9)
    np.testing.assert_allclose(track.R_world_cam[1], R[0].T @ R[1], atol=1e-9)
    np.testing.assert_allclose(track.timestamps_s, [0.0, 0.1])


def test_kitti_pose_bad_field(tmp_path: Path) -> None:
    path = tmp_path / "poses.txt"
    path.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 x 0 0 1 0\n")
    with pytest.raises(InputFileError, match=r"poses.txt, line 2, field 't1'"):
        read_kitti_poses(path)


@pytest.mark.parametrize("position", ["1e308", "-2e8", "inf"])
def test_a_position_beyond_any_map_is_one_error_not_a_numpy_warning(
    tmp_path: Path, position: str
) -> None:
    """A translation replaced by a huge number overflowed in the step check (a RuntimeWarning
    from numpy reached the user) before it was refused or read."""
    path = tmp_path / "poses.txt"
    lines = [f"1 0 0 {0.5 * k} 0 1 0 0 0 0 1 {0.8 * k}" for k in range(6)]
    lines[3] = f"1 0 0 {position} 0 1 0 0 0 0 1 2.4"
    path.write_text("\n".join(lines) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InputFileError, match=r"line 4, field 't0"):
            read_kitti_poses(path)


def test_kitti_pose_not_a_rotation(tmp_path: Path) -> None:
    path = tmp_path / "poses.txt"
    path.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n2 0 0 0 0 1 0 0 0 0 1 0\n")
    with pytest.raises(InputFileError, match=r"line 2.*not a rotation"):
        read_kitti_poses(path)


def test_missing_pose_file(tmp_path: Path) -> None:
    with pytest.raises(MissingInputError, match="pose file not found"):
        read_pose_file(tmp_path / "x.txt")


def test_tum_reader_and_autodetect(tmp_path: Path) -> None:
    q = Rotation.from_euler("x", [[0.0], [2.0]], degrees=True).as_quat()
    path = tmp_path / "tum.txt"
    path.write_text(
        "".join(f"{t} 0 0 0 {a} {b} {c} {d}\n" for t, (a, b, c, d) in zip([5.0, 5.5], q))
    )
    track = read_pose_file(path)
    np.testing.assert_allclose(track.timestamps_s, [5.0, 5.5])
    assert geo.ego_road_gradient(track.R_world_cam[0], track.R_world_cam[1]) == pytest.approx(
        math.radians(2.0)
    )
    bad = tmp_path / "bad.txt"
    bad.write_text("0 0 0 0 0 0 0 2\n")
    with pytest.raises(InputFileError, match="quaternion norm"):
        read_tum_poses(bad)


def test_oxts_vehicle_pitch_becomes_camera_gradient(tmp_path: Path) -> None:
    # vehicle pitches nose up by 1.5° about its y (left) axis: in ISO axes, nose-up = negative y rot
    pitch = Rotation.from_euler("y", -1.5, degrees=True).as_quat()
    path = tmp_path / "oxts.txt"
    path.write_text(f"0 0 0 0 0 0 0 1\n0.05 1 0 0 {pitch[0]} {pitch[1]} {pitch[2]} {pitch[3]}\n")
    track = read_oxts_rotations(path)
    np.testing.assert_allclose(track.timestamps_s, [0.0, 0.1])  # t column ignored
    theta = geo.ego_road_gradient(track.R_world_cam[0], track.R_world_cam[1])
    assert theta == pytest.approx(math.radians(1.5), abs=1e-9)
    assert np.allclose(R_CAM_VEHICLE_NOMINAL @ [1, 0, 0], [0, 0, 1])  # forward → camera z


def test_lookback_indices_by_timestamp() -> None:
    t = np.arange(25) * 0.1
    j = lookback_indices(t, 1.0)
    assert list(j[:11]) == [0] * 11  # less than 1 s of history → frame 0; frame 10 → frame 0
    assert list(j[11:14]) == [1, 2, 3]
    # a dropped frame: look back to the latest frame at least 1 s older
    t2 = np.array([0.0, 0.1, 0.2, 0.4, 1.15, 1.3])
    assert list(lookback_indices(t2, 1.0)) == [0, 0, 0, 0, 1, 2]


@given(st.lists(st.floats(0.01, 1.0), min_size=1, max_size=60), st.floats(0.05, 3.0))
def test_lookback_is_at_least_the_interval_or_the_first(steps: list[float], look: float) -> None:
    t = np.cumsum([0.0, *steps])
    j = lookback_indices(t, look)
    for i, ji in enumerate(j):
        assert ji <= i
        if ji > 0:
            assert t[i] - t[ji] >= look - 1e-6
            assert t[i] - t[ji + 1] < look + 1e-6 or ji + 1 > i


def test_track_rejects_timestamps_going_backwards() -> None:
    with pytest.raises(DataMismatchError, match="frame 2"):
        RotationTrack.from_arrays([0.0, 0.1, 0.05], np.stack([np.eye(3)] * 3))


def test_real_oxts_and_orbslam_agree(kitti_tracking_dir: Path) -> None:
    from slopedist.streaming.step import ego_gradients

    calib = kitti_tracking_dir / "calib" / "0000.txt"
    oxts = read_oxts_rotations(kitti_tracking_dir / "oxts_poses" / "0000.txt", calib)
    orb = read_kitti_poses(kitti_tracking_dir / "orbslam3_poses" / "0000.txt")
    diff = np.degrees(ego_gradients(oxts) - ego_gradients(orb))
    # the data README: ORB-SLAM3's pitch agrees with OXTS to about 0.02–0.07° RMS on 0000–0010
    assert math.sqrt(np.mean(diff**2)) < 0.1


def test_tum_writer_reads_back_exactly_and_as_evo_parses_it(tmp_path: Path) -> None:
    from slopedist.odometry.base import RotationTrack
    from slopedist.odometry.posefiles import TUM_HEADER, write_tum_poses

    rng = np.random.default_rng(3)  # a drive's rotations: a few degrees from frame to frame
    R = Rotation.from_rotvec(rng.normal(scale=0.05, size=(5, 3))).as_matrix()
    R = R[0].T @ R  # relative to the first, as the readers return them
    t = 1317000000.0 + np.array([0.0, 0.1, 0.2, 0.35, 0.5])
    valid = np.array([True, True, False, True, True])
    path = write_tum_poses(tmp_path / "traj.tum", RotationTrack.from_arrays(t, R, valid))
    lines = path.read_text().splitlines()
    assert lines[0] == TUM_HEADER
    # evo's reader: '#' lines skipped, space-delimited, 8 floats per row
    rows = [[float(v) for v in ln.split(" ")] for ln in lines if not ln.startswith("#")]
    assert all(len(r) == 8 for r in rows) and len(rows) == 4
    track = read_tum_poses(path)
    np.testing.assert_array_equal(track.timestamps_s, t[valid])
    np.testing.assert_allclose(track.R_world_cam, R[valid], atol=1e-12)
    assert all(r[1:4] == [0.0, 0.0, 0.0] for r in rows)


def test_pose_errors_name_the_real_line(tmp_path: Path) -> None:
    path = tmp_path / "tum.txt"
    path.write_text("# t x y z qx qy qz qw\n\n0 0 0 0 0 0 0 1\n# gap\n0.1 0 0 0 0 0 0 3\n")
    with pytest.raises(InputFileError, match=r"line 5, field 'qx qy qz qw'"):
        read_tum_poses(path)
    path.write_text("# header\n1 0 0 0 0 1 0 0 0 0 1 0\n\n2 0 0 0 0 1 0 0 0 0 1 0\n")
    with pytest.raises(InputFileError, match=r"line 4.*not a rotation"):
        read_kitti_poses(path)


def test_tum_times_that_do_not_increase_name_the_file_and_line(tmp_path: Path) -> None:
    """The error said only 'timestamps must increase: frame 1 at 1.0 s follows 1.0 s'."""
    path = tmp_path / "tum.txt"
    path.write_text("# t x y z qx qy qz qw\n1.0 0 0 0 0 0 0 1\n\n1.0 0 0 1 0 0 0 1\n")
    with pytest.raises(InputFileError, match=r"tum.txt, line 4, field 't': time 1 s does not"):
        read_tum_poses(path)
    with pytest.raises(InputFileError, match=r"line 4, field 't'"):
        read_pose_file(path)
    assert len(read_tum_poses(path, frame_period_s=0.1)) == 2  # its t column is not used


def _tum_lines(xyz: np.ndarray, R: np.ndarray) -> str:
    q = Rotation.from_matrix(R).as_quat()
    return "".join(
        f"{0.1 * k} {p[0]} {p[1]} {p[2]} {a} {b} {c} {d}\n"
        for k, (p, (a, b, c, d)) in enumerate(zip(xyz, q))
    )


def _drive(axis_up: str, axis_forward: int, turn_deg: float, n: int = 80) -> str:
    yaw = np.linspace(0.0, math.radians(turn_deg), n)
    R = Rotation.from_euler(axis_up, yaw[:, None]).as_matrix()
    xyz = np.zeros((n, 3))
    xyz[:, axis_forward] = np.arange(n) * 1.0
    return _tum_lines(xyz, R)


@pytest.mark.parametrize("turn", [0.0, 60.0])
def test_auto_format_refuses_vehicle_frame_poses(tmp_path: Path, turn: float) -> None:
    path = tmp_path / "poses.txt"
    path.write_text(_drive("z", 0, turn))  # vehicle frame: forward x, turning about z (up)
    with pytest.raises(InputFileError, match=r"vehicle-frame poses.*give the pose format"):
        read_pose_file(path)
    assert len(read_pose_file(path, PoseFormat.TUM)) == 80  # explicit format: read as told
    assert len(read_oxts_rotations(path)) == 80
    path.write_text(_drive("y", 2, turn))  # camera frame: forward z, turning about y
    assert len(read_pose_file(path)) == 80


def test_auto_format_on_real_oxts_and_orbslam(kitti_tracking_dir: Path) -> None:
    for seq in ("0000", "0008", "0010"):
        with pytest.raises(InputFileError, match="vehicle-frame"):
            read_pose_file(kitti_tracking_dir / "oxts_poses" / f"{seq}.txt")
    for seq in ("0000", "0004", "0006", "0014"):
        data = np.loadtxt(kitti_tracking_dir / "orbslam3_poses" / f"{seq}.txt").reshape(-1, 3, 4)
        assert vehicle_frame_evidence(data[:, :, 3], data[:, :, :3]) is None


def test_kitti_poses_written_as_4x4_matrices_read_as_3x4(tmp_path: Path) -> None:
    R = Rotation.from_euler("xyz", [[0.1, 0.2, 0.3], [0.15, 0.25, 0.3]]).as_matrix()
    write_kitti(tmp_path / "p12.txt", R)
    rows = [
        [*line.split(), "0", "0", "0", "1"]
        for line in (tmp_path / "p12.txt").read_text().splitlines()
    ]
    (tmp_path / "p16.txt").write_text("".join(" ".join(r) + "\n" for r in rows))
    expected = read_kitti_poses(tmp_path / "p12.txt")
    for track in (read_kitti_poses(tmp_path / "p16.txt"), read_pose_file(tmp_path / "p16.txt")):
        np.testing.assert_array_equal(track.R_world_cam, expected.R_world_cam)
    rows[1][-1] = "2"
    (tmp_path / "bad.txt").write_text("".join(" ".join(r) + "\n" for r in rows))
    with pytest.raises(InputFileError, match=r"line 2, field 'm30..m33': a 4×4 pose's last row"):
        read_kitti_poses(tmp_path / "bad.txt")


def test_tum_timestamps_in_nanoseconds_are_refused(tmp_path: Path) -> None:
    """They read as seconds 10⁸ apart: the look-back of one second then took the previous
    frame, whatever the frame rate."""
    path = tmp_path / "ns.txt"
    path.write_text(
        "".join(
            f"{1_600_000_000_000_000_000 + k * 100_000_000} 0 0 {k} 0 0 0 1\n" for k in range(5)
        )
    )
    with pytest.raises(
        InputFileError, match=r"ns.txt, line 2, field 't': poses are 1e\+08 s apart"
    ):
        read_tum_poses(path)
    assert len(read_tum_poses(path, frame_period_s=0.1)) == 5  # its t column is not used


def test_tum_writer_leaves_out_a_pose_that_is_not_one(tmp_path: Path) -> None:
    """A rotation with NaN (a frame the odometry lost), a null matrix or a NaN time has no
    line: it was a LinAlgError / ValueError ending the run, or a ``nan`` time written as one."""
    from slopedist.odometry.posefiles import TUM_HEADER, TumPoseWriter

    writer = TumPoseWriter(tmp_path / "traj.tum")
    assert writer.write(0.0, np.eye(3))
    assert not writer.write(0.1, np.full((3, 3), np.nan))
    assert not writer.write(0.2, np.zeros((3, 3)))
    assert not writer.write(math.nan, np.eye(3))
    assert not writer.write(0.3, np.eye(3), np.array([0.0, math.inf, 0.0]))
    assert writer.write(0.4, np.eye(3))
    writer.close()
    assert (writer.poses, writer.skipped) == (2, 4)
    lines = (tmp_path / "traj.tum").read_text().splitlines()
    assert lines == [
        TUM_HEADER,
        "0.0 0.0 0.0 0.0 0.0 0.0 0.0 1.0",
        "0.4 0.0 0.0 0.0 0.0 0.0 0.0 1.0",
    ]


def _turning_drive(n: int = 120, speed_mps: float = 12.0) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame positions (m) and rotations of a drive at 10 Hz: forward along z, a 60° turn
    about y and a few degrees of pitch."""
    s = np.arange(n) / (n - 1)
    R = Rotation.from_euler(
        "yx", np.c_[np.radians(60.0) * s, np.radians(3.0) * np.sin(4 * s)]
    ).as_matrix()
    steps = R @ np.array([0.0, 0.0, speed_mps * 0.1])
    return np.cumsum(steps, axis=0), R


def _kitti_text(xyz: np.ndarray, R: np.ndarray) -> str:
    return "".join(
        " ".join(f"{v:.9f}" for v in np.hstack([Rk, pk[:, None]]).ravel()) + "\n"
        for pk, Rk in zip(xyz, R)
    )


def _shuffled(n: int) -> np.ndarray:
    order = np.random.default_rng(5).permutation(n - 1) + 1
    return np.r_[0, order]


@pytest.mark.parametrize("layout", ["kitti", "tum", "oxts"])
def test_pose_lines_out_of_order_are_refused_naming_the_first_jump(
    tmp_path: Path, layout: str
) -> None:
    """Shuffled lines (consecutive poses tens of metres and degrees apart) were read as a
    drive, and every distance was ``ok``, off by up to 94 % (KITTI layout), 111 % (OXTS)."""
    xyz, R = _turning_drive()
    order = _shuffled(len(R))
    path = tmp_path / "poses.txt"
    read = {
        "kitti": lambda: read_kitti_poses(path),
        "tum": lambda: read_pose_file(path, PoseFormat.TUM),
        "oxts": lambda: read_oxts_rotations(path),
    }[layout]
    text = _kitti_text if layout == "kitti" else _tum_lines
    path.write_text(text(xyz, R))
    assert len(read()) == len(R)  # in order: a drive
    path.write_text(text(xyz[order], R[order]))  # (TUM and OXTS: the t column stays in order)
    with pytest.raises(InputFileError, match=r"line 2, .*faster than a car moves.*out of order"):
        read()


def test_oxts_lines_out_of_order_are_refused_by_their_t_column(tmp_path: Path) -> None:
    xyz, R = _turning_drive()
    lines = _tum_lines(xyz, R).splitlines(keepends=True)
    lines[5], lines[6] = lines[6], lines[5]  # two lines swapped: a step of one frame back
    path = tmp_path / "oxts.txt"
    path.write_text("".join(lines))
    with pytest.raises(InputFileError, match=r"line 7, field 't': time 0.5 s comes after 0.6"):
        read_oxts_rotations(path)


def test_a_glitch_and_a_restart_of_the_odometry_are_read(tmp_path: Path) -> None:
    """One pose far off (out and back) and a restart at the origin (one jump) are left to the
    rotations' jump check, frame by frame."""
    xyz, R = _turning_drive()
    xyz[40] += [0.0, 0.0, 80.0]  # a glitch
    xyz[90:] -= xyz[90]  # a restart: the trajectory goes on from the origin
    path = tmp_path / "poses.txt"
    path.write_text(_kitti_text(xyz, R))
    assert len(read_kitti_poses(path)) == len(R)


def test_the_shared_pose_files_are_all_one_drive(kitti_tracking_dir: Path) -> None:
    from slopedist.odometry.jumps import impossible_steps

    for path in sorted((kitti_tracking_dir / "orbslam3_poses").glob("*.txt")):
        data = np.loadtxt(path).reshape(-1, 3, 4)
        t = np.arange(len(data)) * 0.1
        assert not impossible_steps(t, data[:, :, :3], data[:, :, 3]).any(), path
        read_kitti_poses(path)
    for path in sorted((kitti_tracking_dir / "oxts_poses").glob("*.txt")):
        calib = kitti_tracking_dir / "calib" / path.name
        read_oxts_rotations(path, calib)
