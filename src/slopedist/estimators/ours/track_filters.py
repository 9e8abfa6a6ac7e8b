"""The filters each track of ``ours`` runs over its frames: the distance (a constant-velocity
Kalman filter on log distance, with the noise the track shows) and the target's road gradient (a
random walk), and the gradient prior the ground-contact cue takes from them.

Functions of the frame's records (:mod:`~slopedist.estimators.ours.records`); the filter
equations are :mod:`~slopedist.estimators.ours.filter`'s. Log distances ``ℓ = log(Z / 1 m)``,
angles in radians, image coordinates in pixels, times in seconds.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.estimators.ours import cues, fusion
from slopedist.estimators.ours import filter as kf
from slopedist.estimators.ours.config import OursAblation
from slopedist.estimators.ours.fusion import LogCue
from slopedist.estimators.ours.records import (
    DistanceFilterResult,
    FrameTargets,
    FusedCues,
    TargetGradient,
    TrackMatch,
)

FloatArray = NDArray[np.float64]


def contact_gradient_prior(
    gradient_feedback: bool, gradient_sigma_rad: float, match: TrackMatch
) -> tuple[FloatArray | float, FloatArray | float]:
    """Mean and variance (rad, rad²) of the target gradient α the ground-contact cue uses:
    each track's estimate predicted to now (``gradient_feedback``), else the prior (spread
    ``gradient_sigma_rad``)."""
    if not gradient_feedback:  # the prior, the same for every target
        return 0.0, gradient_sigma_rad**2
    n = match.rows.shape[0]
    grad_m = np.zeros(n)
    grad_v = np.full(n, np.inf)
    grad_o = np.zeros(n)
    if match.continued_rows.size:
        grad_m[match.continued] = match.before.gradient_mean_rad
        grad_v[match.continued] = match.gradient_var_rad2
        grad_o[match.continued] = match.before.gradient_var_other_rad2
    a_m, a_v = fusion.shrink_to_prior(grad_m, grad_v + grad_o, gradient_sigma_rad)
    return a_m[:, None], a_v[:, None]


_MIN_DEPTH_RATIO = 0.1
"""Smallest depth change the camera's rotation may cause a track between two updates."""


def filter_distance(
    abl: OursAblation,
    match: TrackMatch,
    measurement: LogCue,
    depth_ratio: FloatArray | None,
    keep_predicted: bool = False,
) -> DistanceFilterResult:
    """Update the continued tracks' distance filters (constant velocity, with the depth change
    ``depth_ratio`` ``(m,)``, ``Z_now/Z_last``, the camera's rotation gives each continued
    track); a box further than ``gate_sigma`` from its track's prediction and every new box
    start a filter at the measurement, as every box does when ``depth_ratio`` is None (no
    motion model or no continued track). ``keep_predicted``: also give the predicted rows
    (an offline pass)."""
    n = match.rows.shape[0]
    continued = np.zeros(n, dtype=bool)
    if depth_ratio is None:
        filt = kf.start_rows(measurement.mean, measurement.var_white, abl.rate_sigma_per_s)
        return DistanceFilterResult(filt, match.rows, continued)
    prior = match.before.filter_rows.copy()
    prior[0] += np.log(np.maximum(depth_ratio, _MIN_DEPTH_RATIO))
    pred = kf.cv_predict_rows(prior, match.elapsed_s, abl.process.accel_mps2)
    old = match.continued
    m_old, v_old, w_old = measurement.mean[old], measurement.var[old], measurement.var_white[old]
    updated, nis = kf.cv_update_rows(pred, m_old, w_old)
    scale = None
    if abl.noise_time_s is not None:  # the frame-to-frame noise this track shows
        prior_scale = match.before.noise_scale
        scale = _noise_scale(prior_scale, nis, match.elapsed_s, abl.noise_time_s)
    dev = m_old - pred[0]
    same = dev * dev <= (pred[2] + v_old) * abl.gate_sigma**2
    predicted = None
    if keep_predicted:
        predicted = np.full((5, n), np.nan)
        predicted[:, np.flatnonzero(old)[same]] = pred[:, same]
    filt = kf.start_rows(measurement.mean, measurement.var_white, abl.rate_sigma_per_s)
    idx = np.flatnonzero(old)
    filt[:, idx[same]] = updated[:, same]
    continued[idx[same]] = True
    rows = match.rows.copy()
    rows[idx[~same]] = -1  # another vehicle took this track's id or place: afresh
    scale_all = None
    if scale is not None:
        scale_all = np.ones(n)
        scale_all[idx[same]] = scale[same]
    return DistanceFilterResult(filt, rows, continued, predicted, scale_all)


