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
