"""The road model of the synthetic hills: elevation and heading as smooth functions of distance.

Convention:
    World frame ``W``: X forward along the road at ``s = 0``, Y to the left, Z up (metres); the
    road's centreline passes through the origin at ``s = 0`` heading along +X at elevation 0.
    ``s`` is the horizontal (plan) distance along the centreline, metres; ``w`` the lateral
    offset from the centreline, metres, positive to the left. The road cross-section is level
    (no banking), so the surface point of ``(s, w)`` is ``C(s) + w·L(s)`` with ``C`` the
    centreline and ``L`` the horizontal unit vector to its left.

Profile: the grade ``g(s) = dz/ds`` (a tangent, 0.05 = 5 %) starts at ``start_grade`` and each
:class:`GradeChange` moves it linearly to a new grade over a vertical curve of the given length
centred on ``at_m`` (so the elevation is a parabola there: a crest when the grade falls, a sag
when it rises). :class:`SpeedBump` adds a raised-cosine hump to the elevation. Plan: the
curvature ``κ(s)`` (1/m, positive turning left) is zero except on :class:`HorizontalCurve`
arcs, entered and left through linear-curvature transitions (clothoids). The heading is
``ψ(s) = ∫κ``, the plan position ``∫(cos ψ, sin ψ)``.

Every quantity is tabulated once on a fine grid (:data:`ROAD_STEP_M`) and linearly interpolated;
the renderer and the ground truth both read these tables, so they agree exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.core.errors import ConfigurationError

FloatArray = NDArray[np.float64]

ROAD_STEP_M = 0.05
"""Spacing of the road's tables along ``s``, metres."""


@dataclass(frozen=True)
class GradeChange:
    """A change of grade through a vertical curve.

    Attributes:
        at_m: centre of the vertical curve along the road (plan distance ``s``), metres.
        grade_pct: grade after the curve, percent (positive uphill in the driving direction).
        length_m: length of the vertical curve over which the grade changes linearly, metres.
    """

    at_m: float
    grade_pct: float
    length_m: float = 40.0

    def __post_init__(self) -> None:
        _finite(self, ("at_m", "grade_pct", "length_m"))
        if self.length_m <= 0:
            raise ConfigurationError(f"grade change length_m must be > 0 m, got {self.length_m}")
        if abs(self.grade_pct) > 40:
            raise ConfigurationError(f"grade_pct must be within ±40 %, got {self.grade_pct}")


@dataclass(frozen=True)
class HorizontalCurve:
    """A circular arc entered and left through clothoid transitions.

    Attributes:
        start_m: start of the entry transition along the road, metres.
        length_m: length of the constant-radius arc, metres.
        radius_m: signed radius, metres; positive turns left, negative right.
        transition_m: length of each clothoid transition (curvature linear), metres.
    """

    start_m: float
    length_m: float
    radius_m: float
    transition_m: float = 20.0

    def __post_init__(self) -> None:
        _finite(self, ("start_m", "length_m", "radius_m", "transition_m"))
        if self.length_m < 0 or self.transition_m < 0:
            raise ConfigurationError("curve length_m and transition_m must be ≥ 0 m")
        if abs(self.radius_m) < 30:
            raise ConfigurationError(
                f"curve radius_m must be at least 30 m in magnitude, got {self.radius_m}"
            )

    def curvature(self, s: FloatArray) -> FloatArray:
        """Curvature of this curve at plan distances ``s`` (1/m)."""
        k = 1.0 / self.radius_m
        t = self.transition_m
        a, b = self.start_m, self.start_m + t
        c, d = b + self.length_m, b + self.length_m + t
        up = np.clip((s - a) / t, 0.0, 1.0) if t > 0 else (s >= a).astype(float)
        down = np.clip((d - s) / t, 0.0, 1.0) if t > 0 else (s <= c).astype(float)
        return k * np.minimum(up, down) * ((s >= a) & (s <= d))


