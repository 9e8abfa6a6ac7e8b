"""The cue steps of one frame of ``ours``: size cues, ground contact, occlusion, fusion over the
heading hypotheses, the target gradient and the outputs.

Functions of the frame's records (:mod:`~slopedist.estimators.ours.records`) and the options; the
state (tracks, self-calibration) stays with :class:`~slopedist.estimators.ours.estimator.
OursEstimator`. Camera frame x right, y down, z forward; distances in metres, log distances
``ℓ = log(Z / 1 m)``, angles in radians, image coordinates in pixels.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.estimators.ours import cues, fusion, road_bend
from slopedist.estimators.ours import filter as kf
from slopedist.estimators.ours.config import OursAblation
from slopedist.estimators.ours.cues import SizeCue
from slopedist.estimators.ours.fusion import LogCue, ModeSpreads
from slopedist.estimators.ours.occlusion import hidden_sides, occlusion_log_var, unexplained_excess
from slopedist.estimators.ours.records import (
    BoxEstimates,
    CalibrationInUse,
    DistanceFilterResult,
    FrameTargets,
    FusedCues,
    SizeCues,
    TargetGradient,
    TrackMatch,
    UpperBound,
)

FloatArray = NDArray[np.float64]


def size_cues(
    cfg: OursAblation, cam: Camera, targets: FrameTargets, calib: CalibrationInUse
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
    if cfg.use_width:
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
    return _border_cut_size_cues(cfg, targets, SizeCues(height, width, []))


def shape_gap(targets: FrameTargets, size: SizeCues) -> FloatArray:
    """How far each target's box shape is from its class's: the gap between its height and
    width cues at the heading that explains it best, in σ of the class prior (``(n,)``; NaN
    without a width cue; :func:`~slopedist.estimators.ours.fusion.shape_gap_sigma`)."""
    hyp = targets.classes.hypotheses
    return fusion.shape_gap_sigma(
        size.height, size.width, hyp.log_sigma_height, hyp.log_sigma_width, hyp.corr_height_width
    )


def _border_cut_size_cues(cfg: OursAblation, targets: FrameTargets, size: SizeCues) -> SizeCues:
    """The size cues with the dimensions cut by the image border (height: top or bottom;
    width: a side) weakened and, with ``censor_border_cuts``, turned into upper bounds."""
    cuts = targets.border_cuts
    if cuts is None:
        return size
    hyp = targets.classes.hypotheses
    height, width, bounds, _ = size
    cut_h = (cuts.top | cuts.bottom)[:, None]
    if cut_h.any():
        height = _cut_by_border(cfg, height, hyp.log_sigma_height, cut_h, bounds, True)
    if cfg.use_width and cuts.sides.any():
        width = _cut_by_border(cfg, width, hyp.log_sigma_width, cuts.sides[:, None], bounds, False)
    return SizeCues(height, width, bounds)


def _cut_by_border(
    cfg: OursAblation,
    cue: SizeCue,
    log_sigma: FloatArray,
    rows: NDArray[np.bool_],
    bounds: list[UpperBound],
    inflate_other: bool,
) -> SizeCue:
    """``cue`` with its white variance (and its other variance when ``inflate_other``)
    multiplied by ``truncation_factor²`` where ``rows`` ``(n, 1)``; the cue as it was becomes
    an upper bound there (appended to ``bounds``) when ``censor_border_cuts``."""
    if cfg.censor_border_cuts:
        bounds.append(UpperBound(cue.mean, _total_var(cue, log_sigma), rows))
    inflation = cfg.truncation_factor**2
    return cue._replace(
        var_white=np.where(rows, cue.var_white * inflation, cue.var_white),
        var_other=np.where(rows, cue.var_other * inflation, cue.var_other)
        if inflate_other
        else cue.var_other,
    )


def ground_contact_cue(
    cfg: OursAblation,
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
    cos2 = math.cos(theta_rad) ** 2
    v_target = cam.c_y - f * (
        np.tan(theta_rad + alpha) if cfg.gradient_feedback else math.tan(theta_rad)
    )
    row_white = targets.box_sigma_px**2 + (f * jitter_rad / cos2) ** 2
    row_other = (f / cos2) ** 2 * (alpha_var + calib.horizon_offset_sigma_rad**2)
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
        if cfg.censor_border_cuts:
            bounds.append(UpperBound(ground.mean, ground.var, rows))
        ground = fusion.inflate(ground, rows, cfg.truncation_factor**2)
    return ground


def occlusion_adjusted(
    cfg: OursAblation, targets: FrameTargets, size: SizeCues, ground: LogCue
) -> SizeCues:
    """A size cue that says too far may show only part of a vehicle hidden behind a nearer
    one (censored): which sides nearer boxes may cut, then the outlier test against the
    ground contact; the unexplained excess becomes per-vehicle variance."""
    gate = cfg.occlusion_gate_sigma
    hyp = targets.classes.hypotheses
    height, width, bounds, _ = size
    cut_w, cut_h = hidden_sides(targets.boxes_px, gate * targets.box_sigma_px)
    if cut_h.any():
        excess = unexplained_excess(
            height.mean, _total_var(height, hyp.log_sigma_height), ground.mean, ground.var, gate
        )
        extra = occlusion_log_var(excess, cut_h[:, None])
        height = height._replace(var_other=height.var_other + extra)
    if cfg.use_width and cut_w.any():
        excess = unexplained_excess(
            width.mean, _total_var(width, hyp.log_sigma_width), ground.mean, ground.var, gate
        )
        extra = occlusion_log_var(excess, cut_w[:, None])
        width = width._replace(var_other=width.var_other + extra)
    return SizeCues(height, width, bounds, cut_w | cut_h)


def fuse_hypotheses(
    targets: FrameTargets,
    size: SizeCues,
    ground: LogCue | None,
    log_prior: FloatArray,
    size_modes: ModeSpreads,
    gate_sigma: float = 3.0,
    height_lever: FloatArray | None = None,
) -> FusedCues:
    """Fuse the cues per hypothesis (headings × size modes: a class mixes typical vehicles
    and, less often, ones of atypical height and odd objects of no class's size; or, when a
    target's class is generic, the vehicle types × headings the cues were computed for),
    censor by the bounds, and collapse the hypotheses by their posterior weights.

    The targets' class constants, and so the cues, are ``(n, modes·K)``: repeated over the size
    modes (mode-major, :class:`~slopedist.estimators.ours.class_table.ClassTable`'s
    ``n_modes``) for a specific class, over the vehicle types for a generic one.
    ``log_prior``: ``(n, K·modes)`` log prior of the hypotheses; ``size_modes``: how each mode
    widens the class's size spreads (:class:`~slopedist.estimators.ours.fusion.ModeSpreads`
    of the targets' hypotheses: of a single mode when their class is generic);
    ``gate_sigma``: the cue consistency check's threshold
    (:func:`~slopedist.estimators.ours.fusion.check_consistency`); ``height_lever``: the
    height cue's ``∂ℓ/∂h`` per hypothesis (its ``SizeCue.camera_lever``) for the fused
    ``camera_lever`` (None: not computed).
    """
    hyp = targets.classes.hypotheses
    type_weight = targets.classes.type_log_weight
    n_modes = len(size_modes.modes)
    spreads = size_modes.spreads(hyp.log_sigma_height, hyp.log_sigma_width)
    size_cue = fusion.fuse_size_cues(size.height, size.width, *spreads, hyp.corr_height_width)
    fused = size_cue if ground is None else fusion.fuse_log_cues(size_cue, ground)
    corr = hyp.corr_height_width
    lever = road_bend.fused_camera_lever(size, spreads, corr, size_cue, ground, height_lever)
    for bound, bound_var, rows_cut in size.bounds:
        fused = fusion.censor_upper(fused, bound, bound_var, rows_cut)
    extent, width_mean = hyp.half_extent_m, size.width.mean
    if n_modes > 1:  # what every mode shares, per heading: the first mode's columns
        k = extent.shape[1] // n_modes
        extent, width_mean = extent[:, :k], width_mean[:, :k]
        if ground is not None:
            ground = LogCue(
                ground.mean[:, :k], ground.var[:, :k], ground.var_white[:, :k], ground.loglik[:, :k]
            )
    collapsed, weights = _collapse(
        width_mean,
        size_cue,
        fused,
        ground,
        n_modes if type_weight is None else type_weight.shape[1],
        log_prior,
        extent,
        most_likely_mode=type_weight is not None,
        gate=gate_sigma,
        odd_mode=size_modes.odd,
    )
    if lever is None:
        return collapsed
    return collapsed._replace(camera_lever=np.add.reduce(weights * lever, axis=1))


def _collapse(
    width_mean: FloatArray,
    size_cue: LogCue,
    fused: LogCue,
    ground: LogCue | None,
    n_modes: int,
    log_prior: FloatArray,
    extent: FloatArray,
    most_likely_mode: bool = False,
    gate: float = 3.0,
    odd_mode: int | None = None,
) -> tuple[FusedCues, FloatArray]:
    """Collapse the fused cues ``(n, modes·K)`` (mode-major) over the hypotheses by their
    posterior weights (``extent``: the half depth extent, m, ``ground``: the ground contact and
    ``width_mean``: the width cue's ℓ, each per hypothesis or, when the same in every mode, per
    heading ``(n, K)``;
    ``odd_mode``: the index of the odd-object mode, whose posterior weight is reported, if
    there is one); also returns the posterior weights ``(n, modes·K)``.

    With ``most_likely_mode`` (vehicle types), the mean is the most probable mode's (its
    headings collapsed) and the other modes only widen the variance: a type the cues cannot
    tell apart from the common one leaves the estimate where the common one puts it instead of
    pulling it by the rarer types' prior weight.
    """
    n = fused.mean.shape[0]
    measurement, weights = fusion.collapse_hypotheses(fused, log_prior + fused.loglik)
    by_mode = weights.reshape(n, n_modes, -1)
    heading_weights = np.add.reduce(by_mode, axis=1) if n_modes > 1 else weights
    size_mix = fusion.mix_hypotheses(size_cue, weights)
    if most_likely_mode and n_modes > 1:
        rows = np.arange(n)
        best = by_mode.sum(axis=2).argmax(axis=1)
        in_best = np.zeros_like(by_mode)
        in_best[rows, best] = by_mode[rows, best]
        w_best = in_best.reshape(n, -1)
        w_best /= np.add.reduce(w_best, axis=1, keepdims=True)
        measurement = fusion.widen_to_mixture(fused, w_best, weights)
        size_mix = fusion.widen_to_mixture(size_cue, w_best, weights)
        width_mean = width_mean.reshape(n, n_modes, -1)[rows, best]
    gap = np.full(n, np.nan)
    ground_mix = None
    if ground is not None:  # per heading (the same in every size mode), or per hypothesis
        by_heading = ground.mean.shape[1] == heading_weights.shape[1]
        ground_mix = fusion.mix_hypotheses(ground, heading_weights if by_heading else weights)
        measurement, gap = fusion.check_consistency(measurement, size_mix, ground_mix, gate)
    extent_weights = heading_weights if extent.shape[1] == heading_weights.shape[1] else weights
    return FusedCues(
        measurement,
        size_mix,
        fused.loglik,
        log_prior,
        heading_weights,
        np.add.reduce(extent_weights * extent, axis=1),
        np.add.reduce(heading_weights * width_mean, axis=1),
        gap,
        ground_mix,
        np.add.reduce(by_mode[:, odd_mode], axis=1) if odd_mode is not None else np.zeros(n),
    ), weights


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
    cfg: OursAblation,
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
        filt = kf.start_rows(measurement.mean, measurement.var_white, cfg.rate_sigma_per_s)
        return DistanceFilterResult(filt, match.rows, continued)
    prior = match.before.filter_rows.copy()
    prior[0] += np.log(np.maximum(depth_ratio, _MIN_DEPTH_RATIO))
    pred = kf.cv_predict_rows(prior, match.elapsed_s, cfg.process.accel_mps2)
    old = match.continued
    m_old, v_old, w_old = measurement.mean[old], measurement.var[old], measurement.var_white[old]
    updated, nis = kf.cv_update_rows(pred, m_old, w_old)
    scale = None
    if cfg.noise_time_s is not None:  # the frame-to-frame noise this track shows
        prior_scale = match.before.noise_scale
        scale = _noise_scale(prior_scale, nis, match.elapsed_s, cfg.noise_time_s)
    dev = m_old - pred[0]
    same = dev * dev <= (pred[2] + v_old) * cfg.gate_sigma**2
    predicted = None
    if keep_predicted:
        predicted = np.full((5, n), np.nan)
        predicted[:, np.flatnonzero(old)[same]] = pred[:, same]
    filt = kf.start_rows(measurement.mean, measurement.var_white, cfg.rate_sigma_per_s)
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
    time to collision it reports (:func:`box_estimates`), which the jumps make uncertain."""
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


