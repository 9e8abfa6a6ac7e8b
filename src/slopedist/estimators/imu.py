"""The IMU baseline (Qi et al. 2019): the ego road gradient from an IMU instead of visual
odometry.

``imu`` is the paper's estimator (ego gradient θ of eq. 2–4, vanishing line of eq. 5, per-target
adjustment of eq. 6–7, distance of eq. 1) fed with the rotations of the vehicle's GPS/IMU
(KITTI's OXTS poses) rather than ORB-SLAM3 or the built-in visual odometry ("paper"-style).
``imu-ego`` is the same without the eq. 7 adjustment (Qi et al.'s own form, "ego"-style).
Comparing ``imu`` with ``paper`` measures how much visual odometry loses against an IMU.

Both declare :attr:`rotation_source` = ``"oxts"``, so an evaluation feeds them OXTS rotations
whatever source it uses for the other methods; a sequence without OXTS poses has no ``imu`` row.
"""

from __future__ import annotations

from typing import ClassVar

from slopedist.estimators.ground_contact import EgoGradientEstimator, PaperEstimator

IMU_ROTATION_SOURCE = "oxts"
"""Value of :attr:`~slopedist.estimators.base.Estimator.rotation_source` of the IMU methods
(the name of :attr:`slopedist.io.kitti.tracking.RotationSource.OXTS`)."""


class ImuEstimator(PaperEstimator):
    """The paper's estimator driven by IMU (OXTS) rotations: Qi et al.'s IMU gradient + eq. 7."""

    name: ClassVar[str] = "imu"
    rotation_source: ClassVar[str | None] = IMU_ROTATION_SOURCE


class ImuEgoEstimator(EgoGradientEstimator):
    """Ego gradient from IMU (OXTS) rotations, no per-target adjustment (Qi et al. 2019)."""

    name: ClassVar[str] = "imu-ego"
    rotation_source: ClassVar[str | None] = IMU_ROTATION_SOURCE