@dataclass(frozen=True)
class SpeedBump:
    """A raised-cosine speed bump across the whole road.

    Attributes:
        at_m: centre along the road, metres.
        height_m: height at the centre, metres.
        length_m: length along the road (base to base), metres.
    """

    at_m: float
    height_m: float = 0.08
    length_m: float = 3.7

    def __post_init__(self) -> None:
        _finite(self, ("at_m", "height_m", "length_m"))
        if not 0 < self.height_m <= 0.3:
            raise ConfigurationError(f"bump height_m must be in (0, 0.3] m, got {self.height_m}")
        if self.length_m <= 0.2:
            raise ConfigurationError(f"bump length_m must be > 0.2 m, got {self.length_m}")

    def elevation(self, s: FloatArray) -> FloatArray:
        """Height added to the road at plan distances ``s``, metres."""
        x = (s - self.at_m) / self.length_m
        inside = np.abs(x) < 0.5
        return np.where(inside, 0.5 * self.height_m * (1.0 + np.cos(2.0 * np.pi * x)), 0.0)


@dataclass(frozen=True)
class RoadSpec:
    """Everything that defines a road.

    Attributes:
        start_grade_pct: grade at ``s = 0`` (and before the first change), percent.
        grade_changes: vertical curves, by ``at_m``.
        curves: horizontal curves.
        bumps: speed bumps.
        lane_width_m: width of one lane, metres.
        lanes: number of lanes (the centreline is the middle of the carriageway).
        verge_m: width of the verge between the carriageway's edge and the roadside structures.
        s_min_m, s_max_m: extent of the modelled road along ``s``, metres.
    """

    start_grade_pct: float = 0.0
    grade_changes: tuple[GradeChange, ...] = ()
    curves: tuple[HorizontalCurve, ...] = ()
    bumps: tuple[SpeedBump, ...] = ()
    lane_width_m: float = 3.5
    lanes: int = 2
    verge_m: float = 6.0
    s_min_m: float = -60.0
    s_max_m: float = 900.0

    def __post_init__(self) -> None:
        _finite(self, ("start_grade_pct", "lane_width_m", "verge_m", "s_min_m", "s_max_m"))
        if not 2.0 <= self.lane_width_m <= 6.0:
            raise ConfigurationError(f"lane_width_m must be in [2, 6] m, got {self.lane_width_m}")
        if not 1 <= self.lanes <= 6:
            raise ConfigurationError(f"lanes must be 1..6, got {self.lanes}")
        if not 1.0 <= self.verge_m <= 30.0:
            raise ConfigurationError(f"verge_m must be in [1, 30] m, got {self.verge_m}")
        if self.s_max_m - self.s_min_m < 50:
            raise ConfigurationError("the road must be at least 50 m long")

    @property
    def half_width_m(self) -> float:
        """Half the carriageway width, metres."""
        return 0.5 * self.lanes * self.lane_width_m

    @property
    def corridor_half_width_m(self) -> float:
        """Lateral offset of the roadside structures (carriageway half-width + verge), metres."""
        return self.half_width_m + self.verge_m


def _finite(obj: object, names: tuple[str, ...]) -> None:
    for name in names:
        value = getattr(obj, name)
        if not math.isfinite(value):
            raise ConfigurationError(f"{type(obj).__name__}.{name} must be finite, got {value}")


