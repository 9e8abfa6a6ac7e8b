"""Camera intrinsics from views of a checkerboard (OpenCV's detector and ``calibrateCamera``).

The board has ``pattern = (columns, rows)`` *inner* corners spaced ``square_m`` metres. Corners
are found with ``cv2.findChessboardCornersSB`` (sub-pixel accurate), at most ``max_views``
views spread evenly over the frames are kept, and ``cv2.calibrateCamera`` fits ``fx, fy, cx,
cy`` and the five distortion coefficients ``k1, k2, p1, p2, k3``. The fit reports its RMS
reprojection error in pixels and warns when the views cannot pin the camera down:

- fewer than :data:`MIN_GOOD_VIEWS` views with the board found;
- the board's tilt varies by less than :data:`MIN_TILT_SPREAD_DEG` between views (fronto-parallel
  views leave the focal length and principal point poorly determined);
- the corners cover less than :data:`MIN_COVERAGE` of the image (distortion near the edges is
  then extrapolated);
- an RMS reprojection error above :data:`MAX_GOOD_RMS_PX`.

:func:`write_opencv_yaml` writes the OpenCV FileStorage YAML that
:func:`slopedist.io.calibration.read_calibration` (``--calib``) reads.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import ConfigurationError, DataMismatchError
from slopedist.core.paths import utf8_name
from slopedist.io.intrinsics import Intrinsics

MIN_VIEWS = 3
"""Fewest views with the board found for a fit at all."""
MIN_GOOD_VIEWS = 10
"""Fewer views than this give a warning."""
MIN_TILT_SPREAD_DEG = 20.0
"""Largest angle between two views' board normals below which the views are too similar."""
MIN_POSE_SPREAD_DEG = 1.0
"""Largest angle between two views' board normals below which every view shows the board at one
tilt: a plane seen at one pose gives two of the camera's constraints, so the focal length is not
determined and no fit is reported (one board pose filmed 12 times fitted fx = 493 px for 500 with
an RMS of 0.03 px, only warned about)."""
MIN_COVERAGE = 0.4
"""Fraction of the image the corners' convex hull (over all views) must cover."""
MAX_GOOD_RMS_PX = 1.0
"""RMS reprojection error above which the fit is suspect, pixels."""


@dataclass(frozen=True)
class CheckerboardFit:
    """Result of :func:`calibrate_checkerboard`.

    Attributes:
        intrinsics: fitted K (pixels) and distortion ``k1, k2, p1, p2, k3``, with the image size.
        rms_px: RMS reprojection error over all corners, pixels.
        n_frames: frames examined.
        n_views: views with the board found and used in the fit.
        tilt_spread_deg: largest angle between two views' board normals, degrees.
        coverage: fraction of the image inside the convex hull of all corners.
        warnings: reasons the fit may be unreliable (empty = none).
        corners: the used views' corners, each ``(cols·rows, 2)`` pixels.
        n_found: frames with the board found (``n_views`` of them are used, at most
            ``max_views``).
    """

    intrinsics: Intrinsics
    rms_px: float
    n_frames: int
    n_views: int
    tilt_spread_deg: float
    coverage: float
    warnings: tuple[str, ...]
    corners: tuple[NDArray[np.float32], ...] = ()
    n_found: int = 0


def board_points(pattern: tuple[int, int], square_m: float) -> NDArray[np.float32]:
    """The inner corners on the board plane, ``(cols·rows, 3)`` metres, row by row, z = 0."""
    cols, rows = pattern
    grid = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square_m
    return np.c_[grid, np.zeros(len(grid))].astype(np.float32)


def find_corners(image: NDArray[np.uint8], pattern: tuple[int, int]) -> NDArray[np.float32] | None:
    """The board's inner corners in ``image`` (``(cols·rows, 2)`` pixels) or None if not found."""
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if not cv2.checkChessboard(gray, pattern):  # quick rejection of frames without the board
        return None
    found, corners = cv2.findChessboardCornersSB(
        gray, pattern, flags=cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_ACCURACY
    )
    return np.asarray(corners, np.float32).reshape(-1, 2) if found else None


def _tilt_spread_deg(rvecs: list[NDArray]) -> float:
    normals = np.array([cv2.Rodrigues(r)[0][:, 2] for r in rvecs])
    cosines = np.clip(np.abs(normals @ normals.T), -1.0, 1.0)
    return float(np.degrees(np.arccos(cosines.min())))


def _coverage(corners: list[NDArray], size: tuple[int, int]) -> float:
    hull = cv2.convexHull(np.concatenate(corners).astype(np.float32))
    return float(cv2.contourArea(hull) / (size[0] * size[1]))