def _noise_scale(
    prior_scale: FloatArray, nis: FloatArray, elapsed_s: FloatArray, time_s: float
) -> FloatArray:
    """A track's measurement-noise scale: how many times the frame-to-frame (white) variance
    its filter is told its measurements actually jump.

    The normalised innovation squared of the filter's update, ``nis = ν²/(P_pred + R)``
    (:func:`~slopedist.estimators.ours.filter.cv_update_rows`, ν in log distance), has
    mean 1 when the noise model is right and about ``k`` when the noise is ``k`` times larger
    (a detector's box that grows and shrinks, cues that switch). Its running mean over about
    ``time_s`` seconds (weight ``min(1, dt/time_s)`` per update), started at 1, is the scale.
    The filter itself keeps the nominal noise (a filter told the larger noise lags approaching
    vehicles: on KITTI it cost 1–2 % of RMSE); the scale widens the σ of the speed and the
    time to collision it reports (:func:`~slopedist.estimators.ours.outputs.box_estimates`),
    which the jumps make uncertain."""
    weight = np.minimum(elapsed_s * (1.0 / time_s), 1.0)
    return prior_scale + weight * (nis - prior_scale)


def target_gradient(
    gradient_sigma_rad: float,
    cam: Camera,
    targets: FrameTargets,
    match: TrackMatch,
    fused: FusedCues,
    rows: NDArray[np.int64],
    theta_rad: float,
    jitter_rad: float,
    cam_height_m: float,
) -> TargetGradient:
    """Each target's continuous road gradient α from its box centre's offset Δy below the
    horizon and the size distance (:func:`~slopedist.estimators.ours.cues.target_gradient`),
    updated as a random walk over its track (``rows``: after the distance gate), and combined
    with the prior of spread ``gradient_sigma_rad``."""
    f = cam.f
    size = fused.size
    boxes = targets.boxes_px
    z_size = np.exp(size.mean)
    delta_y = (boxes[:, 1] + boxes[:, 3]) * 0.5 - (cam.c_y - f * math.tan(theta_rad))
    flat = cues.expected_centre_offset_px(
        z_size, f, cam_height_m, targets.classes.height_m, fused.half_extent_m
    )
    a_obs = np.arctan((flat - delta_y) * (1.0 / f))  # cues.target_gradient, flat once
    gain2 = flat * flat * (1.0 / (f * f))
    a_white = gain2 * size.var_white + (targets.box_sigma_px**2 + (f * jitter_rad) ** 2) / f**2
    z_h_sd = targets.classes.height_sigma_m * 0.5 / z_size
    a_other = gain2 * (size.var - size.var_white) + z_h_sd * z_h_sd
    prior_mean, prior_var = _gradient_prior(
        rows, match.continued, match.before.gradient_mean_rad, match.gradient_var_rad2
    )
    g_mean, g_var = kf.random_walk_update(prior_mean, prior_var, 0.0, 0.0, a_obs, a_white)
    alpha, alpha_var = fusion.shrink_to_prior(g_mean, g_var + a_other, gradient_sigma_rad)
    return TargetGradient(g_mean, g_var, a_other, alpha, alpha_var, delta_y, z_size)


_MAX_GRADIENT_VAR = 1e6
"""Prior variance of a new track's road gradient (rad², practically none)."""


def _gradient_prior(
    rows: NDArray[np.int64], old: NDArray[np.bool_], mean_old: FloatArray, var_old: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Mean and variance (rad, rad²) of each target's road gradient before this frame: its
    track's random walk predicted to now (``mean_old``, ``var_old``: of the targets ``old``
    that were associated with a track), or (0, 10⁶) for a target that starts a track (``rows``
    < 0, after the gate)."""
    kept = rows[old] >= 0
    mean, var = np.zeros(rows.shape), np.full(rows.shape[0], _MAX_GRADIENT_VAR)
    idx = np.flatnonzero(old)[kept]
    mean[idx] = mean_old[kept]
    var[idx] = np.minimum(var_old[kept], _MAX_GRADIENT_VAR)
    return mean, var
