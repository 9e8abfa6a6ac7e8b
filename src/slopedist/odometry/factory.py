"""Rotation sources from pixels by name: ``make_odometry("builtin", camera, **options)``.

Backends register a factory in :data:`ODOMETRY_BACKENDS`; heavy or optional ones import their
dependencies inside the factory, so listing the names costs nothing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields
from typing import Any

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.odometry.base import RotationOdometry
from slopedist.odometry.point_map import PointMap

OdometryFactory = Callable[..., RotationOdometry]


def _builtin(camera: Camera, point_map: PointMap | None = None, **options: Any) -> RotationOdometry:
    """The built-in OpenCV visual odometry; options are fields of ``VisualOdometryConfig``, and
    ``point_map`` maps its tracked pixels into the ideal ``camera`` (lens distortion, fx ≠ fy;
    :mod:`~slopedist.odometry.point_map`)."""
    from slopedist.odometry.point_map import PointNormaliser
    from slopedist.odometry.visual import BuiltinVisualOdometry, VisualOdometryConfig

    known = {f.name for f in fields(VisualOdometryConfig)}
    unknown = sorted(set(options) - known)
    if unknown:
        raise ConfigurationError(
            f"unknown option(s) {', '.join(unknown)} of the builtin visual odometry; "
            f"known: {', '.join(sorted(known))}"
        )
    odometry = BuiltinVisualOdometry(camera, VisualOdometryConfig(**options))
    odometry.normalise = PointNormaliser(camera.K, point_map)
    return odometry


def _orbslam3(camera: Camera, **options: Any) -> RotationOdometry:
    """Monocular ORB-SLAM3 (optional extra ``orbslam3``); options are the keyword arguments of
    ``OrbSlam3Odometry`` (``vocabulary``, ``fps``, ``n_features``, ``realtime``)."""
    import inspect

    from slopedist.odometry.orbslam3 import OrbSlam3Odometry

    known = set(inspect.signature(OrbSlam3Odometry).parameters) - {"camera"}
    unknown = sorted(set(options) - known)
    if unknown:
        raise ConfigurationError(
            f"unknown option(s) {', '.join(unknown)} of the orbslam3 backend; "
            f"known: {', '.join(sorted(known))}"
        )
    return OrbSlam3Odometry(camera, **options)


ODOMETRY_BACKENDS: dict[str, OdometryFactory] = {"builtin": _builtin, "orbslam3": _orbslam3}
"""Name → factory ``(camera, **options) → RotationOdometry``."""


def available_odometry() -> list[str]:
    """Names accepted by :func:`make_odometry`."""
    return list(ODOMETRY_BACKENDS)


def make_odometry(name: str, camera: Camera, **options: Any) -> RotationOdometry:
    """Create the visual-odometry backend ``name`` for ``camera``.

    Raises:
        ConfigurationError: unknown backend name or option.
        OptionalDependencyError: the backend needs an optional package that is not installed.
    """
    factory = ODOMETRY_BACKENDS.get(name)
    if factory is None:
        raise ConfigurationError(
            f"unknown odometry backend '{name}'; choose from {', '.join(ODOMETRY_BACKENDS)}"
        )
    return factory(camera, **options)
