"""Logged body orientations → camera rotations (extrinsic convention) and the per-frame source."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from slopedist.core.errors import DataMismatchError
from slopedist.odometry.base import OdometryState
from slopedist.odometry.imu import MAX_EXTRAPOLATION_S, TrackRotationSource, camera_rotations


def rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def body_quats(pitch_rad: np.ndarray, yaw0: float = 0.4) -> np.ndarray:
    """Body orientations: a fixed heading ``yaw0`` then a pitch about the body y axis (left)."""
    return np.array([Rotation.from_euler("ZY", [yaw0, p]).as_quat() for p in pitch_rad])


def test_body_pitch_becomes_a_rotation_about_camera_minus_x() -> None:
    # body y (left) is camera −x, so a pitch a about body y is Rx(−a) in the camera frame;
    # the fixed heading cancels against the first sample
    pitch = np.radians([0.0, 1.0, 3.0])
    track = camera_rotations([0.0, 0.1, 0.2], body_quats(pitch))
    for R, a in zip(track.R_world_cam, pitch):
        np.testing.assert_allclose(R, rx(-a), atol=1e-12)


def test_positive_pitch_about_body_left_points_the_optical_axis_down() -> None:
    # a body pitch about +y (left) by +a turns the nose (x forward) DOWN by a (right-hand rule),
    # so the camera's z axis gets a +y (down) component in the first camera's frame
    track = camera_rotations([0.0, 1.0], body_quats(np.radians([0.0, 2.0])))
    z_axis = track.R_world_cam[1][:, 2]
    assert z_axis[1] == pytest.approx(math.sin(math.radians(2.0)))


def test_other_extrinsic_and_repeated_stamps() -> None:
    q = body_quats(np.radians([0.0, 1.0, 1.0, 2.0]))
    track = camera_rotations([0.0, 0.1, 0.1, 0.2], q, R_cam_body=np.eye(3))
    assert len(track) == 3  # the repeated stamp is dropped
    np.testing.assert_allclose(
        track.R_world_cam[2], Rotation.from_euler("Y", 2.0, True).as_matrix(), atol=1e-12
    )


def test_bad_quaternions_are_errors() -> None:
    with pytest.raises(DataMismatchError, match="norm"):
        camera_rotations([0.0], [[0.0, 0.0, 0.0, 2.0]])
    with pytest.raises(DataMismatchError, match=r"\(N, 4\)"):
        camera_rotations([0.0, 1.0], [[0.0, 0.0, 0.0, 1.0]])


def test_source_interpolates_between_samples_and_reports_outside() -> None:
    pitch = np.radians([0.0, 2.0])
    source = TrackRotationSource(camera_rotations([1.0, 2.0], body_quats(pitch)))
    grey = np.zeros((2, 2), np.uint8)
    mid = source.process(grey, 1.5)
    assert mid.state is OdometryState.OK
    assert mid.R_world_cam is not None
    np.testing.assert_allclose(mid.R_world_cam, rx(-math.radians(1.0)), atol=1e-12)
    assert source.process(grey, 1.0 - MAX_EXTRAPOLATION_S / 2).state is OdometryState.OK
    assert source.process(grey, 0.5).state is OdometryState.NOT_INITIALISED
    assert source.process(grey, 2.5).state is OdometryState.LOST


def test_speed_track_interpolates_and_is_nan_outside() -> None:
    from slopedist.odometry.imu import SpeedTrack

    speed = SpeedTrack([0.0, 1.0, 1.0, 2.0], [10.0, 12.0, 99.0, 8.0])
    assert speed(0.5) == pytest.approx(11.0)
    assert speed(1.5) == pytest.approx(10.0)  # the repeated time's sample is dropped
    assert speed(2.0 + MAX_EXTRAPOLATION_S / 2) == 8.0
    assert math.isnan(speed(3.0)) and math.isnan(speed(-1.0))
    with pytest.raises(DataMismatchError):
        SpeedTrack([], [])
