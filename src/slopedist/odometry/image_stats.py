"""Image statistics the built-in visual odometry tracks through: exposure, sharpness, global shift.

Lucas–Kanade assumes constant brightness and equal sharpness between two frames; these functions
measure a frame's grey-level statistics and sharpness and map one frame onto another's, so that
an exposure jump or a blurred frame can be tracked (:mod:`slopedist.odometry.visual`).

Convention: images are single-channel uint8 ``H×W``; shifts in pixels ``(dx, dy)``.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def half_size(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Half-resolution copy (2×2 block means; an odd last row/column is dropped)."""
    h, w = image.shape
    even = image[: h - h % 2, : w - w % 2]
    return np.asarray(cv2.resize(even, (w // 2, h // 2), interpolation=cv2.INTER_AREA))


MIN_EXPOSURE_STD = 2.0
"""Frames whose grey-level standard deviation is below this (blank, black) are not rescaled."""
EXPOSURE_JUMP_LEVELS = 16.0
"""Frames whose exposure match (:func:`match_exposure`) moves some grey level by this much are
tracked matched from the start. Between KITTI frames, changes of the scene alone move the
mean by up to ~7 levels and the spread by up to ~7 %, which maps some level by at most ~15."""
MIN_EXPOSURE_CHANGE = 3.0
"""After a failed frame, an exposure match that moves no grey level by this much (levels) is
not worth a retry."""


def grey_stats(image: NDArray[np.uint8]) -> tuple[float, float]:
    """Mean and standard deviation of a frame's grey levels."""
    mean, std = (float(v) for v in np.ravel(cv2.meanStdDev(image)))
    return mean, std


def match_exposure(
    image: NDArray[np.uint8],
    reference: NDArray[np.uint8],
    min_change: float,
    image_stats: tuple[float, float] | None = None,
    reference_stats: tuple[float, float] | None = None,
) -> NDArray[np.uint8] | None:
    """``image`` with its grey levels mapped affinely to the mean and standard deviation of
    ``reference`` (a global gain and offset, as an exposure or gain change of the camera makes).

    ``image_stats``, ``reference_stats``: the frames' :func:`grey_stats` when already known.
    Returns None when either frame is nearly uniform (nothing to match) or when the mapping
    would change no grey level by ``min_change`` (grey levels) or more.
    """
    mean_i, std_i = grey_stats(image) if image_stats is None else image_stats
    mean_r, std_r = grey_stats(reference) if reference_stats is None else reference_stats
    if std_i < MIN_EXPOSURE_STD or std_r < MIN_EXPOSURE_STD:
        return None
    gain = std_r / std_i
    levels = np.arange(256, dtype=np.float64)
    mapped = np.clip(np.rint(mean_r + gain * (levels - mean_i)), 0, 255)
    if np.max(np.abs(mapped - levels)) < min_change:
        return None
    return np.asarray(cv2.LUT(image, mapped.astype(np.uint8)))


SHARPNESS_RATIO = 1.5
"""When one of two consecutive frames has this many times the other's gradient energy, the
sharper one is blurred to match before tracking. Between the shared KITTI frames the ratio
stays below 1.23; a Gaussian blur of 1.3–1.4 px reaches 1.5."""
MAX_BLUR_RATIO = 8.0
"""A frame with less than 1/this of the previous good frame's gradient energy (a Gaussian blur
of about 4 px on KITTI frames) is ``LOST``, and the next sharp frame is tracked from the last
sharp one: on the sharp turn with three frames blurred by 10 px that gives θ 0.09° RMS, against
0.15° when they are tracked."""
BLUR_SIGMAS_PX = (0.7, 1.0, 1.4, 2.0, 2.8, 4.0, 5.6, 8.0)
"""Gaussian blurs tried by :func:`blur_to_energy`, pixels."""


def gradient_energy(image: NDArray[np.uint8], small: NDArray[np.uint8] | None = None) -> float:
    """Sharpness of a frame: the mean squared Sobel gradient of its half-size copy divided by
    its grey-level variance (per pixel², independent of the exposure's gain and offset);
    comparable between frames of the same scene. ``small``: the half-size copy
    (:func:`half_size`) when already made."""
    if small is None:
        small = half_size(image)
    square_sum = 0.0
    for gradient in cv2.spatialGradient(small):  # the int16 3×3 Sobel x and y gradients
        mean, std = mean_std(gradient)
        square_sum += std**2 + mean**2  # E[g²], per axis
    grey_std = float(cv2.meanStdDev(small)[1][0, 0])
    return square_sum / max(grey_std**2, 1.0)


def mean_std(values: NDArray[np.integer | np.floating]) -> tuple[float, float]:
    """Mean and standard deviation of integer-valued ``values`` exactly as ``cv2.meanStdDev``
    gives them (its formulas on the exact sum and sum of squares), without its slow int16
    path (the sums are exact while below 2⁵³)."""
    v = np.asarray(values, dtype=np.float64).ravel()
    scale = 1.0 / max(v.size, 1)
    # integers: both sums are exact in float64 (below 2⁵³), whatever the order of the additions
    # (no BLAS dot: OpenBLAS would spread it over threads that spin when the cores are busy)
    mean = float(np.add.reduce(v)) * scale
    square_sum = float(np.add.reduce(v * v))
    return mean, math.sqrt(max(square_sum * scale - mean * mean, 0.0))


def blur_to_energy(image: NDArray[np.uint8], target: float) -> NDArray[np.uint8]:
    """``image`` blurred (Gaussian, one of :data:`BLUR_SIGMAS_PX`) so that its
    :func:`gradient_energy` comes closest to ``target`` (that of a blurrier frame of the same
    scene)."""
    best: tuple[float, NDArray[np.uint8]] = (math.inf, image)
    for sigma in BLUR_SIGMAS_PX:
        blurred: NDArray[np.uint8] = np.asarray(
            cv2.GaussianBlur(image, (0, 0), sigma), dtype=np.uint8
        )
        gap = abs(math.log(max(gradient_energy(blurred), 1e-9) / max(target, 1e-9)))
        if gap >= best[0]:
            break  # the energy falls with sigma: past the closest one
        best = (gap, blurred)
    return best[1]


def global_shift(image_a: NDArray[np.uint8], image_b: NDArray[np.uint8]) -> FloatArray:
    """Dominant image shift a → b in pixels ``(2,)`` by phase correlation at quarter size."""
    h, w = image_a.shape
    size = (max(w // 4, 8), max(h // 4, 8))
    a = cv2.resize(image_a, size, interpolation=cv2.INTER_AREA).astype(np.float32)
    b = cv2.resize(image_b, size, interpolation=cv2.INTER_AREA).astype(np.float32)
    (dx, dy), response = cv2.phaseCorrelate(a, b)
    if not (math.isfinite(dx) and math.isfinite(dy)) or response < 0.05:
        return np.zeros(2)
    return np.array([dx * w / size[0], dy * h / size[1]])
