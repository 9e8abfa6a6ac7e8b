"""slopedist's own estimator (``--method ours``).

Pure math (:mod:`.cues`: size and ground-contact cues, their uncertainties, fusion, the continuous
target gradient; :mod:`.filter`: the Kalman filter equations) is kept apart from state
(:mod:`.tracking`: track bookkeeping; :mod:`.selfcal`: online calibration) and from the
estimator that ties them together (:mod:`.estimator`).
"""

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
