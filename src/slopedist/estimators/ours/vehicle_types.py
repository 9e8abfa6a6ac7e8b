"""Vehicle types behind a generic class: the hypotheses of ``ours`` for a class-blind detector.

A class-blind detector calls every vehicle ``Car`` (PointRCNN's and RRC's boxes, COCO's
``car`` for vans and SUVs alike). Taking the car prior at its word makes a 2.5 m tall van look
1.6 times nearer than it is, with the car's tight spread. For a class named generic
(:attr:`~slopedist.estimators.ours.config.OursConfig.generic_classes`) every vehicle type of
:data:`~slopedist.estimators.ours.priors.VEHICLE_TYPE_MIXTURE` becomes a set of hypotheses next
to the headings (``T`` types × ``K`` headings, the type's dimensions in every cue, its published
frequency as prior weight). The ground contact hardly depends on the type, so where the size
cues and the ground contact disagree the posterior moves to the type that reconciles them; a
track carries its type belief from frame to frame (near, the ground contact tells the type; far,
the size cue then measures with the right dimensions); and the estimate is the most probable
type's, the others widening its spread (:func:`~slopedist.estimators.ours.fusion.
widen_to_mixture`) instead of pulling it by their prior weight.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from slopedist.estimators.ours.priors import DimensionPrior, prior_row

if TYPE_CHECKING:
    from slopedist.estimators.ours.records import FusedCues

FloatArray = NDArray[np.float64]

TypeMixture = tuple[tuple[str, DimensionPrior, float], ...]
"""``(name, dimension prior, relative weight)`` per vehicle type."""

NOT_THIS_TYPE_LOG_WEIGHT = -700.0
"""Log prior weight of the other types for a class that names its vehicle type (``exp(−700)``
is negligible, yet finite: no NaN from ``−inf − (−inf)``)."""


def type_rows(
    prior: DimensionPrior, mixture: TypeMixture, generic: bool
) -> tuple[list[tuple[float, ...]], FloatArray]:
    """The prior rows (:func:`~slopedist.estimators.ours.priors.prior_row`) of each type and
    their log prior weights ``(T,)``: the mixture's types for a ``generic`` class, else the
    class's own ``prior`` in every slot, all but the first of negligible weight (so that the
    targets of a frame share one hypothesis layout)."""
    n = len(mixture)
    if generic:
        weight = np.array([w for _, _, w in mixture], dtype=float)
        return [prior_row(p) for _, p, _ in mixture], np.log(weight / weight.sum())
    log_weight = np.full(n, NOT_THIS_TYPE_LOG_WEIGHT)
    log_weight[0] = 0.0
    return [prior_row(prior)] * n, log_weight


def type_moments(prior: DimensionPrior, mixture: TypeMixture) -> FloatArray:
    """``(T, 3)`` each vehicle type of ``mixture`` against the class ``prior``: its log size
    offset ``c`` (how much bigger, in log, than the prior), the variance its own spread adds
    to the prior's (≥ 0), and its log prior weight (normalised). Sizes on the isotropic scale
    √(H·W) the size cues measure (the log of the geometric mean of height and width; each
    spread ``((σH/H)² + (σW/W)² + 2ρ(σH/H)(σW/W))/4``)."""

    def log_scale(p: DimensionPrior) -> tuple[float, float]:
        s_h, s_w = p.height_sigma_m / p.height_m, p.width_sigma_m / p.width_m
        var = 0.25 * (s_h * s_h + s_w * s_w + 2.0 * p.corr_hw * s_h * s_w)
        return 0.5 * float(np.log(p.height_m * p.width_m)), var

    own_mean, own_var = log_scale(prior)
    weight = np.array([w for _, _, w in mixture], dtype=float)
    moments = np.array([log_scale(p) for _, p, _ in mixture])
    return np.stack(
        [
            moments[:, 0] - own_mean,
            np.maximum(moments[:, 1] - own_var, 0.0),
            np.log(weight / weight.sum()),
        ],
        axis=1,
    )


def type_log_var(moments: FloatArray, log_weight: FloatArray | None = None) -> FloatArray:
    """The variance of a vehicle's log size about its class prior that its unknown type adds:
    ``Σ π_t (c_t² + v_t)`` over the types of :func:`type_moments` ``(..., T, 3)``, with the
    weights ``π`` of ``log_weight`` ``(..., T)`` (normalised here; default the prior weights).

    With the published mixture (:data:`~slopedist.estimators.ours.priors.VEHICLE_TYPE_MIXTURE`)
    about the ``Car`` prior and its prior weights it is 0.019 (a log σ of 0.14): 9 % vans 29 %
    bigger, 3 % trucks and buses 80 % bigger."""
    lw = moments[..., 2] if log_weight is None else log_weight
    w = np.exp(lw - np.max(lw, axis=-1, keepdims=True))
    w /= np.sum(w, axis=-1, keepdims=True)
    c = moments[..., 0]
    return np.asarray(np.sum(w * (c * c + moments[..., 1]), axis=-1), dtype=float)


def sigma_log_var(moments: FloatArray | None, fused: FusedCues) -> FloatArray | None:
    """``(n,)`` the variance of the fused log distance that a class read as generic for σ only
    adds, from the targets' :func:`type_moments` ``(n, T, 3)`` (None when no target's class
    is read so).

    A vehicle ``c`` bigger in log than its class prior moves the size cues by ``−c`` and the
    fusion by ``−w·c``, ``w = var_ground/(var_size + var_ground)`` the size cues' share (1
    without a ground contact), every frame of its track alike, so the filter cannot average
    it. Its type is weighed by the cue gap ``ℓ_ground − ℓ_size`` (about ``c`` for a type ``c``
    bigger, with variance ``var_size + var_ground`` plus the type's own extra spread) and
    the type's published frequency: near, where the ground contact is tight, a car is told
    from a van; far, the weights stay the prior's. The variance is ``w²·Σ π_t (c_t² + v_t)``
    (:func:`type_log_var`)."""
    if moments is None:
        return None
    ground = fused.ground
    log_weight = moments[..., 2]
    share = np.ones(moments.shape[0])
    if ground is not None:
        total = fused.size.var + ground.var
        with np.errstate(invalid="ignore", divide="ignore"):
            w = ground.var / total
        known = np.isfinite(w)
        share = np.where(known, w, share)
        gap = np.where(known, ground.mean - fused.size.mean, 0.0)[:, None]
        var = np.where(known, total, 1.0)[:, None] + moments[..., 1]
        log_weight = log_weight - 0.5 * ((gap - moments[..., 0]) ** 2 / var + np.log(var))
        log_weight = np.where(known[:, None], log_weight, moments[..., 2])
    return share * share * type_log_var(moments, log_weight)
