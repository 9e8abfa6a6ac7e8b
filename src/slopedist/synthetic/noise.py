"""Detector realism: noise applied to the exact 2D boxes of the synthetic scenes.

Convention: boxes ``(left, top, right, bottom)`` in pixels, origin top-left. Noise is drawn from
``numpy.random.default_rng([seed, frame, row])``, so a target's noise depends only on the seed,
the frame index and its row (deterministic, whatever the order frames are processed in and
whichever other targets are in view).

Model, per detection: the box is scaled about its centre by ``1 + ε`` with ``ε ~ N(0,
scale_sigma)`` (one factor for width and height: a detector that misjudges the size), then
each edge moves by ``N(0, jitter_px)`` pixels; it is missed with probability ``miss_rate``; a
target whose visible share (not hidden by the road or another vehicle) is below
``min_visible``, or whose box is lower than ``min_height_px``, is never detected; with
``truncate`` the noisy box is clipped to the image like a detector's output.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.core.errors import ConfigurationError


@dataclass(frozen=True)
class BoxNoiseSpec:
    """Parameters of the box-noise model (see the module docstring).

    Attributes:
        jitter_px: standard deviation of each edge's displacement, pixels.
        scale_sigma: standard deviation of the relative size error (0.03 = 3 %).
        miss_rate: probability that a detectable target is missed in a frame.
        truncate: clip noisy boxes to the image.
        min_visible: smallest visible share of a target that is detected (0..1).
        min_height_px: smallest box height that is detected, pixels.
    """

    jitter_px: float = 1.0
    scale_sigma: float = 0.02
    miss_rate: float = 0.03
    truncate: bool = True
    min_visible: float = 0.3
    min_height_px: float = 12.0

    def __post_init__(self) -> None:
        for name in ("jitter_px", "scale_sigma", "miss_rate", "min_visible", "min_height_px"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ConfigurationError(f"noise {name} must be a finite number ≥ 0, got {value}")
        if self.miss_rate > 1 or self.min_visible > 1:
            raise ConfigurationError("noise miss_rate and min_visible must be ≤ 1")
        if self.scale_sigma > 0.5:
            raise ConfigurationError(f"noise scale_sigma must be ≤ 0.5, got {self.scale_sigma}")

    @classmethod
    def exact(cls) -> BoxNoiseSpec:
        """No noise and no misses (still only visible, large-enough targets are detected)."""
        return cls(0.0, 0.0, 0.0, True, 0.3, 12.0)


def _normal_cdf(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Standard normal CDF (turns a normal draw into a uniform one)."""
    from scipy.special import ndtr

    return np.asarray(ndtr(x))


def detectable(boxes: ArrayLike, visible_share: ArrayLike, spec: BoxNoiseSpec) -> NDArray[np.bool_]:
    """Which exact boxes ``(N, 4)`` a detector could report (visible and tall enough)."""
    b = np.asarray(boxes, dtype=float).reshape(-1, 4)
    vis = np.asarray(visible_share, dtype=float).reshape(-1)
    tall = (b[:, 3] - b[:, 1]) >= spec.min_height_px
    return np.asarray(np.all(np.isfinite(b), axis=1) & tall & (vis >= spec.min_visible))


def noisy_boxes(
    boxes: ArrayLike,
    visible_share: ArrayLike,
    spec: BoxNoiseSpec,
    image_size: tuple[int, int],
    seed: int,
    frame: int,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Apply the noise model to one frame's exact boxes.

    Args:
        boxes: ``(N, 4)`` exact boxes (NaN rows = target not in view).
        visible_share: ``(N,)`` share of each target's pixels that is visible (0..1).
        spec: noise parameters.
        image_size: ``(width, height)`` pixels.
        seed: the scenario's seed; frame: the frame index.

    Returns:
        ``(noisy boxes (N, 4), detected (N,) bool)``; rows not detected are NaN.
    """
    b = np.asarray(boxes, dtype=float).reshape(-1, 4)
    n = b.shape[0]
    # one generator per row (target), drawn whether it is in view or not: the noise of a
    # target depends only on the seed, the frame and its row
    draws = np.array(
        [
            np.random.default_rng([int(seed) & 0xFFFFFFFF, int(frame), i, 0xB0C5]).standard_normal(
                6
            )
            for i in range(n)
        ]
    ).reshape(n, 6)
    eps = draws[:, 0] * spec.scale_sigma
    jitter = draws[:, 1:5] * spec.jitter_px
    miss = _normal_cdf(draws[:, 5]) < spec.miss_rate
    found = detectable(b, visible_share, spec) & ~miss
    cx = 0.5 * (b[:, 0] + b[:, 2])
    cy = 0.5 * (b[:, 1] + b[:, 3])
    hw = 0.5 * (b[:, 2] - b[:, 0]) * (1.0 + eps)
    hh = 0.5 * (b[:, 3] - b[:, 1]) * (1.0 + eps)
    out = np.stack([cx - hw, cy - hh, cx + hw, cy + hh], axis=1) + jitter
    if spec.truncate:
        w, h = image_size
        out = np.clip(out, [0.0, 0.0, 0.0, 0.0], [w - 1.0, h - 1.0, w - 1.0, h - 1.0])
    found &= (out[:, 2] > out[:, 0] + 1.0) & (out[:, 3] > out[:, 1] + 1.0)
    out[~found] = np.nan
    return out, found
