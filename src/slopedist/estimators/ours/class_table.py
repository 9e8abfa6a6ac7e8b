"""Class priors of ``ours`` as per-heading constants, computed once per class name.

The priors and the heading grid are fixed for an estimator, so each class name's constants are
computed once and a frame gathers its targets' rows. Lengths in metres,
headings ψ in radians (the angle of a vehicle's length axis from the camera's z axis).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slopedist.estimators.ours import cues
from slopedist.estimators.ours.priors import (
    VEHICLE_TYPE_MIXTURE,
    DimensionPrior,
    prior_row,
    resolve_prior,
)
from slopedist.estimators.ours.vehicle_types import (
    NOT_THIS_TYPE_LOG_WEIGHT,
    TypeMixture,
    type_moments,
    type_rows,
)
from slopedist.io.detections.boxes import class_key

FloatArray = NDArray[np.float64]

MIN_NEAR_M = 0.5
"""Smallest distance to a target's nearest face the cues accept, metres."""


class HypothesisConstants(NamedTuple):
    """Class constants per (target, heading hypothesis), each ``(n, K)``, or ``(n, M·K)``
    when repeated over ``M`` size modes (mode-major; the same constants in every mode).

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
        generic: ``(n,)`` whether the class is generic (its vehicle type unknown).
        type_log_weight: ``(n, T)`` log prior weight of each vehicle type when a target's
            class is generic (then :attr:`hypotheses` are ``(n, T·K)``, type-major:
            :mod:`~slopedist.estimators.ours.vehicle_types`), else None.
        type_moments: ``(n, T, 3)`` the vehicle types of a class read as generic for σ only
            (:func:`~slopedist.estimators.ours.vehicle_types.type_moments`; a class as given:
            one type, itself), or None when no target's class is.
        sized: ``(n,)`` the targets whose size the detector gives (a known dimension), or None
            when no target's is.
    """

    height_m: FloatArray
    height_sigma_m: FloatArray
    height_log_sigma: FloatArray
    hypotheses: HypothesisConstants
    generic: NDArray[np.bool_]
    type_log_weight: FloatArray | None
    type_moments: FloatArray | None = None
    sized: NDArray[np.bool_] | None = None


DetectorSizes = tuple[FloatArray, FloatArray]
"""A detector's vehicle sizes: ``(n, 3)`` height, width, length and ``(n, 3)`` their 1σ, metres
(NaN = unknown; :func:`slopedist.io.detections.sizes.size_arrays`)."""


def _sized(sizes: DetectorSizes | None, n: int) -> NDArray[np.bool_] | None:
    """``(n,)`` the targets with a known dimension, or None when there is none."""
    if sizes is None:
        return None
    sized = np.asarray(np.isfinite(sizes[0]).any(axis=1), dtype=bool)
    if sized.shape[0] != n:
        raise ValueError(f"{sized.shape[0]} detector sizes for {n} targets")
    return sized if sized.any() else None


