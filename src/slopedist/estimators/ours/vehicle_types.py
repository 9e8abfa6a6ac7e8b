"""Vehicle types behind a generic class: the size cues of ``ours`` under a mixture of types.

A class-blind detector calls every vehicle ``Car`` (PointRCNN's and RRC's boxes, COCO's
``car`` for vans and SUVs alike). Taking the car prior at its word makes a 2.5 m tall van look
1.6 times nearer than it is, with the car's tight spread. For a class named generic
(:attr:`~slopedist.estimators.ours.config.OursConfig.generic_classes`) the size cues are read
under each vehicle type of :data:`~slopedist.estimators.ours.priors.VEHICLE_TYPE_MIXTURE` in
turn (a type is one more hypothesis next to the headings, with the type's published frequency as
prior weight); the ground contact does not depend on the type (but for where the centre lies
behind the contact point), so where the two disagree the posterior moves to the type that
reconciles them, and the collapse over the hypotheses widens the size cue's spread instead of
biasing it.

A cue computed with the class prior's dimensions (height ``H``, width ``W``, length ``L``)
reads ``y = ℓ − c·η`` (:class:`~slopedist.estimators.ours.cues.SizeCue`: lever ``c``, ``η`` the
log size deviation); under type ``t`` it is therefore ``y + c·log(H_t/H)`` for the height cue,
``y + c·log(W_t/W) + (1 − c)·log(L_t/L)`` for the width cue, and the centre depth of the ground
contact moves by the difference of the half depth extents ``e_t − e``. Log distances ``ℓ =
log(Z / 1 m)``; headings ψ in radians.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slopedist.estimators.ours import cues
from slopedist.estimators.ours.cues import SizeCue
from slopedist.estimators.ours.fusion import LogCue
from slopedist.estimators.ours.priors import DimensionPrior

FloatArray = NDArray[np.float64]


class TypeModes(NamedTuple):
    """The types of a mixture relative to one class prior, ``T`` types and ``K`` headings.

    Attributes:
        log_weight: ``(T,)`` log prior probability of each type.
        log_height_ratio, log_width_ratio, log_length_ratio: ``(T,)`` ``log(dim_t / dim)``.
        log_sigma_height, log_sigma_width, log_sigma_length: ``(T,)`` the types' relative
            size spreads σ/dim.
        half_extent_m: ``(T, K)`` each type's half depth extent at each heading.
        extent_shift_m: ``(T, K)`` its difference to the class prior's.
    """

    log_weight: FloatArray
    log_height_ratio: FloatArray
    log_width_ratio: FloatArray
    log_length_ratio: FloatArray
    log_sigma_height: FloatArray
    log_sigma_width: FloatArray
    log_sigma_length: FloatArray
    half_extent_m: FloatArray
    extent_shift_m: FloatArray


def type_modes(
    base: DimensionPrior,
    mixture: tuple[tuple[str, DimensionPrior, float], ...],
    yaw_rad: FloatArray,
) -> TypeModes:
    """The :class:`TypeModes` of ``mixture`` (``(name, prior, weight)`` per type; the weights
    are normalised) relative to the class prior ``base``, at the headings ``yaw_rad`` ``(K,)``."""
    priors = [p for _, p, _ in mixture]
    weight = np.array([w for _, _, w in mixture], dtype=float)
    H, W, L = (
        np.array([getattr(p, k) for p in priors]) for k in ("height_m", "width_m", "length_m")
    )
    sH, sW, sL = (
        np.array([getattr(p, k) for p in priors])
        for k in ("height_sigma_m", "width_sigma_m", "length_sigma_m")
    )
    psi = np.asarray(yaw_rad, dtype=float)[None, :]
    extent = cues.depth_half_extent(psi, W[:, None], L[:, None])
    return TypeModes(
        np.log(weight / weight.sum()),
        np.log(H / base.height_m),
        np.log(W / base.width_m),
        np.log(L / base.length_m),
        sH / H,
        sW / W,
        sL / L,
        extent,
        extent - cues.depth_half_extent(psi, base.width_m, base.length_m),
    )


class TypeCues(NamedTuple):
    """The cues of the targets under one vehicle type, each ``(n, K)``."""

    height: SizeCue
    width: SizeCue
    ground: LogCue | None
    log_sigma_height: FloatArray
    log_sigma_width: FloatArray
    half_extent_m: FloatArray


def cues_under_type(
    modes: TypeModes,
    t: int,
    height: SizeCue,
    width: SizeCue,
    ground: LogCue | None,
    log_sigma_length: FloatArray,
) -> TypeCues:
    """The class prior's cues (``log_sigma_length``: its relative length spread, ``(n, K)``)
    read under type ``t``; ``modes`` holds the targets' types, ``(n, T)`` and ``(n, T, K)``
    (see the module docstring)."""
    h = SizeCue(
        height.mean + height.lever * modes.log_height_ratio[:, t, None],
        height.lever,
        height.var_white,
        height.var_other,
    )
    length_lever = 1.0 - width.lever
    share = length_lever * length_lever  # the length's share of the width cue's variance
    sigma_l = modes.log_sigma_length[:, t, None]
    w = SizeCue(
        width.mean
        + width.lever * modes.log_width_ratio[:, t, None]
        + length_lever * modes.log_length_ratio[:, t, None],
        width.lever,
        width.var_white,
        width.var_other + share * (sigma_l * sigma_l - log_sigma_length * log_sigma_length),
    )
    g = ground
    shift = modes.extent_shift_m[:, t]
    if ground is not None and shift.any():
        centre = np.exp(ground.mean) + shift
        g = LogCue(np.log(np.maximum(centre, 1e-3)), ground.var, ground.var_white, ground.loglik)
    shape = height.mean.shape
    return TypeCues(
        h,
        w,
        g,
        np.broadcast_to(modes.log_sigma_height[:, t, None], shape),
        np.broadcast_to(modes.log_sigma_width[:, t, None], shape),
        modes.half_extent_m[:, t],
    )


NOT_THIS_TYPE_WEIGHT = 1e-300
"""Prior weight of the other types for a class that names its vehicle type (negligible, yet
a finite log: no NaN from ``−inf − (−inf)``)."""


def own_type_mixture(
    prior: DimensionPrior, n_types: int
) -> tuple[tuple[str, DimensionPrior, float], ...]:
    """The mixture of a class that names its type: ``n_types`` copies of its own prior, all
    but the first of negligible weight (so that generic and specific targets share a frame's
    hypothesis layout)."""
    return (("own", prior, 1.0),) + (("own", prior, NOT_THIS_TYPE_WEIGHT),) * (n_types - 1)
