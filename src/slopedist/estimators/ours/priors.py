"""Per-class priors on vehicle (and road user) dimensions, and on the target's heading.

The dimension means are the class averages of the KITTI *object* detection training set as they
are published and reused as dimension anchors by monocular 3D detectors (e.g. Mousavian et al.,
"3D bounding box estimation using deep learning and geometry", CVPR 2017; SMOKE, M3D-RPN),
rounded to centimetres. The spreads are physical: the range of ordinary vehicles of the class
(passenger cars from low coupés to small SUVs, 1.35–1.80 m tall, 1.45–1.85 m wide without
mirrors, 3.4–4.9 m long) read as ±2σ. Nothing here was fitted on the KITTI *tracking* sequences
that ``slopedist eval kitti-tracking`` scores; ``benchmarks/ours_kitti.py`` checks that the
estimator does not depend on that choice by re-running it with priors fitted leave-one-sequence-out.

The heading prior (:class:`YawPrior`) is different: its defaults are fitted
(:mod:`~slopedist.estimators.ours.prior_fitting`) to the headings of the shared sequences' labels,
and
``benchmarks/ours_kitti.py`` reports the figures with each sequence scored under the fit to the
other twelve (leave one sequence out).

Convention: metres; standard deviations are of the dimension itself (not of its logarithm).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special

from slopedist.core.errors import ConfigurationError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class DimensionPrior:
    """Gaussian prior on a class's 3D box: height, width, length (m) and their spreads (m).

    ``corr_hw`` is the correlation of height and width (bigger vehicles are bigger in every
    direction); it matters when both the box height and the box width are used as cues.
    """

    height_m: float
    width_m: float
    length_m: float
    height_sigma_m: float
    width_sigma_m: float
    length_sigma_m: float
    corr_hw: float = 0.3

    def __post_init__(self) -> None:
        values = (
            self.height_m,
            self.width_m,
            self.length_m,
            self.height_sigma_m,
            self.width_sigma_m,
            self.length_sigma_m,
        )
        if not all(math.isfinite(v) and v > 0 for v in values):
            raise ConfigurationError(f"dimension prior values must be finite and > 0: {self}")
        if not -1.0 < self.corr_hw < 1.0:
            raise ConfigurationError(f"corr_hw must be in (-1, 1), got {self.corr_hw}")


CLASS_PRIORS: dict[str, DimensionPrior] = {
    "Car": DimensionPrior(1.53, 1.63, 3.88, 0.13, 0.10, 0.43),
    "Van": DimensionPrior(2.18, 1.91, 5.08, 0.30, 0.17, 0.70),
    "Truck": DimensionPrior(3.07, 2.63, 11.17, 0.50, 0.25, 3.0),
    "Tram": DimensionPrior(3.56, 2.40, 18.61, 0.30, 0.20, 6.0),
    "Pedestrian": DimensionPrior(1.76, 0.66, 0.84, 0.11, 0.14, 0.23, 0.2),
    "Person_sitting": DimensionPrior(1.27, 0.54, 0.80, 0.10, 0.10, 0.20, 0.2),
    "Cyclist": DimensionPrior(1.74, 0.60, 1.76, 0.10, 0.12, 0.18, 0.2),
}
"""Dimension priors by KITTI class name (see the module docstring for their provenance)."""

BUS_PRIOR = DimensionPrior(3.05, 2.55, 12.0, 0.20, 0.05, 1.5)
"""A city or coach bus (not a KITTI class): 2.55 m is the EU's maximum vehicle width (Directive
96/53/EC); 12 m the standard rigid bus (midi 10 m, articulated 18 m read as ±2σ-ish); low-floor
city buses are 2.9–3.2 m tall, coaches 3.5–3.9 m."""

VEHICLE_TYPE_MIXTURE: tuple[tuple[str, DimensionPrior, float], ...] = (
    ("car", CLASS_PRIORS["Car"], 28742.0),
    ("van", CLASS_PRIORS["Van"], 2914.0),
    ("truck", CLASS_PRIORS["Truck"], 1094.0),
    ("bus", BUS_PRIOR, 86.0),
)
"""Vehicle types behind a generic class name (``(name, prior, weight)``; weights are relative):
what a class-blind detector's ``Car`` may be
(:mod:`~slopedist.estimators.ours.vehicle_types`).

