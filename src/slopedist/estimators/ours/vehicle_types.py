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

import numpy as np
from numpy.typing import NDArray

from slopedist.estimators.ours.priors import DimensionPrior, prior_row

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


def type_log_var(prior: DimensionPrior, mixture: TypeMixture) -> float:
    """Variance of a vehicle's log size about ``prior`` that a generic class adds to it: the
    second moment of the mixture's types about the class prior, minus the prior's own spread
    (≥ 0), on the isotropic scale √(H·W) the size cues measure (the log of the geometric mean
    of height and width; each type's spread ``(σH/H)² + (σW/W)² + 2ρ(σH/H)(σW/W)``, over 4).

    With the published mixture (:data:`~slopedist.estimators.ours.priors.VEHICLE_TYPE_MIXTURE`)
    about the ``Car`` prior it is 0.019 (a log σ of 0.14): 9 % vans 29 % bigger, 3 % trucks and
    buses 80 % bigger."""

    def log_scale(p: DimensionPrior) -> tuple[float, float]:
        s_h, s_w = p.height_sigma_m / p.height_m, p.width_sigma_m / p.width_m
        var = 0.25 * (s_h * s_h + s_w * s_w + 2.0 * p.corr_hw * s_h * s_w)
        return 0.5 * float(np.log(p.height_m * p.width_m)), var

    own_mean, own_var = log_scale(prior)
    weight = np.array([w for _, _, w in mixture], dtype=float)
    moments = np.array([log_scale(p) for _, p, _ in mixture])
    second = np.sum(weight * ((moments[:, 0] - own_mean) ** 2 + moments[:, 1])) / weight.sum()
    return max(float(second) - own_var, 0.0)
