"""slopedist's own estimator (``--method ours``): the algorithm is :mod:`.estimator`'s
``OursEstimator.estimate``, step by step; docs/method.md's code map names every module."""

from slopedist.estimators.ours.estimator import (
    EXTRA_COLUMNS,
    OursAblation,
    OursConfig,
    OursEstimator,
    OursSelfCalibratingEstimator,
)
from slopedist.estimators.ours.priors import CLASS_PRIORS, DimensionPrior, YawPrior
from slopedist.estimators.ours.selfcal import Calibration, SelfCalConfig, SelfCalibrator

__all__ = [
    "CLASS_PRIORS",
    "EXTRA_COLUMNS",
    "Calibration",
    "DimensionPrior",
    "OursAblation",
    "OursConfig",
    "OursEstimator",
    "OursSelfCalibratingEstimator",
    "SelfCalConfig",
    "SelfCalibrator",
    "YawPrior",
]
