"""The cues of a frame's targets in ``ours``, per (target, hypothesis): the size cues (box
height and width), the ground contact, and the size cues that the image border or a nearer box
may cut.

Each cue is a log distance with its variance split into a white part (independent from frame to
frame) and a per-vehicle part (:class:`~slopedist.estimators.ours.fusion.LogCue`); the formulas
are :mod:`~slopedist.estimators.ours.cues`'. A cue cut by the image border keeps a weak weight
and bounds the distance from above. The ground contact's trust is set by the noise of its row
(:func:`contact_row_noise`: the box edge, the horizon jitter, the target-gradient prior and the
mount noise).

Camera frame x right, y down, z forward; distances in metres, log distances ``ℓ = log(Z / 1 m)``,
angles in radians, image coordinates in pixels.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.estimators.ours import cues, fusion
from slopedist.estimators.ours.config import OursAblation
from slopedist.estimators.ours.cues import SizeCue
from slopedist.estimators.ours.fusion import LogCue
from slopedist.estimators.ours.occlusion import hidden_sides, occlusion_log_var, unexplained_excess
from slopedist.estimators.ours.records import (
    CalibrationInUse,
    FrameTargets,
    SizeCues,
    UpperBound,
)

FloatArray = NDArray[np.float64]


def size_cues(
    abl: OursAblation, cam: Camera, targets: FrameTargets, calib: CalibrationInUse
) -> SizeCues:
    """Height and width cues per (target, heading hypothesis); a dimension cut by the image
    border keeps a weak Gaussian weight and bounds the distance from above."""
    hyp = targets.classes.hypotheses
    height = cues.height_cue_log(
        targets.edge_px(3) - targets.edge_px(1),
        cam.f,
        calib.height_m,
        targets.box_sigma_px,
        calib.height_sigma_m,
        hyp.height_m,
        hyp.half_extent_m,
        hyp.half_extent_var_m2,
    )
    if abl.use_width:
        width = cues.width_cue_log(
            targets.edge_px(0),
            targets.edge_px(2),
            cam.f,
            cam.c_x,
            targets.box_sigma_px,
            hyp.half_width_cos_m,
            hyp.half_width_sin_m,
            hyp.half_length_cos_m,
            hyp.half_length_sin_m,
            hyp.min_centre_depth_m,
        )
        length_share = (1.0 - width.lever) * hyp.log_sigma_length
        length_share *= length_share
        width = SizeCue(width.mean, width.lever, width.var_white, length_share)
    else:
        nan = np.full(hyp.half_extent_m.shape, np.nan)
        width = SizeCue(nan, nan, nan, nan)
    return _border_cut_size_cues(abl, targets, SizeCues(height, width, []))


def shape_gap(targets: FrameTargets, size: SizeCues) -> FloatArray:
    """How far each target's box shape is from its class's: the gap between its height and
    width cues at the heading that explains it best, in σ of the class prior (``(n,)``; NaN
    without a width cue; :func:`~slopedist.estimators.ours.fusion.shape_gap_sigma`)."""
    hyp = targets.classes.hypotheses
    return fusion.shape_gap_sigma(
        size.height, size.width, hyp.log_sigma_height, hyp.log_sigma_width, hyp.corr_height_width
    )


def _border_cut_size_cues(abl: OursAblation, targets: FrameTargets, size: SizeCues) -> SizeCues:
    """The size cues with the dimensions cut by the image border (height: top or bottom;
    width: a side) weakened and, with ``censor_border_cuts``, turned into upper bounds."""
    cuts = targets.border_cuts
    if cuts is None:
        return size
    hyp = targets.classes.hypotheses
    height, width, bounds, _ = size
    cut_h = (cuts.top | cuts.bottom)[:, None]
    if cut_h.any():
        height = _cut_by_border(abl, height, hyp.log_sigma_height, cut_h, bounds, True)
    if abl.use_width and cuts.sides.any():
        width = _cut_by_border(abl, width, hyp.log_sigma_width, cuts.sides[:, None], bounds, False)
    return SizeCues(height, width, bounds)


def _cut_by_border(
    abl: OursAblation,
    cue: SizeCue,
    log_sigma: FloatArray,
    rows: NDArray[np.bool_],
    bounds: list[UpperBound],
    inflate_other: bool,
) -> SizeCue:
    """``cue`` with its white variance (and its other variance when ``inflate_other``)
    multiplied by ``truncation_factor²`` where ``rows`` ``(n, 1)``; the cue as it was becomes
    an upper bound there (appended to ``bounds``) when ``censor_border_cuts``."""
    if abl.censor_border_cuts:
        bounds.append(UpperBound(cue.mean, _total_var(cue, log_sigma), rows))
    inflation = abl.truncation_factor**2
    return cue._replace(
        var_white=np.where(rows, cue.var_white * inflation, cue.var_white),
        var_other=np.where(rows, cue.var_other * inflation, cue.var_other)
        if inflate_other
        else cue.var_other,
    )


def ground_contact_cue(
    abl: OursAblation,
    cam: Camera,
    targets: FrameTargets,
    bounds: list[UpperBound],
    alpha: FloatArray | float,
    alpha_var: FloatArray | float,
    theta_rad: float,
    jitter_rad: float,
    calib: CalibrationInUse,
) -> LogCue:
    """Eq. 1 with the horizon of θ + α per hypothesis; a box cut at the bottom keeps a weak
    weight and bounds the distance from above (appended to ``bounds``).

    ``alpha``, ``alpha_var``: the target gradient relative to θ the cue assumes (rad, rad²;
    ``(n, 1)`` per target or one for all).
    """
    f = cam.f
    v_target = cam.c_y - f * (
        np.tan(theta_rad + alpha) if abl.gradient_feedback else math.tan(theta_rad)
    )
    noise = contact_row_noise(
        f, theta_rad, targets.box_sigma_px, jitter_rad, alpha_var, calib.horizon_offset_sigma_rad
    )
    row_white, row_other = noise.white_px2, noise.per_vehicle_px2
    hyp = targets.classes.hypotheses
    ground = cues.ground_contact_log_cue(
        targets.edge_px(3),
        v_target,
        f,
        calib.height_m,
        hyp.half_extent_m,
        row_white,
        row_other,
        calib.height_sigma_m,
        hyp.half_extent_sigma_m,
    )
    cuts = targets.border_cuts
    if cuts is not None and cuts.bottom.any():
        rows = cuts.bottom[:, None]
        if abl.censor_border_cuts:
            bounds.append(UpperBound(ground.mean, ground.var, rows))
        ground = fusion.inflate(ground, rows, abl.truncation_factor**2)
    return ground


def consistent_contact(
    targets: FrameTargets, size: SizeCues, tight: LogCue, wide: LogCue, gate_sigma: float
) -> LogCue:
    """``tight`` (a ground contact trusted more than configured) where it agrees with the
    height cue within ``gate_sigma`` standard deviations of their difference at the heading
    that reconciles them best, else ``wide`` (the configured trust): a target whose road
    departs from what the drive has shown so far keeps the configured prior."""
    hyp = targets.classes.hypotheses
    height = size.height
    var = _total_var(height, hyp.log_sigma_height) + tight.var
    with np.errstate(invalid="ignore"):
        z = np.abs(height.mean - tight.mean) / np.sqrt(var)
    z_best = np.nanmin(np.where(np.isfinite(z), z, np.inf), axis=1, keepdims=True)
    off = ~(z_best <= gate_sigma)
    return LogCue(*(np.where(off, w, t) for t, w in zip(tight, wide, strict=True)))


class ContactRowNoise(NamedTuple):
    """The variance of a box's bottom row relative to the horizon the ground-contact cue
    assumes, px², split as the fusion needs it.

    Attributes:
        white_px2: the part independent from frame to frame (box edge, horizon jitter).
        per_vehicle_px2: the part that stays with a vehicle (its road's gradient, the mount);
            ``(n, 1)`` per target or one for all.
    """

    white_px2: float
    per_vehicle_px2: FloatArray | float


def contact_row_noise(
    f: float,
    theta_rad: float,
    box_sigma_px: float,
    horizon_jitter_rad: float,
    target_gradient_var_rad2: FloatArray | float,
    mount_sigma_rad: float,
) -> ContactRowNoise:
    """Where the ground-contact cue's trust comes from: the noise of the row ``b − v`` it
    reads (``b`` the box bottom, ``v`` the horizon row ``c_y − f·tan θ``; an angle error ``δ``
    moves the horizon by ``f·δ/cos²θ`` rows). Four terms:

    - **box edge**: the bottom edge's pixel noise ``box_sigma_px`` (white);
    - **horizon jitter**: the ego gradient θ's per-frame error ``horizon_jitter_rad`` (the
      ablation's ``theta_sigma_rad``, ``no_rotation_theta_sigma_rad`` without a rotation;
      white);
    - **target-gradient prior**: how far the target's road may climb relative to the ego's,
      ``target_gradient_var_rad2`` (``gradient_sigma_rad²``, or a track's estimate with
      ``gradient_feedback``; per vehicle);
    - **mount noise**: the mount angle's uncertainty ``mount_sigma_rad`` (``mount_sigma_rad``,
      or the self-calibration's σ; per vehicle).

    ``f`` focal length (px), ``theta_rad`` the ego gradient with the calibration's offset.
    """
    cos2 = math.cos(theta_rad) ** 2
    box_edge = box_sigma_px**2
    horizon_jitter = (f * horizon_jitter_rad / cos2) ** 2
    rows_per_rad2 = (f / cos2) ** 2
    per_vehicle = rows_per_rad2 * (target_gradient_var_rad2 + mount_sigma_rad**2)
    return ContactRowNoise(box_edge + horizon_jitter, per_vehicle)


def occlusion_adjusted(
    abl: OursAblation, targets: FrameTargets, size: SizeCues, ground: LogCue
) -> SizeCues:
    """A size cue that says too far may show only part of a vehicle hidden behind a nearer
    one (censored): which sides nearer boxes may cut, then the outlier test against the
    ground contact; the unexplained excess becomes per-vehicle variance."""
    gate = abl.occlusion_gate_sigma
    hyp = targets.classes.hypotheses
    height, width, bounds, _ = size
    cut_w, cut_h = hidden_sides(targets.boxes_px, gate * targets.box_sigma_px)
    if cut_h.any():
        excess = unexplained_excess(
            height.mean, _total_var(height, hyp.log_sigma_height), ground.mean, ground.var, gate
        )
        extra = occlusion_log_var(excess, cut_h[:, None])
        height = height._replace(var_other=height.var_other + extra)
    if abl.use_width and cut_w.any():
        excess = unexplained_excess(
            width.mean, _total_var(width, hyp.log_sigma_width), ground.mean, ground.var, gate
        )
        extra = occlusion_log_var(excess, cut_w[:, None])
        width = width._replace(var_other=width.var_other + extra)
    return SizeCues(height, width, bounds, cut_w | cut_h)


def _total_var(cue: SizeCue, log_sigma: FloatArray) -> FloatArray:
    """Total variance of a size cue's log distance: its noise and the class's size spread
    (relative spread ``log_sigma`` times the cue's lever)."""
    return (cue.lever * log_sigma) ** 2 + cue.var_white + cue.var_other
