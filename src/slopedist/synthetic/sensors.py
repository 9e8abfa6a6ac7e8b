"""Simulated sensors of the synthetic scenes: the true rotations as an odometry, an IMU's
noisy rotations and a depth network's noisy depth maps (used by ``slopedist demo``).

Convention: rotations camera-to-world ``(3, 3)``; depth in metres; radians inside.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from slopedist.odometry.base import OdometryResult, OdometryState

FloatArray = NDArray[np.float64]

IMU_PITCH_NOISE_RAD = math.radians(0.03)
"""Standard deviation of the simulated IMU's pitch and roll error per frame (an OXTS RT3000 is
specified at 0.03°), radians."""
DEPTH_SCALE_SIGMA = 0.05
"""Simulated depth network: per-frame log-scale error (5 %)."""
DEPTH_PIXEL_SIGMA = 0.03
"""Simulated depth network: per-pixel log error (3 %)."""


class TrueRotationOdometry:
    """Rotation source that returns the scene's true camera rotations (a diagnostic: it
    separates odometry error from method error; ``slopedist demo --odometry truth``)."""

    def __init__(self, R_world_cam: FloatArray) -> None:
        self._R = R_world_cam
        self._k = 0

    def process(
        self,
        image_gray: NDArray[np.uint8],
        timestamp_s: float,
        mask_boxes: NDArray[np.float64] | None = None,
    ) -> OdometryResult:
        R = self._R[self._k]
        self._k += 1
        return OdometryResult(R, OdometryState.OK, 0)

    def reset(self) -> None:
        self._k = 0


def imu_rotations(R_true: FloatArray, seed: int) -> FloatArray:
    """True camera rotations with IMU-like pitch and roll noise (radians, per frame)."""
    rng = np.random.default_rng([seed, 0x1A1])
    eps = rng.normal(0.0, IMU_PITCH_NOISE_RAD, (len(R_true), 3)) * np.array([1.0, 0.0, 1.0])
    return np.asarray(R_true @ Rotation.from_rotvec(eps).as_matrix())


class DepthNoise:
    """Simulated metric depth network: true depth × per-frame scale × per-pixel noise."""

    def __init__(self, height: int, width: int, seed: int) -> None:
        rng = np.random.default_rng([seed, 0xDE9])
        self._field = np.exp(rng.normal(0.0, DEPTH_PIXEL_SIGMA, (2 * height, 2 * width))).astype(
            np.float32
        )
        self._seed = seed
        self._h, self._w = height, width

    def __call__(self, depth: NDArray[np.float32], k: int) -> NDArray[np.float32]:
        scale = math.exp(
            np.random.default_rng([self._seed, k, 0xDE9]).normal(0.0, DEPTH_SCALE_SIGMA)
        )
        oy, ox = (k * 131) % self._h, (k * 977) % self._w
        out = depth * self._field[oy : oy + self._h, ox : ox + self._w] * np.float32(scale)
        out[~np.isfinite(depth)] = np.nan
        return np.asarray(out, dtype=np.float32)
