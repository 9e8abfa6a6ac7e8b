"""Distance estimators behind one small interface, selectable by name."""

from __future__ import annotations

from collections.abc import Callable
from enum import Enum
from typing import Any

from slopedist.camera import Camera
from slopedist.errors import ConfigurationError
from slopedist.estimators.base import (
    Estimator,
    FrameEstimates,
    FrameInput,
    MissingReason,
    ReferencePoint,
)
from slopedist.estimators.depthmap import DepthMapEstimator
from slopedist.estimators.ground_contact import (
    EgoGradientEstimator,
    FlatGroundEstimator,
    PaperEstimator,
)
from slopedist.estimators.imu import ImuEgoEstimator, ImuEstimator
from slopedist.estimators.ours import OursEstimator, OursSelfCalibratingEstimator


class Method(str, Enum):
    """Estimator names accepted by the command line and :func:`make_estimator`."""

    FLAT = "flat"
    EGO = "ego"
    PAPER = "paper"
    IMU = "imu"
    IMU_EGO = "imu-ego"
    DEPTHMAP = "depthmap"
    OURS = "ours"
    OURS_SELFCAL = "ours-selfcal"


DEFAULT_METHOD = Method.OURS.value
"""The estimator of ``run`` and of the demo's overlays when none is chosen."""

ESTIMATORS: dict[str, Callable[..., Estimator]] = {
    Method.FLAT.value: FlatGroundEstimator,
    Method.EGO.value: EgoGradientEstimator,
    Method.PAPER.value: PaperEstimator,
    Method.IMU.value: ImuEstimator,
    Method.IMU_EGO.value: ImuEgoEstimator,
    Method.DEPTHMAP.value: DepthMapEstimator,
    Method.OURS.value: OursEstimator,
    Method.OURS_SELFCAL.value: OursSelfCalibratingEstimator,
}


def available_methods() -> list[str]:
    """Names of every registered estimator."""
    return list(ESTIMATORS)


def make_estimator(name: str, camera: Camera, **options: Any) -> Estimator:
    """Build the estimator registered as ``name`` for ``camera``."""
    try:
        factory = ESTIMATORS[str(getattr(name, "value", name))]
    except KeyError:
        raise ConfigurationError(
            f"unknown method '{name}'; choose from {', '.join(available_methods())}"
        ) from None
    return factory(camera, **options)


__all__ = [
    "DEFAULT_METHOD",
    "ESTIMATORS",
    "DepthMapEstimator",
    "EgoGradientEstimator",
    "Estimator",
    "FlatGroundEstimator",
    "FrameEstimates",
    "FrameInput",
    "ImuEgoEstimator",
    "ImuEstimator",
    "Method",
    "MissingReason",
    "OursEstimator",
    "OursSelfCalibratingEstimator",
    "PaperEstimator",
    "ReferencePoint",
    "available_methods",
    "make_estimator",
]
