"""Class priors of ``ours`` as per-heading constants, computed once per class name.

The priors and the heading grid are fixed for an estimator, so each frame only gathers rows
(one fancy-indexing operation per frame) instead of recomputing them. Lengths in metres,
headings ψ in radians (the angle of a vehicle's length axis from the camera's z axis).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slopedist.estimators.ours import cues
from slopedist.estimators.ours.priors import DimensionPrior, prior_row, resolve_prior

FloatArray = NDArray[np.float64]

MIN_NEAR_M = 0.5
"""Smallest distance to a target's nearest face the cues accept, metres."""


class HypothesisConstants(NamedTuple):
    """Class constants per (target, heading hypothesis), each ``(n, K)``.

    Attributes:
        half_extent_m: the footprint's half depth extent e (centre to nearest face along z).
        half_extent_var_m2: its variance over the class's size spread.
        half_extent_sigma_m: its standard deviation.
        min_centre_depth_m: the smallest centre depth accepted (``e + MIN_NEAR_M``).
        height_m: the class's height H (repeated over the hypotheses).
        log_sigma_height, log_sigma_width, log_sigma_length: relative size spreads σ/size.
        corr_height_width: correlation of the height and width deviations.
        half_width_cos_m, half_width_sin_m, half_length_cos_m, half_length_sin_m:
            ``W cos ψ/2``, ``W sin ψ/2``, ``L cos ψ/2``, ``L sin ψ/2`` (the width cue's terms).
    """

    half_extent_m: FloatArray
    half_extent_var_m2: FloatArray
    half_extent_sigma_m: FloatArray
    min_centre_depth_m: FloatArray
    height_m: FloatArray
    log_sigma_height: FloatArray
    log_sigma_width: FloatArray
    log_sigma_length: FloatArray
    corr_height_width: FloatArray
    half_width_cos_m: FloatArray
    half_width_sin_m: FloatArray
    half_length_cos_m: FloatArray
    half_length_sin_m: FloatArray


class TargetClasses(NamedTuple):
    """The class constants of one frame's targets.

    Attributes:
        height_m: ``(n,)`` class height H.
        height_sigma_m: ``(n,)`` its spread σH.
        height_log_sigma: ``(n,)`` its relative spread σH/H.
        hypotheses: the per-heading constants.
    """

    height_m: FloatArray
    height_sigma_m: FloatArray
    height_log_sigma: FloatArray
    hypotheses: HypothesisConstants


class ClassTable:
    """Class priors and their per-heading constants, one row per class name seen so far.

    Args:
        priors: class → dimension prior (None = the built-in table).
        yaw_rad: ``(K,)`` the heading hypotheses.
    """

    def __init__(self, priors: dict[str, DimensionPrior] | None, yaw_rad: FloatArray) -> None:
        self._priors = priors
        self._yaw = yaw_rad
        self._index: dict[object, int] = {}
        self._rows: list[tuple[float, ...]] = []
        self._build()

    def gather(self, classes: NDArray[np.object_]) -> TargetClasses:
        """The constants of the class names ``classes`` ``(n,)`` (new names are added)."""
        rows = self._row_indices(classes)
        scalars = self._scalars[rows]
        # rows gathered along the second axis: each plane of a frame is contiguous
        planes = self._planes[:, rows]
        return TargetClasses(
            scalars[:, 0], scalars[:, 3], scalars[:, 7], HypothesisConstants(*planes)
        )

    def _row_indices(self, classes: NDArray[np.object_]) -> NDArray[np.intp]:
        index = self._index
        try:
            return np.array([index[c] for c in classes], dtype=np.intp)
        except KeyError:
            for c in classes:
                if c not in index:
                    index[c] = len(self._rows)
                    self._rows.append(prior_row(resolve_prior(c, self._priors)))
            self._build()
            return np.array([index[c] for c in classes], dtype=np.intp)

    def _build(self) -> None:
        """Scalars ``(rows, 10)``: H, W, L, σH, σW, σL, corr_hw, σH/H, σW/W, σL/L; planes
        ``(13, rows, K)`` in the order of :class:`HypothesisConstants`."""
        a = np.asarray(self._rows, dtype=float).reshape(-1, 7)
        H, W, L, sH, sW, sL, corr = (a[:, k : k + 1] for k in range(7))
        psi = self._yaw[None, :]
        self._scalars = np.concatenate([a, sH / H, sW / W, sL / L], axis=1)
        e = cues.depth_half_extent(psi, W, L)
        var_e = 0.25 * ((np.abs(np.cos(psi)) * sL) ** 2 + (np.abs(np.sin(psi)) * sW) ** 2)
        planes = HypothesisConstants(
            half_extent_m=e,
            half_extent_var_m2=var_e,
            half_extent_sigma_m=np.sqrt(var_e),
            min_centre_depth_m=e + MIN_NEAR_M,
            height_m=H,
            log_sigma_height=sH / H,
            log_sigma_width=sW / W,
            log_sigma_length=sL / L,
            corr_height_width=corr,
            half_width_cos_m=0.5 * W * np.cos(psi),
            half_width_sin_m=0.5 * W * np.sin(psi),
            half_length_cos_m=0.5 * L * np.cos(psi),
            half_length_sin_m=0.5 * L * np.sin(psi),
        )
        self._planes = np.stack([np.broadcast_to(p, e.shape) for p in planes])
