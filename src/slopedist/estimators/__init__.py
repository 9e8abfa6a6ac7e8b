"""Distance estimators behind one small interface, selectable by name.

This module is the registry: the one place outside a method's own package that names it. The
layers above build a method by name (:func:`make_estimator`, :class:`EstimatorConfig`) and
ask it what it can do through :class:`~slopedist.estimators.base.Estimator`; what they share
with ``ours`` (its option texts, the vehicle dimension priors and the box of a 3D vehicle) they
take from here, never from ``slopedist.estimators.ours``. Internal: the public names are those
of ``slopedist`` itself.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from enum import Enum
from typing import Any

from slopedist.core import geometry as geo
from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.core.suggest import unknown_choice
from slopedist.estimators.base import (
    Estimator,
    FrameEstimates,
    FrameInput,
    MissingReason,
    ReferencePoint,
)
from slopedist.estimators.depthmap import DepthMapEstimator, DepthSample, DepthScaling
from slopedist.estimators.ground_contact import (
    EgoGradientEstimator,
    FlatGroundEstimator,
    PaperEstimator,
)
from slopedist.estimators.imu import ImuEgoEstimator, ImuEstimator
from slopedist.estimators.ours import OursEstimator, OursSelfCalibratingEstimator
from slopedist.estimators.ours.config import OPTION_SEPARATOR as OURS_OPTION_SEPARATOR
from slopedist.estimators.ours.config import (
    OursConfig,
    configs_of,
    idle_sigma_only,
    unscored_generic_class,
)
from slopedist.estimators.ours.config import parse_option_list as parse_ours_option_list
from slopedist.estimators.ours.config import parse_options as parse_ours_options
from slopedist.estimators.ours.cues import project_box
from slopedist.estimators.ours.offline import OursOfflineEstimator
from slopedist.estimators.ours.priors import CLASS_PRIORS, DimensionPrior, prior_for


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
    OURS_OFFLINE = "ours-offline"


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
    Method.OURS_OFFLINE.value: OursOfflineEstimator,
}


OFFLINE_COUNTERPARTS = {Method.OURS.value: Method.OURS_OFFLINE.value}
"""The offline method (``--offline``: smoothed over the whole drive) of each causal method
that has one; reported under its own name, next to the causal one."""


def offline_method(name: str) -> str:
    """The offline counterpart of method ``name`` (itself if it is offline already).

    Raises:
        ConfigurationError: the method has no offline counterpart.
    """
    value = _method_name(name)
    if getattr(ESTIMATORS[value], "offline", False):
        return value
    if value not in OFFLINE_COUNTERPARTS:
        raise ConfigurationError(
            f"method '{value}' has no offline mode (methods with one: "
            f"{', '.join(OFFLINE_COUNTERPARTS)})"
        )
    return OFFLINE_COUNTERPARTS[value]


def with_offline(names: Iterable[str]) -> list[str]:
    """``names`` with the offline counterpart of each causal method that has one right after
    it (once): ``ours`` → ``ours, ours-offline``."""
    out: list[str] = []
    for name in names:
        for m in (name, OFFLINE_COUNTERPARTS.get(name)):
            if m is not None and m not in out:
                out.append(m)
    return out


def available_methods() -> list[str]:
    """Names of every registered estimator."""
    return list(ESTIMATORS)


def causal_methods() -> list[str]:
    """Names of every registered causal estimator (the default of the commands that run
    "every method"; offline ones are asked for by name or ``--offline``)."""
    return [m for m in ESTIMATORS if not getattr(ESTIMATORS[m], "offline", False)]


def takes_ours_options(name: str) -> bool:
    """Whether method ``name`` is ``ours`` or built on it (``ours-selfcal``, ``ours-offline``):
    the methods that take :attr:`EstimatorConfig.ours_options` and
    :attr:`EstimatorConfig.reference`.

    Raises:
        ConfigurationError: an unknown method.
    """
    factory = ESTIMATORS[_method_name(name)]
    return isinstance(factory, type) and issubclass(factory, OursEstimator)


def native_reference(name: str) -> ReferencePoint | None:
    """The point of the vehicle method ``name`` reports when not asked for another: ``ours``
    and the methods built on it their centre (option ``reference``'s default, KITTI's label
    z), ``depthmap`` the surface at the box centre pixel, the ground-contact methods the
    contact row; None for a name that is no method (e.g. a record written by another tool).
    An evaluation without a declared truth point scores each method there (the published
    protocol)."""
    factory = ESTIMATORS.get(str(getattr(name, "value", name)))
    if factory is None:
        return None
    if takes_ours_options(name):
        return ReferencePoint(OursConfig.reference)
    if isinstance(factory, type) and issubclass(factory, DepthMapEstimator):
        return ReferencePoint.BOX_CENTRE_PIXEL
    return ReferencePoint.CONTACT


def make_estimator(name: str, camera: Camera, **options: Any) -> Estimator:
    """Build the estimator registered as ``name`` for ``camera``.

    Raises:
        ConfigurationError: an unknown method, or an option the method does not take (the
            message lists the ones it takes).
    """
    factory = ESTIMATORS[_method_name(name)]
    known = _option_names(factory)
    unknown = sorted(set(options) - known) if known is not None else []
    if unknown:
        raise ConfigurationError(
            f"unknown option(s) for method '{name}': {', '.join(unknown)} "
            f"(known: {', '.join(sorted(known or ())) or 'none'})"
        )
    return factory(camera, **options)


def _option_names(factory: Callable[..., Estimator]) -> set[str] | None:
    """The keyword options ``factory`` takes after the camera (None: any, it checks them)."""
    params = list(inspect.signature(factory).parameters.values())[1:]  # after the camera
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        return None
    return {p.name for p in params}


@dataclass(frozen=True)
class EstimatorConfig:
    """Everything that configures an estimator, whichever command or evaluation asks for it.

    Each option applies to the methods that have it and is ignored by the others: the eq. 7
    steps go to the paper's method and everything built on it (``paper``, ``imu``), the depth
    options to ``depthmap``.

    Attributes:
        method: a :class:`Method` name.
        alphas_deg: eq. 7 angle steps α1, α2, α3, degrees.
        thresholds_px: eq. 7 Δy thresholds t1 > t2 > t3 of α1, α2, α3, pixels.
        depth_sample: which pixels of a box give its depth (``depthmap``).
        depth_window_px: window side for ``depth_sample = window``, pixels (odd).
        depth_scaling: per-frame median scaling of scale-less depth (``depthmap``).
        reference: the point of the vehicle ``ours`` reports (``centre``, ``nearest_face``,
            ``contact``; None: its default, the centre).
        ours_options: ``(name, value)`` settings of ``ours`` and the methods built on it
            (:class:`~slopedist.estimators.ours.config.OursConfig` options, or experimental
            :class:`~slopedist.estimators.ours.config.OursAblation` ones; e.g. from
            ``--ours-option``, :func:`~slopedist.estimators.ours.config.parse_option`).
        generic_classes: class names ``ours`` reads as generic, a mixture of vehicle types
            (its option ``generic_classes``; ``--generic-class``): those a class-blind
            detector gives every vehicle, e.g. ``("car",)``; compared without regard to case.

    Raises:
        ConfigurationError: an unknown method, eq. 7 steps that are not three finite numbers
            or thresholds that do not decrease, an unknown depth sample or scaling, ours
            options or a reference that ``ours`` refuses
            (:func:`~slopedist.estimators.ours.config.configs_of`).
    """

    method: str = DEFAULT_METHOD
    alphas_deg: tuple[float, float, float] = (3.0, 5.0, 6.0)
    thresholds_px: tuple[float, float, float] = (0.0, -10.0, -20.0)
    depth_sample: DepthSample = DepthSample.CENTRE
    depth_window_px: int = 5
    depth_scaling: DepthScaling = DepthScaling.NONE
    reference: str | None = None
    ours_options: tuple[tuple[str, Any], ...] = ()
    generic_classes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "method", _method_name(self.method))
        geo.GradientAdjustment.from_degrees(self.alphas_deg, self.thresholds_px)  # the checks
        try:
            ours = dict(self.ours_options)
        except (TypeError, ValueError):
            raise ConfigurationError(
                f"ours_options must be (name, value) pairs, got {self.ours_options!r}"
            ) from None
        if self.reference is not None:
            ours["reference"] = self.reference
        if self.generic_classes:
            ours["generic_classes"] = self.generic_classes
        configs_of(ours)  # the known options, their ranges and the reference
        try:
            object.__setattr__(self, "depth_sample", DepthSample(self.depth_sample))
            object.__setattr__(self, "depth_scaling", DepthScaling(self.depth_scaling))
        except ValueError as exc:
            raise ConfigurationError(str(exc)) from None

    def with_method(self, method: str) -> EstimatorConfig:
        """The same options for another method."""
        return dataclasses.replace(self, method=method)

    def options(self, method: str | None = None) -> dict[str, Any]:
        """Constructor options of ``method`` (default: :attr:`method`) from this config."""
        factory = ESTIMATORS[_method_name(method or self.method)]
        if isinstance(factory, type) and issubclass(factory, PaperEstimator):
            return {
                "adjustment": geo.GradientAdjustment.from_degrees(
                    self.alphas_deg, self.thresholds_px
                )
            }
        if isinstance(factory, type) and issubclass(factory, DepthMapEstimator):
            return {
                "sample": self.depth_sample,
                "window_px": self.depth_window_px,
                "scaling": self.depth_scaling,
            }
        if takes_ours_options(method or self.method):
            ours = dict(self.ours_options)
            if self.generic_classes:
                ours["generic_classes"] = tuple(self.generic_classes)
            return ours if self.reference is None else ours | {"reference": self.reference}
        return {}

    def method_options(self, methods: Iterable[str]) -> dict[str, dict[str, Any]]:
        """:meth:`options` of every method (the ``method_options`` of an evaluation config)."""
        return {_method_name(m): self.options(m) for m in methods}


def _method_name(name: str | Method) -> str:
    value = str(getattr(name, "value", name))
    if value not in ESTIMATORS:
        raise ConfigurationError(unknown_choice("method", value, available_methods()))
    return value


def build_estimator(config: EstimatorConfig, camera: Camera) -> Estimator:
    """The estimator ``config`` describes, for ``camera``."""
    return make_estimator(config.method, camera, **config.options())


__all__ = [
    "CLASS_PRIORS",
    "DEFAULT_METHOD",
    "ESTIMATORS",
    "OURS_OPTION_SEPARATOR",
    "DepthMapEstimator",
    "DimensionPrior",
    "EgoGradientEstimator",
    "Estimator",
    "EstimatorConfig",
    "FlatGroundEstimator",
    "FrameEstimates",
    "FrameInput",
    "ImuEgoEstimator",
    "ImuEstimator",
    "Method",
    "MissingReason",
    "OursEstimator",
    "OursOfflineEstimator",
    "OursSelfCalibratingEstimator",
    "PaperEstimator",
    "ReferencePoint",
    "available_methods",
    "build_estimator",
    "causal_methods",
    "idle_sigma_only",
    "make_estimator",
    "native_reference",
    "offline_method",
    "parse_ours_option_list",
    "parse_ours_options",
    "prior_for",
    "project_box",
    "takes_ours_options",
    "unscored_generic_class",
    "with_offline",
]