class ClassTable:
    """Class priors and their per-heading constants, one row per class name seen so far.

    Args:
        priors: class → dimension prior (None = the built-in table).
        yaw_rad: ``(K,)`` the heading hypotheses.
        generic_classes: class names that do not name the vehicle type (a class-blind
            detector's one class): their targets are read under ``type_mixture``. Names are
            compared without regard to case or surrounding spaces, as the vehicle classes
            are (:func:`~slopedist.io.detections.boxes.vehicle_mask`).
        type_mixture: ``(name, prior, weight)`` per vehicle type.
        spread_classes: class names read as generic for the σ only: their hypotheses are
            their own class's, and :attr:`TargetClasses.type_moments` carries
            ``type_mixture``'s types against their prior.
        n_modes: the size modes (:class:`~slopedist.estimators.ours.fusion.SizeMode`) a
            specific class's hypotheses are repeated over: its planes are ``(n, n_modes·K)``,
            so that the cues of every mode are computed as arrays of one shape (a generic
            class's vehicle types take the modes' place).
    """

    def __init__(
        self,
        priors: dict[str, DimensionPrior] | None,
        yaw_rad: FloatArray,
        generic_classes: tuple[str, ...] = (),
        type_mixture: TypeMixture = VEHICLE_TYPE_MIXTURE,
        n_modes: int = 1,
        spread_classes: tuple[str, ...] = (),
    ) -> None:
        self._priors = priors
        self._spread_names = frozenset(class_key(c) for c in spread_classes)
        self._type_moments: list[FloatArray] = []
        self._n_modes = n_modes
        self._yaw = yaw_rad
        self._generic_names = frozenset(class_key(c) for c in generic_classes)
        self._mixture = type_mixture
        self._index: dict[object, int] = {}
        self._rows: list[tuple[float, ...]] = []
        self._type_rows: list[tuple[float, ...]] = []  # T per class row
        self._type_weights: list[FloatArray] = []
        self._generic_rows: list[bool] = []
        self._build()

    def gather(
        self, classes: NDArray[np.object_], sizes: DetectorSizes | None = None
    ) -> TargetClasses:
        """The constants of the class names ``classes`` ``(n,)`` (new names are added).

        ``sizes``: the vehicle sizes a detector gives, ``(n, 3)`` height, width, length and
        ``(n, 3)`` their 1σ (m; NaN = unknown). A target with a known dimension takes it, and
        its σ, in place of its class prior's (the class prior's for the others; the class's
        height-width correlation); its vehicle type is then known: it is never read as a
        mixture of types (:attr:`TargetClasses.generic` false) nor widened by one for σ.
        """
        rows = self._row_indices(classes.tolist())
        scalars = self._scalars[rows]
        generic = self._generic[rows]
        sized = _sized(sizes, rows.shape[0])
        if sized is not None:
            generic = generic & ~sized
        # rows gathered along the second axis: each plane of a frame is contiguous
        if self._generic_names and generic.any():
            planes, type_log_weight = self._type_planes[:, rows], self._type_log_weight[rows]
        else:
            planes, type_log_weight = self._planes[:, rows], None
        moments = self._spread[rows] if self._spread_names else None
        spread = self._is_spread[rows] if self._spread_names else None
        if sizes is not None and sized is not None:
            scalars, planes, type_log_weight, moments = self._with_sizes(
                sizes, sized, scalars, planes, type_log_weight, moments
            )
            spread = None if spread is None else spread & ~sized
        if moments is not None and spread is not None and not spread.any():
            moments = None
        return TargetClasses(
            scalars[:, 0],
            scalars[:, 3],
            scalars[:, 7],
            HypothesisConstants(*planes),
            generic,
            type_log_weight,
            moments,
            sized,
        )

    def _with_sizes(
        self,
        sizes: DetectorSizes,
        sized: NDArray[np.bool_],
        scalars: FloatArray,
        planes: FloatArray,
        type_log_weight: FloatArray | None,
        moments: FloatArray | None,
    ) -> tuple[FloatArray, FloatArray, FloatArray | None, FloatArray | None]:
        """The gathered constants with the ``sized`` targets' own: their known dimensions and
        σ in their prior rows, their planes in the frame's layout (repeated over the size
        modes, or over the types with the other types of no weight), one type for σ."""
        dims, sigma = sizes
        idx = np.flatnonzero(sized)
        a = scalars[idx, :7].copy()
        known = np.isfinite(dims[idx])
        a[:, 0:3] = np.where(known, dims[idx], a[:, 0:3])
        a[:, 3:6] = np.where(known, sigma[idx], a[:, 3:6])
        scalars = scalars.copy()
        scalars[idx] = np.concatenate([a, a[:, 3:6] / a[:, 0:3]], axis=1)
        own = self._planes_of(a)
        planes = planes.copy()
        if type_log_weight is not None:
            n_types = type_log_weight.shape[1]
            planes[:, idx] = np.tile(own, n_types)
            type_log_weight = type_log_weight.copy()
            type_log_weight[idx] = NOT_THIS_TYPE_LOG_WEIGHT
            type_log_weight[idx, 0] = 0.0
        else:
            planes[:, idx] = np.tile(own, self._n_modes)
        if moments is not None:
            moments = moments.copy()
            moments[idx] = 0.0
            moments[idx, 1:, 2] = NOT_THIS_TYPE_LOG_WEIGHT
        return scalars, planes, type_log_weight, moments

    def _row_indices(self, classes: list[object]) -> NDArray[np.intp]:
        """The table rows of the class names ``classes`` (rows are added for new names)."""
        index = self._index
        new = [c for c in dict.fromkeys(classes) if c not in index]
        for c in new:
            index[c] = len(self._rows)
            self._add_row(c)
        if new:
            self._build()
        return np.array([index[c] for c in classes], dtype=np.intp)

    def _add_row(self, name: object) -> None:
        """A new class name's prior and its vehicle types."""
        prior = resolve_prior(name, self._priors)
        self._rows.append(prior_row(prior))
        generic = class_key(name) in self._generic_names
        rows, log_weight = type_rows(prior, self._mixture, generic)
        self._generic_rows.append(generic)
        if class_key(name) in self._spread_names:
            self._type_moments.append(type_moments(prior, self._mixture))
        else:  # one type (itself), the others of no weight
            own = np.zeros((len(self._mixture), 3))
            own[1:, 2] = NOT_THIS_TYPE_LOG_WEIGHT
            self._type_moments.append(own)
        self._type_rows.extend(rows)
        self._type_weights.append(log_weight)

    def _build(self) -> None:
        """Scalars ``(rows, 10)``: H, W, L, σH, σW, σL, corr_hw, σH/H, σW/W, σL/L; planes
        ``(13, rows, n_modes·K)`` in the order of :class:`HypothesisConstants`; with generic
        classes also the type planes ``(13, rows, T·K)``, type-major."""
        a = np.asarray(self._rows, dtype=float).reshape(-1, 7)
        self._scalars = np.concatenate([a, a[:, 3:6] / a[:, 0:3]], axis=1)
        self._planes = self._planes_of(a)
        if self._n_modes > 1:
            self._planes = np.tile(self._planes, self._n_modes)
        self._generic = np.array(self._generic_rows, dtype=bool)
        if self._spread_names:
            self._spread = np.asarray(self._type_moments, dtype=float)
            self._is_spread = np.array(
                [class_key(n) in self._spread_names for n in self._index], bool
            )
        if self._generic_names:
            n_types = len(self._mixture)
            by_type = np.asarray(self._type_rows, dtype=float).reshape(-1, n_types, 7)
            planes = [self._planes_of(by_type[:, t]) for t in range(n_types)]
            self._type_planes = np.concatenate(planes, axis=2)
            self._type_log_weight = np.asarray(self._type_weights, dtype=float).reshape(-1, n_types)

    def _planes_of(self, a: FloatArray) -> FloatArray:
        """The per-heading planes ``(13, rows, K)`` of prior rows ``a`` ``(rows, 7)``."""
        H, W, L, sH, sW, sL, corr = (a[:, k : k + 1] for k in range(7))
        psi = self._yaw[None, :]
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
        return np.stack([np.broadcast_to(p, e.shape) for p in planes])
