"""Settings and diagnostics of the built-in visual odometry (:mod:`slopedist.odometry.visual`).

Pixels are pixels of the working frames (the input frames, or their copies scaled down to
``max_width_px`` wide: :mod:`~slopedist.odometry.working_size`), times seconds, angles radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from slopedist.core.errors import ConfigurationError
from slopedist.odometry.base import LOOKBACK_S


@dataclass(frozen=True)
class VisualOdometryConfig:
    """Parameters of :class:`~slopedist.odometry.visual.BuiltinVisualOdometry` (pixels of the
    working frames).

    Attributes:
        lookback_s: interval over which rotations are estimated directly, seconds; use the same
            look-back as the gradient (1 s).
        max_features: number of tracks kept alive.
        min_feature_distance_px: minimum distance between tracks, pixels.
        corner_quality: Shi–Tomasi quality level relative to the best corner of the frame.
        klt_window_px: side of the Lucas–Kanade window, pixels.
        klt_levels: pyramid levels above the full-resolution image.
        klt_iterations: maximum Lucas–Kanade iterations per level.
        klt_max_error: tracks whose mean absolute patch difference (grey levels) exceeds this
            are dropped.
        inlier_threshold_px: inlier threshold and robust-loss scale of the fits, pixels.
        outlier_px: tracks with a larger residual in a fit are dropped, pixels.
        min_inliers: fewer inliers than this make a frame ``LOST``.
        min_inlier_ratio: fits explaining a smaller fraction of the tracks are retried with
            OpenCV's USAC solver and, failing that, rejected.
        static_parallax_px: when the rotation-only model explains the tracks with a median
            residual below this (pixels), it is used instead of the essential matrix.
        max_bridge_s: after this long without a good frame, tracking restarts (new segment).
        max_history_frames: hard cap on the frame records kept for the look-back.
        fuse_frame_to_frame: when the direct fit reaches further back than the previous frame,
            fuse it with the rotation chained from the previous frame's (information-weighted:
            the chain helps where the direct fit is weak, e.g. yaw against a sideways
            translation with few tracks).
        frame_to_frame_floor_rad: standard deviation added per axis to every frame-to-frame
            step of the chain, radians: a fit between consecutive frames has systematic errors
            its residuals do not show (on the rendered hills about 0.005–0.01° per step, in
            pitch and roll, the same sign from step to step), which add up over the ten steps of
            a look-back; without this floor the fusion trusts the chain most where it is
            biased.
        affine_refinement: refine every Lucas–Kanade position with an affine fit of the patch
            (:mod:`~slopedist.odometry.affine_refine`; its stretch and shear bias the
            translational fit on the road near the camera).
        max_width_px: frames wider than this (pixels) are tracked scaled down to this width,
            equally in both axes (:mod:`~slopedist.odometry.working_size`); None: never. The
            default keeps KITTI's 1242 px frames as they are and tracks 1920×1080 video at
            1280×720: θ as accurate (within 0.01° of full resolution, and no worse against
            the ground truth on the KITTI excerpts scaled to 1920 px), 25 % less processor
            time (``benchmarks/realtime.py --part widths``); 960 px loses accuracy.
    """

    lookback_s: float = LOOKBACK_S
    max_features: int = 250
    min_feature_distance_px: float = 12.0
    corner_quality: float = 0.01
    klt_window_px: int = 11
    klt_levels: int = 3
    klt_iterations: int = 12
    klt_max_error: float = 40.0
    inlier_threshold_px: float = 1.0
    outlier_px: float = 3.0
    min_inliers: int = 20
    min_inlier_ratio: float = 0.5
    static_parallax_px: float = 0.7
    max_bridge_s: float = 0.5
    max_history_frames: int = 256
    fuse_frame_to_frame: bool = True
    frame_to_frame_floor_rad: float = math.radians(0.02)
    affine_refinement: bool = True
    max_width_px: int | None = 1280

    def __post_init__(self) -> None:
        positive = (
            "lookback_s",
            "min_feature_distance_px",
            "corner_quality",
            "klt_max_error",
            "inlier_threshold_px",
            "outlier_px",
            "static_parallax_px",
            "max_bridge_s",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigurationError(f"visual odometry {name} must be > 0, got {value}")
        if self.max_features < self.min_inliers or self.min_inliers < 8:
            raise ConfigurationError(
                "visual odometry needs 8 ≤ min_inliers ≤ max_features, got "
                f"min_inliers={self.min_inliers}, max_features={self.max_features}"
            )
        if self.klt_window_px < 5 or self.klt_levels < 0 or self.klt_iterations < 1:
            raise ConfigurationError("klt_window_px ≥ 5, klt_levels ≥ 0, klt_iterations ≥ 1")
        if not 0 < self.min_inlier_ratio <= 1:
            raise ConfigurationError("min_inlier_ratio must lie in (0, 1]")
        if self.max_width_px is not None and self.max_width_px < 64:
            raise ConfigurationError(
                f"visual odometry max_width_px must be ≥ 64 or None, got {self.max_width_px}"
            )
        if self.max_history_frames < 2:
            raise ConfigurationError("max_history_frames must be ≥ 2")
        if not (
            math.isfinite(self.frame_to_frame_floor_rad) and self.frame_to_frame_floor_rad >= 0
        ):
            raise ConfigurationError(
                "visual odometry frame_to_frame_floor_rad must be ≥ 0, got "
                f"{self.frame_to_frame_floor_rad}"
            )


@dataclass(frozen=True)
class FitInfo:
    """Diagnostics of the last rotation fit.

    Attributes:
        interval_s: time between the reference frame and the current one, seconds (the
            look-back when the tracks allow it).
        correspondences: tracks common to both frames.
        inliers: inliers of the fit.
        model: ``"rotation"`` (no parallax) or ``"essential"``.
        usac: True when the local fit failed and OpenCV's USAC solver was used.
    """

    interval_s: float
    correspondences: int
    inliers: int
    model: str
    usac: bool