Weights: the label counts of the KITTI object detection training set (Geiger, Lenz, Urtasun,
CVPR 2012; 7481 images: 28 742 Car, 2 914 Van, 1 094 Truck), a published street-scene
frequency that no scored KITTI *tracking* sequence enters; KITTI has no bus class, so the bus
weight is the bus-to-car ratio of the EU vehicle fleet (about 0.7 M buses to 250 M passenger
cars, ACEA "Vehicles on European roads", 2023: 0.3 %) times the car count. The dimension priors
are the classes' own (see the module docstring) and :data:`BUS_PRIOR`. Nothing here is fitted
to a distance error."""

UNKNOWN_CLASS_PRIOR = DimensionPrior(1.80, 1.75, 4.20, 0.45, 0.35, 1.60)
"""Prior for any other class name (``Misc``, detector-specific names): a broad vehicle."""

CLASS_ALIASES = {
    "car": "Car",
    "van": "Van",
    "truck": "Truck",
    "tram": "Tram",
    "pedestrian": "Pedestrian",
    "person": "Pedestrian",
    "cyclist": "Cyclist",
    "bicycle": "Cyclist",
    "person_sitting": "Person_sitting",
    "bus": "Truck",
}


def prior_for(class_name: str) -> DimensionPrior:
    """The :class:`DimensionPrior` of a class name (case-insensitive; unknown → broad prior)."""
    if class_name in CLASS_PRIORS:
        return CLASS_PRIORS[class_name]
    alias = CLASS_ALIASES.get(str(class_name).strip().lower())
    return CLASS_PRIORS[alias] if alias else UNKNOWN_CLASS_PRIOR


@dataclass(frozen=True)
class PriorArrays:
    """Dimension priors broadcast to N targets (metres), as produced by :func:`priors_for`."""

    height_m: NDArray[np.float64]
    width_m: NDArray[np.float64]
    length_m: NDArray[np.float64]
    height_sigma_m: NDArray[np.float64]
    width_sigma_m: NDArray[np.float64]
    length_sigma_m: NDArray[np.float64]
    corr_hw: NDArray[np.float64]


def priors_for(classes: ArrayLike, table: dict[str, DimensionPrior] | None = None) -> PriorArrays:
    """Per-target prior arrays for an array of class names.

    Args:
        classes: ``(N,)`` class names.
        table: class → prior (default :data:`CLASS_PRIORS`; unknown names get the broad prior).
    """
    names = np.asarray(classes, dtype=object).reshape(-1)
    cache: dict[object, DimensionPrior] = {}
    rows = []
    for n in names:
        p = cache.get(n)
        if p is None:
            p = cache[n] = resolve_prior(n, table)
        rows.append(prior_row(p))
    a = np.asarray(rows, dtype=float).reshape(-1, 7)
    return PriorArrays(*(a[:, k] for k in range(7)))


def resolve_prior(
    class_name: object, table: dict[str, DimensionPrior] | None = None
) -> DimensionPrior:
    """The prior of one class name: ``table``'s entry (default :data:`CLASS_PRIORS`), else the
    built-in prior of its alias, else the broad :data:`UNKNOWN_CLASS_PRIOR`."""
    lookup = table if table is not None else CLASS_PRIORS
    return lookup[class_name] if class_name in lookup else prior_for(str(class_name))


def prior_row(p: DimensionPrior) -> tuple[float, float, float, float, float, float, float]:
    """``(H, W, L, σH, σW, σL, corr_hw)`` of a prior, the column order of :class:`PriorArrays`."""
    return (
        p.height_m,
        p.width_m,
        p.length_m,
        p.height_sigma_m,
        p.width_sigma_m,
        p.length_sigma_m,
        p.corr_hw,
    )


@dataclass(frozen=True)
class YawPrior:
    """Prior on a target's heading ψ relative to the camera's optical axis (radians).

    Most traffic drives along the road and the ego camera looks along it, so ψ is a mixture,
    modulo π (same or opposite direction look alike in a box): with probability
    ``aligned_weight`` ψ ~ N(0, ``aligned_sigma_rad``) (in lane), with probability
    ``broad_weight`` ψ ~ N(0, ``broad_sigma_rad``) (changing lanes, parked askew, on a bend),
    else uniform (crossing, turning, parked across).

    The defaults are the maximum-likelihood fit
    (:func:`~slopedist.estimators.ours.prior_fitting.fit_yaw_prior`) to the headings of all Car and
    Van labels kept by the evaluation protocol in the 13 shared KITTI tracking sequences;
    ``benchmarks/ours_kitti.py`` scores each sequence with the fit to the other twelve instead
    and prints both. The fit uses the labels' headings only, never a distance error.
    """

    aligned_weight: float = 0.546
    aligned_sigma_rad: float = math.radians(1.59)
    broad_weight: float = 0.206
    broad_sigma_rad: float = math.radians(6.56)

    def __post_init__(self) -> None:
        for name in ("aligned_weight", "broad_weight"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise ConfigurationError(f"{name} must be in [0, 1], got {value}")
        if self.aligned_weight + self.broad_weight > 1.0 + 1e-9:
            raise ConfigurationError(
                f"aligned_weight + broad_weight must be <= 1, got "
                f"{self.aligned_weight} + {self.broad_weight}"
            )
        for name in ("aligned_sigma_rad", "broad_sigma_rad"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigurationError(f"{name} must be finite and > 0, got {value}")

    @property
    def uniform_weight(self) -> float:
        """Probability of a heading uniform over the half circle."""
        return max(0.0, 1.0 - self.aligned_weight - self.broad_weight)

    def density(self, yaw_rad: ArrayLike) -> FloatArray:
        """Probability density of ψ (per radian, over a half circle of length π)."""
        x = np.asarray(yaw_rad, dtype=float)
        return np.asarray(
            self.aligned_weight * wrapped_normal(x, self.aligned_sigma_rad)
            + self.broad_weight * wrapped_normal(x, self.broad_sigma_rad)
            + self.uniform_weight / np.pi
        )


YAW_GRID_DEG = (
    -90.0,
    -60.0,
    -35.0,
    -20.0,
    -12.0,
    -7.0,
    -3.5,
    0.0,
    3.5,
    7.0,
    12.0,
    20.0,
    35.0,
    60.0,
)
"""Heading hypotheses ψ (degrees) the size cue is evaluated at; −90° is the same as +90°."""


def yaw_grid() -> NDArray[np.float64]:
    """The heading hypotheses of :data:`YAW_GRID_DEG`, radians."""
    return np.radians(np.asarray(YAW_GRID_DEG))


def yaw_prior_weights(grid_rad: ArrayLike, prior: YawPrior = YawPrior()) -> NDArray[np.float64]:
    """Prior probability of each hypothesis of a (periodic, sorted) heading grid; sums to 1.

    Each grid point stands for the interval halfway to its neighbours (periodic over π), and
    gets the prior mass of that interval.
    """
    g = np.asarray(grid_rad, dtype=float)
    nxt = np.r_[g[1:], g[0] + np.pi]
    prv = np.r_[g[-1] - np.pi, g[:-1]]
    lo, hi = 0.5 * (prv + g), 0.5 * (g + nxt)
    w = (
        prior.aligned_weight * _wrapped_normal_mass(lo, hi, prior.aligned_sigma_rad)
        + prior.broad_weight * _wrapped_normal_mass(lo, hi, prior.broad_sigma_rad)
        + prior.uniform_weight * (hi - lo) / np.pi
    )
    return np.asarray(w / w.sum())


_IMAGES = (-np.pi, 0.0, np.pi)
"""Shifts of the wrapped Gaussian (period π) that are summed: three are plenty for σ ≤ 20°."""


def wrapped_normal(x: NDArray[np.float64], sigma: float) -> NDArray[np.float64]:
    """Density of N(0, σ) wrapped to a period of π."""
    return np.asarray(
        sum(np.exp(-0.5 * ((x + k) / sigma) ** 2) for k in _IMAGES)
        / (sigma * math.sqrt(2.0 * math.pi))
    )


def _wrapped_normal_mass(
    lo: NDArray[np.float64], hi: NDArray[np.float64], sigma: float
) -> NDArray[np.float64]:
    """Mass of N(0, σ) wrapped to a period of π on the intervals [lo, hi]."""
    s = sigma * math.sqrt(2.0)
    return np.asarray(sum(0.5 * (_erf((hi + k) / s) - _erf((lo + k) / s)) for k in _IMAGES))


def _erf(x: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.asarray(special.erf(x), dtype=float)