class Road:
    """Tabulated road geometry of a :class:`RoadSpec` (see the module docstring for frames).

    Attributes:
        spec: the road's definition.
        s: ``(N,)`` plan distances of the tables, metres.
        grade: ``(N,)`` dz/ds including bumps.
        z: ``(N,)`` elevation of the centreline, metres.
        heading: ``(N,)`` heading ψ, radians (0 = +X, positive to the left).
        xy: ``(N, 2)`` plan position of the centreline, metres.
        length3d: ``(N,)`` distance driven along the 3D centreline from ``s = 0``, metres.
    """

    def __init__(self, spec: RoadSpec, step_m: float = ROAD_STEP_M) -> None:
        self.spec = spec
        n = math.ceil((spec.s_max_m - spec.s_min_m) / step_m) + 1
        s = spec.s_min_m + step_m * np.arange(n)
        i0 = int(np.argmin(np.abs(s)))
        s = s - s[i0]  # s = 0 falls on a table row exactly
        self.s = s
        grade = np.full(n, spec.start_grade_pct / 100.0)
        prev = spec.start_grade_pct
        for change in sorted(spec.grade_changes, key=lambda c: c.at_m):
            ramp = np.clip((s - (change.at_m - 0.5 * change.length_m)) / change.length_m, 0, 1)
            grade += (change.grade_pct - prev) / 100.0 * ramp
            prev = change.grade_pct
        z = _cumtrapz(grade, step_m, i0)
        bump = np.zeros(n)
        for b in spec.bumps:
            bump += b.elevation(s)
        self.z = z + bump
        self.grade = np.gradient(self.z, step_m)
        kappa = np.zeros(n)
        for c in spec.curves:
            kappa += c.curvature(s)
        self.heading = _cumtrapz(kappa, step_m, i0)
        self.xy = np.stack(
            [
                _cumtrapz(np.cos(self.heading), step_m, i0),
                _cumtrapz(np.sin(self.heading), step_m, i0),
            ],
            axis=1,
        )
        self.length3d = _cumtrapz(np.sqrt(1.0 + self.grade**2), step_m, i0)
        self.step_m = step_m

    # --- queries (vectorised over s) -----------------------------------------------------------

    def elevation(self, s: ArrayLike) -> FloatArray:
        """Centreline elevation at plan distances ``s``, metres."""
        return np.interp(np.asarray(s, dtype=float), self.s, self.z)

    def grade_at(self, s: ArrayLike) -> FloatArray:
        """Grade dz/ds (a tangent; 0.05 = 5 %) at ``s``."""
        return np.interp(np.asarray(s, dtype=float), self.s, self.grade)

    def heading_at(self, s: ArrayLike) -> FloatArray:
        """Heading ψ at ``s``, radians."""
        return np.interp(np.asarray(s, dtype=float), self.s, self.heading)

    def centre(self, s: ArrayLike) -> FloatArray:
        """Centreline point ``(..., 3)`` in the world frame at ``s``, metres."""
        s = np.asarray(s, dtype=float)
        return np.stack(
            [
                np.interp(s, self.s, self.xy[:, 0]),
                np.interp(s, self.s, self.xy[:, 1]),
                np.interp(s, self.s, self.z),
            ],
            axis=-1,
        )

    def left(self, s: ArrayLike) -> FloatArray:
        """Horizontal unit vector ``(..., 3)`` to the left of the centreline at ``s``."""
        psi = self.heading_at(s)
        return np.stack([-np.sin(psi), np.cos(psi), np.zeros_like(psi)], axis=-1)

    def tangent(self, s: ArrayLike) -> FloatArray:
        """Unit 3D tangent ``(..., 3)`` of the centreline (driving direction, with grade)."""
        psi = self.heading_at(s)
        g = self.grade_at(s)
        t = np.stack([np.cos(psi), np.sin(psi), g], axis=-1)
        return t / np.linalg.norm(t, axis=-1, keepdims=True)

    def point(self, s: ArrayLike, w: ArrayLike) -> FloatArray:
        """Road-surface point ``(..., 3)`` at plan distance ``s`` and lateral offset ``w``."""
        s = np.asarray(s, dtype=float)
        w = np.asarray(w, dtype=float)
        return self.centre(s) + w[..., None] * self.left(s)

    def driven_distance(self, s: ArrayLike) -> FloatArray:
        """Distance along the 3D centreline from ``s = 0`` to ``s``, metres."""
        return np.interp(np.asarray(s, dtype=float), self.s, self.length3d)

    def s_at_driven_distance(self, dist_m: ArrayLike) -> FloatArray:
        """Inverse of :meth:`driven_distance`: plan distance ``s`` reached after ``dist_m``."""
        d = np.asarray(dist_m, dtype=float)
        if np.any(d < self.length3d[0]) or np.any(d > self.length3d[-1]):
            raise ConfigurationError(
                f"a vehicle leaves the modelled road (s from {self.s[0]:.0f} to "
                f"{self.s[-1]:.0f} m); shorten the scenario or move its start"
            )
        return np.interp(d, self.length3d, self.s)


def _cumtrapz(y: FloatArray, step: float, i0: int) -> FloatArray:
    """Cumulative trapezoid integral of ``y`` on a uniform grid, zero at index ``i0``."""
    out = np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * step)])
    return out - out[i0]