def box_estimates(
    cam: Camera,
    yaw_grid_rad: FloatArray,
    targets: FrameTargets,
    fused: FusedCues,
    distance: DistanceFilterResult,
    gradient: TargetGradient,
    uid: NDArray[np.int64],
    theta_rad: float,
    calib: CalibrationInUse,
    gradient_sigma_rad: float = 0.0,
) -> BoxEstimates:
    """The outputs: the filtered centre distance with its σ and motion, the target gradient,
    the most likely heading (of the grid ``yaw_grid_rad``) and the two cues' own distances.
    With ``fused.camera_lever``, σ adds the camera height above the target's road
    (:func:`~slopedist.estimators.ours.road_bend.road_bend_log_var`, prior spread
    ``gradient_sigma_rad``)."""
    f = cam.f
    filt = distance.filter_rows
    meas = fused.measurement
    persistent = meas.var - meas.var_white
    dist, sigma = kf.distance_moments_rows(filt, persistent)
    sigma_only = road_bend.sigma_only_log_var(targets, fused, gradient, gradient_sigma_rad)
    if sigma_only is not None:  # the distance stays the class's own: its σ only widens
        sigma = kf.distance_moments_rows(filt, persistent + sigma_only)[1]
    speed, speed_sd, ttc, ttc_sd = _motion_outputs(filt, distance.continued)
    if distance.noise_scale is not None:  # the noise the track shows, when it is larger
        widen = np.sqrt(np.maximum(distance.noise_scale, 1.0))
        speed_sd, ttc_sd = speed_sd * widen, ttc_sd * widen
    v_frame = cam.c_y - f * math.tan(theta_rad)
    theta_adj = theta_rad + gradient.gradient_rad  # the target's road: θ + α
    ground = cues.ground_contact_cue(
        targets.boxes_px[:, 3], v_frame, f, calib.height_m, fused.half_extent_m
    )
    return BoxEstimates(
        distance_m=dist,
        theta_adj_rad=theta_adj,
        v_px=cam.c_y - f * np.tan(theta_adj),
        delta_y_px=gradient.delta_y_px,
        sigma_m=sigma,
        distance_nearest_face_m=dist - fused.half_extent_m,
        speed_mps=speed,
        speed_sigma_mps=speed_sd,
        ttc_s=ttc,
        ttc_sigma_s=ttc_sd,
        target_gradient_rad=gradient.gradient_rad,
        target_gradient_sigma_rad=np.sqrt(gradient.gradient_var_rad2),
        yaw_rad=yaw_grid_rad[fused.heading_weights.argmax(axis=1)],
        distance_size_m=gradient.size_distance_m,
        distance_ground_contact_m=ground,
        distance_width_m=np.exp(fused.width_log),
        cue_gap_sigma=fused.cue_gap_sigma,
        track_uid=uid.astype(float),
        odd_size_prob=fused.odd_size_prob,
    )


