"""The hypotheses ``ours`` fuses a target's cues over, and their collapse into one distance.

A box does not say which way its vehicle points nor whether the vehicle is its class's typical
size, so the cues are computed for every **hypothesis**: a heading ψ of the grid
(:data:`~slopedist.estimators.ours.priors.YAW_GRID_DEG`) × a size mode of the class (the typical
vehicle, an atypical height, an odd object: :class:`~slopedist.estimators.ours.fusion.SizeMode`),
or, for a generic class, a heading × a vehicle type
(:mod:`~slopedist.estimators.ours.vehicle_types`). Each hypothesis has a prior (the heading
prior, a track's carried heading belief, the modes' or types' weights); the fused cues weigh
them by how well they explain the box, and the hypotheses collapse into one measurement by
their posterior weights.

Per (target, hypothesis) arrays are ``(n, M·K)``: ``M`` size modes or types of ``K`` headings
each, mode-major. Log distances ``ℓ = log(Z / 1 m)``; angles in radians; times in seconds.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slopedist.estimators.ours import fusion, road_bend
from slopedist.estimators.ours.config import OursAblation
from slopedist.estimators.ours.fusion import LogCue, ModeSpreads
from slopedist.estimators.ours.priors import yaw_grid, yaw_prior_weights
from slopedist.estimators.ours.records import FrameTargets, FusedCues, SizeCues, TrackMatch
from slopedist.estimators.ours.vehicle_types import NOT_THIS_TYPE_LOG_WEIGHT

FloatArray = NDArray[np.float64]


class Hypotheses:
    """The hypotheses of an estimator's settings and their prior.

    Args:
        ablation: the settings (``yaw_hypotheses``, ``yaw_prior``, the size modes, the vehicle
            types, ``yaw_memory``).

    Attributes:
        yaw_rad: ``(K,)`` the heading hypotheses (ψ = 0 alone without ``yaw_hypotheses``).
        log_yaw_prior: ``(K,)`` their log prior.
        size_modes: the size modes of a specific class.
        mode_spreads: how the size modes widen a specific class's spreads.
        type_spreads: the same for a generic class, whose vehicle types take the modes' place
            (one mode, the typical one, over ``T·K`` columns).
    """

    def __init__(self, ablation: OursAblation) -> None:
        grid = yaw_grid() if ablation.yaw_hypotheses else np.zeros(1)
        self.yaw_rad = grid
        self.log_yaw_prior = (
            np.log(yaw_prior_weights(grid, ablation.yaw_prior)) if grid.size > 1 else np.zeros(1)
        )
        modes = ablation.size_modes
        self.size_modes = [m for m, _ in modes]
        self._log_mode = np.repeat(np.log([p for _, p in modes]), grid.size)
        self.mode_spreads = ModeSpreads(self.size_modes, grid.size)
        self.type_spreads = ModeSpreads(self.size_modes[:1], grid.size * len(ablation.type_mixture))
        self._memory_s = ablation.yaw_memory_s if ablation.yaw_memory else None

    def spreads(self, targets: FrameTargets) -> ModeSpreads:
        """How the hypotheses of ``targets`` widen their class's size spreads: the size
        modes', or the vehicle types' when a target's class is generic."""
        return self.mode_spreads if targets.classes.type_log_weight is None else self.type_spreads

    def log_prior(self, match: TrackMatch, targets: FrameTargets) -> FloatArray:
        """``(n, K·modes)`` log prior of the hypotheses (headings × body-style modes, or
        headings × vehicle types when a target's class is generic); with ``yaw_memory`` a
        continued track's heading belief takes the heading prior's place."""
        k = self.yaw_rad.size
        log_heading_prior = np.broadcast_to(self.log_yaw_prior, (match.rows.shape[0], k))
        if self._memory_s is not None and match.continued_rows.size:
            log_heading_prior = carried_heading_prior(match, self.log_yaw_prior, self._memory_s)
        type_weight = targets.classes.type_log_weight
        if type_weight is not None:
            n_types = type_weight.shape[1]
            return np.tile(log_heading_prior, n_types) + np.repeat(type_weight, k, axis=1)
        log_prior = np.tile(log_heading_prior, len(self.size_modes)) + self._log_mode
        sized = targets.classes.sized
        if sized is not None and len(self.size_modes) > 1:
            # a size the detector measured is that vehicle's: no atypical or odd mode
            log_prior[sized, k:] = NOT_THIS_TYPE_LOG_WEIGHT
        return log_prior


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
