"""Rotation sources: pose files, OXTS/IMU, and visual odometry from pixels.

Internal: the names a user needs are those of :mod:`slopedist` itself (docs/python.md).
"""

from slopedist.odometry.base import (
    OdometryResult,
    OdometryState,
    RotationOdometry,
    RotationTrack,
    lookback_indices,
)
from slopedist.odometry.factory import available_odometry, make_odometry
from slopedist.odometry.posefiles import (
    read_kitti_poses,
    read_oxts_rotations,
    read_pose_file,
    read_tum_poses,
)

__all__ = [
    "OdometryResult",
    "OdometryState",
    "RotationOdometry",
    "RotationTrack",
    "available_odometry",
    "lookback_indices",
    "make_odometry",
    "read_kitti_poses",
    "read_oxts_rotations",
    "read_pose_file",
    "read_tum_poses",
]
