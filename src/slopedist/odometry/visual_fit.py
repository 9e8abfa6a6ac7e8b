"""The two-view fits of :class:`~slopedist.odometry.visual.BuiltinVisualOdometry`: the pose of
the current frame against a reference frame from their tracks.

A rotation-only model when there is no parallax (standing car, only far points), else the
5-degree-of-freedom essential matrix refined on the Sampson distance
(:mod:`slopedist.odometry.twoview`) from the predicted rotation, with the translation started
along the chord of the car's arc; OpenCV's USAC essential-matrix search is the fallback, at
most once per frame, when the local fit does not explain most tracks.

Convention: camera frame x right, y down, z forward; pixels, radians; a fit maps reference to
current, ``X_cur = R X_ref + t``.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.odometry import twoview as tv
from slopedist.odometry.point_map import PointNormaliser
from slopedist.odometry.visual_config import FitInfo, VisualOdometryConfig
from slopedist.odometry.working_size import WorkingSize

FloatArray = NDArray[np.float64]

USAC_MAX_ITERATIONS = 300
"""Iteration cap of OpenCV's USAC essential-matrix search (the fallback of a failed local fit)."""

MAX_WARM_START_DEG = 15.0
"""A previous translation direction warm-starts a fit only within this angle of the chord."""


class TwoViewFitting:
    """The two-view fits of the built-in visual odometry, mixed into
    :class:`~slopedist.odometry.visual.BuiltinVisualOdometry`, which sets the state below.

    Attributes:
        camera: the full-frame camera; ``config``: the odometry's settings.
        normalise: full-frame pixels → ideal camera.
        last_fit: how the last fit went (None: no fit yet this frame).
    """

    camera: Camera
    config: VisualOdometryConfig
    normalise: PointNormaliser
    last_fit: FitInfo | None
    _f: float  # focal length of the working frames, pixels
    _heading: FloatArray  # the car's forward direction in the camera frame
    _t_last: dict[str, FloatArray]  # last translation direction per fit kind
    _usac_budget: int  # global searches left for the current frame
    _work: WorkingSize | None  # working and full frame sizes (None: not yet known)

    def _full(self, uv: NDArray[np.float32]) -> NDArray[np.float32]:
        """Working-frame pixels ``(N, 2)`` as full-frame pixels (the normaliser's)."""
        return uv if self._work is None else self._work.to_full(uv)

    def _fit(
        self,
        uv_ref: NDArray[np.float32],
        uv_cur: NDArray[np.float32],
        R_init: FloatArray,
        kind: str = "direct",
    ) -> tv.TwoViewFit | None:
        """Relative pose reference → current (``X_cur = R X_ref + t``) or None if unreliable.

        ``kind`` ("direct" or "f2f") selects which earlier translation warm-starts the fit.
        """
        c = self.config
        f = self._f
        x1, x2 = self.normalise(self._full(uv_ref)), self.normalise(self._full(uv_cur))
        n = len(x1)
        rot = tv.fit_rotation_only(x1, x2, f, c.inlier_threshold_px, R_init=R_init)
        if rot.n_inliers >= max(c.min_inliers, c.min_inlier_ratio * n) and (
            float(np.median(rot.residuals_px)) < c.static_parallax_px
        ):
            self.last_fit = FitInfo(0.0, n, rot.n_inliers, "rotation", False)
            return rot
        fit = self._refine(x1, x2, R_init, self._t_last.get(kind))
        usac = False
        if fit.n_inliers < c.min_inlier_ratio * n:  # poor prediction: start from the rotation
            other = self._refine(x1, x2, rot.R)
            fit = other if other.n_inliers > fit.n_inliers else fit
        if fit.n_inliers < c.min_inlier_ratio * n and self._usac_budget > 0:
            self._usac_budget -= 1  # at most one global search per frame (bounded time)
            global_fit = self._fit_usac(uv_ref, uv_cur, x1, x2)
            if global_fit is not None and global_fit.n_inliers > fit.n_inliers:
                fit = global_fit
            usac = True
        self.last_fit = FitInfo(0.0, n, fit.n_inliers, "essential", usac)
        if fit.n_inliers < max(c.min_inliers, c.min_inlier_ratio * n):
            return None
        self._t_last[kind] = fit.t
        return fit

    def _fit_usac(
        self,
        uv_ref: NDArray[np.float32],
        uv_cur: NDArray[np.float32],
        x1: FloatArray,
        x2: FloatArray,
    ) -> tv.TwoViewFit | None:
        """Global fallback: USAC essential matrix + cheirality, then the local refinement."""
        c = self.config
        uv_ref, uv_cur = (self.normalise.pixels(self._full(uv)) for uv in (uv_ref, uv_cur))
        threshold = c.inlier_threshold_px * (self.camera.f / self._f)  # full-frame pixels
        K = self.normalise.K
        E, mask = cv2.findEssentialMat(
            uv_ref, uv_cur, K, cv2.USAC_DEFAULT, 0.999, threshold, USAC_MAX_ITERATIONS
        )
        if E is None or E.shape != (3, 3):
            return None
        _, R, _, _ = cv2.recoverPose(E, uv_ref, uv_cur, K, mask=mask)
        return self._refine(x1, x2, np.asarray(R, dtype=np.float64))

    def _refine(
        self, x1: FloatArray, x2: FloatArray, R_init: FloatArray, t_last: FloatArray | None = None
    ) -> tv.TwoViewFit:
        """Essential-matrix refinement from ``R_init``.

        The translation starts along the chord of the car's arc (the heading turned by half the
        rotation), or from ``t_last`` (the previous fit of this kind) when that agrees with the
        chord within ``MAX_WARM_START_DEG``.
        """
        c = self.config
        t_init = tv.so3_exp(0.5 * tv.so3_log(R_init)) @ self._heading
        if t_last is not None and abs(float(t_last @ t_init)) > math.cos(
            math.radians(MAX_WARM_START_DEG)
        ):
            t_init = t_last if t_last @ t_init > 0 else -t_last
        return tv.fit_relative_pose(
            x1, x2, self._f, R_init, t_init, threshold_px=c.inlier_threshold_px
        )
