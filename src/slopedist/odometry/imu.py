"""Camera rotations from a logged orientation (IMU, odometry or pose topic), fed like odometry;
and the ego speed from a logged velocity (:class:`SpeedTrack`).

Extrinsic convention (documented default, KITTI's): the body (IMU / ``base_link``) frame is
x forward, y left, z up; the camera frame is x right, y down, z forward. A body orientation
``R_world_body(t)`` becomes the camera rotation relative to the first sample

    ``R_world_cam(t) = R_cam_body · R_world_body(t0)ᵀ · R_world_body(t) · R_cam_bodyᵀ``

(as :func:`slopedist.odometry.posefiles.read_oxts_rotations`), with ``R_cam_body`` =
:data:`~slopedist.odometry.posefiles.R_CAM_VEHICLE_NOMINAL` unless another is given (a camera
pitched down on its mount is handled by the camera's mount angle, not here).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation, Slerp

from slopedist.core.errors import DataMismatchError, InputFileError
from slopedist.odometry.base import OdometryResult, OdometryState, RotationTrack
from slopedist.odometry.posefiles import R_CAM_VEHICLE_NOMINAL

MAX_EXTRAPOLATION_S = 0.05
"""How far before the first or after the last orientation sample a frame may lie and still get
the nearest sample's rotation, seconds; further out the frame's state is ``lost``
(``not_initialised`` before the first sample)."""


def camera_rotations(
    timestamps_s: ArrayLike,
    quaternions_xyzw: ArrayLike,
    R_cam_body: ArrayLike | None = None,
) -> RotationTrack:
    """Body orientations (``(N, 4)`` x y z w, body-to-world) → camera rotations relative to the
    first sample (see the module docstring). Samples with a repeated or decreasing timestamp are
    dropped (the first of equal stamps is kept).

    Raises:
        DataMismatchError: shapes that do not agree, or a quaternion of norm far from 1.
    """
    t = np.asarray(timestamps_s, dtype=float)
    q = np.asarray(quaternions_xyzw, dtype=float)
    if q.ndim != 2 or q.shape != (t.shape[0], 4):
        raise DataMismatchError(f"quaternions must be (N, 4) with N = {t.shape[0]}, got {q.shape}")
    norms = np.linalg.norm(q, axis=1)
    if np.any(np.abs(norms - 1.0) > 1e-2):
        k = int(np.argmax(np.abs(norms - 1.0) > 1e-2))
        raise DataMismatchError(f"orientation {k} has a quaternion of norm {norms[k]:.4f}, not 1")
    if t.size == 0:
        raise DataMismatchError("no orientation samples")
    keep = np.concatenate([[True], t[1:] > np.maximum.accumulate(t)[:-1]])
    t, q = t[keep], q[keep] / norms[keep, None]
    C = np.asarray(R_CAM_VEHICLE_NOMINAL if R_cam_body is None else R_cam_body, dtype=float)
    R_body = Rotation.from_quat(q).as_matrix()
    R_cam = C @ (R_body[0].T @ R_body) @ C.T
    return RotationTrack.from_arrays(t, R_cam)


class TrackRotationSource:
    """A :class:`~slopedist.odometry.base.RotationTrack` served frame by frame like visual
    odometry (:class:`~slopedist.odometry.base.RotationOdometry`): the rotation at a frame's
    time is the spherical interpolation of the two samples around it.

    Rotations are returned relative to the track's first sample (the look-back of the gradient
    only uses relative rotations). Frames before the first sample are ``not_initialised``,
    frames after the last one (beyond :data:`MAX_EXTRAPOLATION_S`) ``lost``.
    """

    def __init__(self, track: RotationTrack, name: str = "log") -> None:
        if len(track) == 0:
            raise InputFileError(name, "no orientation samples")
        self.track = track
        self.name = name
        self._slerp = (
            Slerp(track.timestamps_s, Rotation.from_matrix(track.R_world_cam))
            if len(track) > 1
            else None
        )

    def rotation_at(self, timestamp_s: float) -> NDArray[np.float64] | None:
        """Camera-to-world rotation ``(3, 3)`` at ``timestamp_s`` seconds, or None outside."""
        t = self.track.timestamps_s
        if timestamp_s < t[0] - MAX_EXTRAPOLATION_S or timestamp_s > t[-1] + MAX_EXTRAPOLATION_S:
            return None
        if self._slerp is None or timestamp_s <= t[0]:
            return np.asarray(self.track.R_world_cam[0], dtype=float)
        if timestamp_s >= t[-1]:
            return np.asarray(self.track.R_world_cam[-1], dtype=float)
        return np.asarray(self._slerp([timestamp_s]).as_matrix()[0], dtype=float)

    def process(
        self,
        image_gray: NDArray[np.uint8],
        timestamp_s: float,
        mask_boxes: NDArray[np.float64] | None = None,
    ) -> OdometryResult:
        """The rotation at ``timestamp_s`` (the pixels are not used)."""
        R = self.rotation_at(timestamp_s)
        if R is not None:
            return OdometryResult(R, OdometryState.OK)
        before = timestamp_s < self.track.timestamps_s[0]
        return OdometryResult(None, OdometryState.NOT_INITIALISED if before else OdometryState.LOST)

    def reset(self) -> None:
        """Nothing to reset (the track is fixed)."""


class SpeedTrack:
    """Ego speed over time (m/s), linearly interpolated at a frame's time (seconds); NaN more
    than :data:`MAX_EXTRAPOLATION_S` outside the samples.

    Args:
        timestamps_s: ``(N,)`` sample times, seconds, on the frames' time axis (increasing;
            repeated times are dropped).
        speeds_mps: ``(N,)`` speeds, m/s.
    """

    def __init__(self, timestamps_s: ArrayLike, speeds_mps: ArrayLike) -> None:
        t = np.asarray(timestamps_s, dtype=float).reshape(-1)
        v = np.asarray(speeds_mps, dtype=float).reshape(-1)
        if t.size == 0 or t.shape != v.shape:
            raise DataMismatchError(
                f"need as many speeds as times (≥ 1), got {v.size} and {t.size}"
            )
        keep = np.concatenate([[True], t[1:] > np.maximum.accumulate(t)[:-1]])
        self.t, self.v = t[keep], v[keep]

    def __call__(self, timestamp_s: float) -> float:
        """Speed at ``timestamp_s`` seconds, m/s (NaN outside the samples)."""
        if not self.t[0] - MAX_EXTRAPOLATION_S <= timestamp_s <= self.t[-1] + MAX_EXTRAPOLATION_S:
            return float("nan")
        return float(np.interp(timestamp_s, self.t, self.v))
