"""Fitting the priors of ``ours`` to labelled data (what ``benchmarks/ours_kitti.py`` does
leave one sequence out, and what the shipped defaults were fitted with on all sequences).

Nothing here looks at a distance error: the heading prior is the distribution of the labels'
headings, the box-edge noise is the spread of the labels' 2D box edges around the projection of
their own 3D boxes.

Convention: camera x right, y down, z forward; radians, metres, pixels. ψ (heading) is the
angle of a vehicle's length axis from the camera's z axis, positive towards +x, modulo π.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import optimize

from slopedist.core.errors import ConfigurationError
from slopedist.estimators.ours.priors import YawPrior, wrapped_normal

FloatArray = NDArray[np.float64]


def kitti_heading(rotation_y_rad: ArrayLike) -> FloatArray:
    """Heading ψ (this module's convention) of KITTI labels' ``rotation_y``, in [−π/2, π/2).

    KITTI's ``rotation_y`` is the angle of the length axis from the camera's x axis (about y),
    so the length axis points along ``(cos r_y, −sin r_y)`` in (x, z); ψ is measured from the
    z axis towards +x, so ``ψ = r_y + π/2`` modulo π.
    """
    r = np.asarray(rotation_y_rad, dtype=float)
    return np.asarray(np.mod(r + np.pi, np.pi) - 0.5 * np.pi)


def fit_yaw_prior(headings_rad: ArrayLike) -> YawPrior:
    """Maximum-likelihood :class:`YawPrior` of observed headings (radians, taken modulo π).

    The three weights (softmax) and two spreads (logarithms) are fitted with Nelder–Mead from
    two starts; the narrower Gaussian is reported as the aligned one.

    Raises:
        ConfigurationError: fewer than 10 finite headings.
    """
    x = np.asarray(headings_rad, dtype=float).reshape(-1)
    x = np.mod(x[np.isfinite(x)] + 0.5 * np.pi, np.pi) - 0.5 * np.pi
    if x.size < 10:
        raise ConfigurationError(f"need at least 10 finite headings to fit, got {x.size}")

    def unpack(p: NDArray[np.float64]) -> tuple[NDArray[np.float64], float, float]:
        a = np.exp(np.r_[p[:2], 0.0] - max(p[0], p[1], 0.0))
        return a / a.sum(), math.exp(p[2]), math.exp(p[3])

    def nll(p: NDArray[np.float64]) -> float:
        a, s1, s2 = unpack(p)
        if not (1e-4 < s1 < 1.0 and 1e-4 < s2 < 1.0):
            return math.inf
        dens = a[0] * wrapped_normal(x, s1) + a[1] * wrapped_normal(x, s2) + a[2] / np.pi
        return -float(np.sum(np.log(dens)))

    best = None
    for start in (
        [1.0, 0.5, math.log(0.02), math.log(0.08)],
        [1.0, 1.0, math.log(0.01), math.log(0.05)],
    ):
        res = optimize.minimize(
            nll,
            np.asarray(start),
            method="Nelder-Mead",
            options={"maxiter": 5000, "xatol": 1e-7, "fatol": 1e-7},
        )
        if best is None or res.fun < best.fun:
            best = res
    assert best is not None
    a, s1, s2 = unpack(best.x)
    if s2 < s1:
        a = a[[1, 0, 2]]
        s1, s2 = s2, s1
    return YawPrior(float(a[0]), s1, float(a[1]), s2)


def kitti_box_corners(
    location_m: ArrayLike, dims_hwl_m: ArrayLike, rotation_y_rad: ArrayLike
) -> FloatArray:
    """The eight corners ``(N, 8, 3)`` (camera x, y, z; metres) of KITTI label 3D boxes.

    ``location_m`` ``(N, 3)`` is the bottom centre (KITTI's x, y, z), ``dims_hwl_m`` ``(N, 3)``
    height, width, length; the length lies along the box's x axis before the rotation
    ``rotation_y`` about the camera's y axis (KITTI's devkit convention).
    """
    loc = np.asarray(location_m, dtype=float).reshape(-1, 3)
    d = np.asarray(dims_hwl_m, dtype=float).reshape(-1, 3)
    ry = np.asarray(rotation_y_rad, dtype=float).reshape(-1)
    h, w, ln = d[:, 0:1], d[:, 1:2], d[:, 2:3]
    xs = ln * np.array([0.5, 0.5, -0.5, -0.5, 0.5, 0.5, -0.5, -0.5])
    ys = -h * np.array([0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0])
    zs = w * np.array([0.5, -0.5, -0.5, 0.5, 0.5, -0.5, -0.5, 0.5])
    c, s = np.cos(ry)[:, None], np.sin(ry)[:, None]
    return np.stack(
        [c * xs + s * zs + loc[:, 0:1], ys + loc[:, 1:2], -s * xs + c * zs + loc[:, 2:3]], axis=-1
    )


def project_kitti_boxes(
    P: ArrayLike, location_m: ArrayLike, dims_hwl_m: ArrayLike, rotation_y_rad: ArrayLike
) -> FloatArray:
    """2D boxes ``(N, 4)`` (left, top, right, bottom; pixels) of KITTI label 3D boxes seen by
    the 3×4 projection matrix ``P`` (e.g. the calibration's ``P2``), unclipped.

    Raises:
        ConfigurationError: ``P`` is not 3×4, or a box reaches behind the camera.
    """
    Pm = np.asarray(P, dtype=float)
    if Pm.shape != (3, 4):
        raise ConfigurationError(f"projection matrix must be 3x4, got shape {Pm.shape}")
    pts = kitti_box_corners(location_m, dims_hwl_m, rotation_y_rad)
    hom = pts @ Pm[:, :3].T + Pm[:, 3]
    if np.any(hom[..., 2] <= 0):
        raise ConfigurationError("a 3D box reaches behind the camera: it has no 2D box")
    u, v = hom[..., 0] / hom[..., 2], hom[..., 1] / hom[..., 2]
    return np.stack([u.min(axis=1), v.min(axis=1), u.max(axis=1), v.max(axis=1)], axis=1)


def box_edge_noise_px(boxes: ArrayLike, reference: ArrayLike) -> float:
    """Pixel noise of box edges around reference boxes: the root mean square over the four
    edges of each edge's robust spread (1.4826 × the median absolute deviation from its median
    offset), so that boxes cut by the image border or mislabelled do not count.

    Args:
        boxes: ``(N, 4)`` boxes (left, top, right, bottom), pixels.
        reference: ``(N, 4)`` the boxes they should be (e.g. :func:`project_kitti_boxes` of the
            same labels).

    Raises:
        ConfigurationError: shapes differ or fewer than 10 finite pairs.
    """
    b = np.asarray(boxes, dtype=float)
    r = np.asarray(reference, dtype=float)
    if b.shape != r.shape or b.ndim != 2 or b.shape[1] != 4:
        raise ConfigurationError(
            f"boxes and reference must both be (N, 4), got {b.shape} and {r.shape}"
        )
    res = b - r
    res = res[np.all(np.isfinite(res), axis=1)]
    if res.shape[0] < 10:
        raise ConfigurationError(f"need at least 10 finite box pairs, got {res.shape[0]}")
    mad = np.median(np.abs(res - np.median(res, axis=0)), axis=0)
    return float(np.sqrt(np.mean((1.4826 * mad) ** 2)))


@dataclass(frozen=True)
class LabelFitInputs:
    """What the fits need from one labelled sequence: the headings ψ ``(N,)`` (radians), the 2D
    boxes ``(N, 4)`` and the projections of the same labels' 3D boxes ``(N, 4)`` (pixels)."""

    headings_rad: FloatArray
    boxes: FloatArray
    projected: FloatArray


def kitti_tracking_fit_inputs(root: str | Path, name: str) -> LabelFitInputs:
    """:class:`LabelFitInputs` of the label rows of KITTI tracking sequence ``name`` under
    ``root`` that the evaluation protocol keeps (Car/Van, not truncated, occluded ≤ 1, z ≤ 80 m),
    with the calibration's ``P2``.

    Raises:
        MissingInputError: the sequence's labels or calibration are absent.
        InputFileError: a file is malformed.
    """
    from slopedist.core.camera import read_kitti_calib
    from slopedist.io.kitti.tracking import load_sequence, protocol_mask

    seq = load_sequence(root, name)
    gt = seq.labels.select(protocol_mask(seq.labels))
    P2 = read_kitti_calib(seq.calib_path)["P2"].reshape(3, 4)
    loc = np.stack([gt.extra["x"], gt.extra["y"], gt.extra["z"]], axis=1)
    return LabelFitInputs(
        kitti_heading(gt.extra["rotation_y"]),
        gt.boxes,
        project_kitti_boxes(P2, loc, gt.extra["dims_hwl"], gt.extra["rotation_y"]),
    )


def fit_parameters(inputs: Sequence[LabelFitInputs]) -> dict[str, Any]:
    """The options of ``ours`` fitted on labelled sequences: ``yaw_prior`` (:func:`fit_yaw_prior`
    of their headings; weights rounded to 0.001, spreads to 0.01°) and ``box_sigma_px``
    (:func:`box_edge_noise_px` of their boxes against their 3D boxes' projections, rounded to
    0.01 px). The defaults of :class:`~slopedist.estimators.ours.OursConfig` are this fit on all
    13 shared KITTI tracking sequences."""
    fit = fit_yaw_prior(np.concatenate([i.headings_rad for i in inputs]))
    sigma = box_edge_noise_px(
        np.concatenate([i.boxes for i in inputs]), np.concatenate([i.projected for i in inputs])
    )
    return {
        "yaw_prior": YawPrior(
            round(fit.aligned_weight, 3),
            math.radians(round(math.degrees(fit.aligned_sigma_rad), 2)),
            round(fit.broad_weight, 3),
            math.radians(round(math.degrees(fit.broad_sigma_rad), 2)),
        ),
        "box_sigma_px": round(sigma, 2),
    }