def _motion_outputs(
    filt: FloatArray, continued: NDArray[np.bool_]
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Speed (m/s), its σ, time to collision (s) and its σ; NaN for a track's first frame."""
    speed, speed_sd, ttc, ttc_sd = (
        np.where(continued, a, np.nan) for a in kf.motion_moments_rows(filt)
    )
    return speed, speed_sd, ttc, ttc_sd


def _total_var(cue: SizeCue, log_sigma: FloatArray) -> FloatArray:
    """Total variance of a size cue's log distance: its noise and the class's size spread
    (relative spread ``log_sigma`` times the cue's lever)."""
    return (cue.lever * log_sigma) ** 2 + cue.var_white + cue.var_other


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


def carried_heading_prior(
    match: TrackMatch, log_yaw_prior: FloatArray, memory_s: float
) -> FloatArray:
    """``(n, K)`` log heading prior of each target when the tracks carry their heading belief
    (``yaw_memory``): a continued track's belief relaxing to the prior ``log_yaw_prior``
    ``(K,)`` with time constant ``memory_s`` (s); the prior for a new track."""
    mix = 1.0 - np.exp(-match.elapsed_s / memory_s)
    carried = (1.0 - mix[:, None]) * np.exp(match.before.log_heading_belief.T) + mix[
        :, None
    ] * np.exp(log_yaw_prior)
    n = match.rows.shape[0]
    log_pi = np.broadcast_to(log_yaw_prior[None, :], (n, log_yaw_prior.size)).copy()
    log_pi[match.continued] = np.log(np.maximum(carried, 1e-300))
    return log_pi


def heading_belief(fused: FusedCues, evidence_weight: float, n_headings: int) -> FloatArray:
    """``(n, K)`` normalised log heading belief after this frame: the prior times the cues'
    likelihood tempered by ``evidence_weight`` (consecutive frames are correlated evidence),
    summed over the body-style modes or vehicle types."""
    belief = fused.log_prior + evidence_weight * fused.loglik
    n_modes = belief.shape[1] // n_headings
    if n_modes > 1:
        n = belief.shape[0]
        belief = np.logaddexp.reduce(belief.reshape(n, n_modes, -1), axis=1)
    return belief - np.logaddexp.reduce(belief, axis=1, keepdims=True)