def _warnings(
    n_views: int, n_found: int, spread: float, coverage: float, rms: float
) -> tuple[str, ...]:
    out = []
    if n_found < MIN_GOOD_VIEWS:
        out.append(f"only {n_found} views with the board found; use ≥ {MIN_GOOD_VIEWS}")
    elif n_views < MIN_GOOD_VIEWS:
        out.append(
            f"only {n_views} of the {n_found} views fitted; use --max-views ≥ {MIN_GOOD_VIEWS}"
        )
    if spread < MIN_TILT_SPREAD_DEG:
        out.append(
            f"views too similar: the board's tilt varies by {spread:.1f}° "
            f"(< {MIN_TILT_SPREAD_DEG:.0f}°); tilt it towards and away from the camera"
        )
    if coverage < MIN_COVERAGE:
        out.append(
            f"corners cover {100 * coverage:.0f} % of the image (< {100 * MIN_COVERAGE:.0f} %); "
            "move the board into the corners and edges"
        )
    if rms > MAX_GOOD_RMS_PX:
        out.append(f"RMS reprojection error {rms:.2f} px > {MAX_GOOD_RMS_PX} px")
    return tuple(out)


def calibrate_checkerboard(
    images: Iterable[NDArray[np.uint8]],
    pattern: tuple[int, int],
    square_m: float = 1.0,
    max_views: int = 40,
) -> CheckerboardFit:
    """Fit intrinsics to the checkerboard views in ``images`` (all of one camera and size).

    Raises:
        ConfigurationError: a pattern under 2×2 inner corners or a non-positive square size.
        DataMismatchError: frames of different sizes, fewer than :data:`MIN_VIEWS` views, or
            views of one board pose only (:data:`MIN_POSE_SPREAD_DEG`).
    """
    if min(pattern) < 2 or square_m <= 0:
        raise ConfigurationError(
            f"checkerboard needs ≥ 2×2 inner corners and a square size > 0, got {pattern}, "
            f"{square_m}"
        )
    found: list[NDArray[np.float32]] = []
    size: tuple[int, int] | None = None
    n_frames = 0
    for image in images:
        n_frames += 1
        h, w = image.shape[:2]
        if size is not None and size != (w, h):
            raise DataMismatchError(
                f"frame {n_frames - 1} is {w}×{h}, the first {size[0]}×{size[1]}"
            )
        size = (w, h)
        corners = find_corners(image, pattern)
        if corners is not None:
            found.append(corners)
    if size is None or len(found) < MIN_VIEWS:
        raise DataMismatchError(
            f"checkerboard ({pattern[0]}×{pattern[1]} inner corners) found in {len(found)} of "
            f"{n_frames} frames; at least {MIN_VIEWS} are needed"
        )
    keep = np.unique(np.linspace(0, len(found) - 1, min(max_views, len(found))).round().astype(int))
    views = [found[i] for i in keep]
    obj = [board_points(pattern, square_m)] * len(views)
    rms, K, dist, rvecs, _ = cv2.calibrateCamera(
        obj, [v.reshape(-1, 1, 2) for v in views], size, None, None
    )
    spread, coverage = _tilt_spread_deg(list(rvecs)), _coverage(views, size)
    if spread < MIN_POSE_SPREAD_DEG:
        raise DataMismatchError(
            f"the focal length is not determined: the board ({pattern[0]}×{pattern[1]}) is seen "
            f"at one tilt in all {len(views)} views (its tilt varies by {spread:.2f}° < "
            f"{MIN_POSE_SPREAD_DEG:g}°); film it tilted towards and away from the camera"
        )
    intrinsics = Intrinsics(np.asarray(K, float), np.asarray(dist, float).reshape(-1), False, size)
    return CheckerboardFit(
        intrinsics,
        float(rms),
        n_frames,
        len(views),
        spread,
        coverage,
        _warnings(len(views), len(found), spread, coverage, float(rms)),
        tuple(views),
        len(found),
    )


def write_opencv_yaml(fit: CheckerboardFit, path: str | Path) -> Path:
    """Write the fit as an OpenCV FileStorage YAML: ``camera_matrix``,
    ``distortion_coefficients``, ``image_width``/``image_height`` and
    ``rms_reprojection_error_px``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    intr = fit.intrinsics
    with utf8_name(path) as name:  # (alive until the file is written: release)
        fs = cv2.FileStorage(name, cv2.FILE_STORAGE_WRITE)
        try:
            if intr.image_size is not None:
                fs.write("image_width", int(intr.image_size[0]))
                fs.write("image_height", int(intr.image_size[1]))
            fs.write("camera_matrix", intr.K)
            fs.write("distortion_coefficients", intr.dist.reshape(1, -1))
            fs.write("rms_reprojection_error_px", float(fit.rms_px))
            fs.write("n_views", int(fit.n_views))
        finally:
            fs.release()
    return path
