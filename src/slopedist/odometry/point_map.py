"""Tracked feature points of a real camera → the ideal pinhole the pose fit assumes.

The built-in odometry tracks corners in the frames as they are (never undistorted, which keeps
it fast) and fits the relative pose on normalised image coordinates ``(x/z, y/z, 1)``. With lens
distortion or ``fx ≠ fy`` the pixels must first be mapped into the ideal camera: a
``point_map`` (pixels of the real camera → pixels of the ideal one, e.g.
:meth:`slopedist.io.intrinsics.Intrinsics.rectify_points`, the one place that undistorts points)
does that before the normalisation with the ideal ``K``. Without a map the pixels are used as
they are (bit for bit the same as before). The built-in odometry's hook is its ``normalise``
attribute, set by ``make_odometry("builtin", camera, point_map=...)``.

A point the map cannot invert (NaN: near the corners of a strongly distorted lens) keeps its
unmapped position: one wrong point is an outlier that the robust fit down-weights, where a NaN
would spoil the whole fit.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from slopedist.odometry.twoview import normalise_pixels

FloatArray = NDArray[np.float64]
PointMap = Callable[[FloatArray], FloatArray]
"""``(N, 2)`` pixels of the real camera → ``(N, 2)`` pixels of the ideal camera (NaN where the
point cannot be mapped)."""


class PointNormaliser:
    """Pixels ``(N, 2)`` → normalised coordinates ``(N, 3)`` of the ideal camera ``K``.

    Args:
        K: 3×3 intrinsics of the ideal camera (pixels).
        point_map: the mapping of real pixels into the ideal camera, or None (ideal already).
    """

    def __init__(self, K: FloatArray, point_map: PointMap | None = None) -> None:
        self.K = np.asarray(K, dtype=float)
        self.point_map = point_map

    def pixels(self, uv: NDArray[np.floating]) -> NDArray[np.floating]:
        """Pixels in the ideal camera (``uv`` itself without a map)."""
        if self.point_map is None or len(uv) == 0:
            return uv
        raw = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        mapped = np.asarray(self.point_map(raw), dtype=np.float64).reshape(-1, 2)
        bad = ~np.all(np.isfinite(mapped), axis=1)
        mapped[bad] = raw[bad]
        return mapped.astype(np.asarray(uv).dtype, copy=False)

    def __call__(self, uv: NDArray[np.floating]) -> FloatArray:
        """Normalised homogeneous coordinates ``(N, 3)`` of the ideal camera."""
        return normalise_pixels(self.pixels(uv), self.K)
