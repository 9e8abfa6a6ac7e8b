"""Per-track size learning of ``ours``: a vehicle's own dimensions, learned over its track.

A class prior says how big a vehicle of the class usually is; a given vehicle is bigger or
smaller by a factor it keeps for its whole track (a van that a class-blind detector calls
``Car`` by some 40 %). Each track therefore carries the log of that factor, ``b = log(size /
class prior)`` (one isotropic scale of height, width and length, dimensionless), with its
variance: the class prior's ``N(0, σ_H²)`` (``σ_H`` the class height's relative spread) until
the track has evidence.

Evidence comes from the frames where the ground contact is reliable: the size cue, computed
with the dimensions ``prior · exp(b̂)``, says ``ℓ_s = ℓ + b̂ − b`` and the ground contact
``ℓ_g = ℓ + noise``, so ``b̂ + ℓ_g − ℓ_s`` observes ``b`` with the variance of the ground
contact (which grows as the distance squared, and holds the target road's gradient spread: near
and on the ego's plane it is tight, far or on a hill it is loose) plus the size cue's white
noise. Consecutive frames share the target road's gradient error, so a frame's evidence is
tempered by ``min(1, dt/τ)`` (τ = ``size_evidence_time_s``: one independent observation per τ
seconds). Frames whose box is cut by the image border give no evidence (cues that disagree
beyond the consistency check do: a van called ``Car`` is such a disagreement); a box that a
nearer box may cut shows at most its vehicle, so its frame counts only when it says the vehicle
is bigger than believed. The learned size then carries the distance where the ground contact
cannot (far away, on hills).

The learned scale multiplies every dimension of the track's hypotheses and its variance
replaces the class spread (each dimension's relative spread is scaled by ``√v / σ_H``).

Pure functions of arrays; per-target arrays are ``(n,)``, per (target, hypothesis) ``(n, K)``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slopedist.estimators.ours.class_table import MIN_NEAR_M, HypothesisConstants
from slopedist.estimators.ours.fusion import LogCue
from slopedist.estimators.ours.records import FrameState, FrameTargets, TrackMatch

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


class TrackSize(NamedTuple):
    """Each target's size belief before this frame.

    Attributes:
        log_scale: ``(n,)`` b̂, log of the track's dimensions over its class prior's.
        log_var: ``(n,)`` its variance (the class prior's, ``σ_H²``, for a new track).
        prior_log_var: ``(n,)`` the class prior's variance ``σ_H²``.
    """

    log_scale: FloatArray
    log_var: FloatArray
    prior_log_var: FloatArray

    @property
    def spread_ratio(self) -> FloatArray:
        """``(n,)`` how much of the class spread is left: ``√(v / σ_H²)``."""
        return np.sqrt(self.log_var / self.prior_log_var)


def track_size(
    stored: FloatArray | None,
    continued: BoolArray,
    prior_log_sigma: FloatArray,
) -> TrackSize:
    """The size belief of a frame's targets: the stored rows ``(2, m)`` (log scale, its
    variance; NaN variance = the prior) of the ``m`` continued targets ``continued`` ``(n,)``,
    the class prior (``prior_log_sigma`` ``(n,)``, relative height spread) elsewhere."""
    prior_var = prior_log_sigma * prior_log_sigma
    log_scale = np.zeros(continued.shape[0])
    log_var = prior_var.copy()
    if stored is not None and stored.shape[1]:
        known = np.isfinite(stored[1])
        idx = np.flatnonzero(continued)[known]
        log_scale[idx] = stored[0, known]
        log_var[idx] = stored[1, known]
    return TrackSize(log_scale, log_var, prior_var)


def scale_hypotheses(hyp: HypothesisConstants, size: TrackSize) -> HypothesisConstants:
    """The hypotheses' dimensions scaled by each target's learned size ``exp(b̂)``, with the
    class spreads narrowed to what is left of them (:attr:`TrackSize.spread_ratio`)."""
    s = np.exp(size.log_scale)[:, None]
    rho = size.spread_ratio[:, None]
    s_rho = s * rho
    e = hyp.half_extent_m * s
    return HypothesisConstants(
        half_extent_m=e,
        half_extent_var_m2=hyp.half_extent_var_m2 * (s_rho * s_rho),
        half_extent_sigma_m=hyp.half_extent_sigma_m * s_rho,
        min_centre_depth_m=e + MIN_NEAR_M,
        height_m=hyp.height_m * s,
        log_sigma_height=hyp.log_sigma_height * rho,
        log_sigma_width=hyp.log_sigma_width * rho,
        log_sigma_length=hyp.log_sigma_length * rho,
        corr_height_width=hyp.corr_height_width,
        half_width_cos_m=hyp.half_width_cos_m * s,
        half_width_sin_m=hyp.half_width_sin_m * s,
        half_length_cos_m=hyp.half_length_cos_m * s,
        half_length_sin_m=hyp.half_length_sin_m * s,
    )


def evidence_weight(elapsed_s: FloatArray, continued: BoolArray, time_s: float) -> FloatArray:
    """``(n,)`` weight of this frame's evidence, ``min(1, dt/τ)`` with ``dt`` the time since
    the track's last update (``elapsed_s`` ``(m,)``, of the continued targets); 0 for a
    target that starts a track (its first frame's gradient error is shared with the next)."""
    w = np.minimum(np.maximum(elapsed_s, 0.0) / time_s, 1.0)
    out = np.zeros(continued.shape[0])
    out[continued] = w
    return out


def learn(
    size: TrackSize,
    size_cue: LogCue,
    ground: LogCue,
    weight: FloatArray,
    usable: BoolArray,
    hidden: BoolArray | None = None,
) -> FloatArray:
    """The size belief after this frame, rows ``(2, n)`` (log scale, its variance).

    ``size_cue``: the size cues' log distance (computed with the learned size); ``ground``:
    the ground contact's; ``weight``: the evidence weight (:func:`evidence_weight`);
    ``usable``: the targets whose frame may teach (box uncut by the border);
    ``hidden``: the targets whose box a nearer box may cut: such a box shows at most its
    vehicle, so its evidence is a lower bound of the size and counts only where it says
    bigger than believed.
    """
    obs = size.log_scale + ground.mean - size_cue.mean
    obs_var = ground.var + size_cue.var_white
    ok = usable & np.isfinite(obs) & np.isfinite(obs_var) & (weight > 0)
    if hidden is not None:
        ok &= ~hidden | (obs > size.log_scale)
    info = np.where(ok, weight / np.where(ok, obs_var, 1.0), 0.0)
    prec = 1.0 / size.log_var
    var = 1.0 / (prec + info)
    mean = var * (prec * size.log_scale + info * np.where(ok, obs, 0.0))
    return np.stack([mean, var])


def with_track_size(targets: FrameTargets, size: TrackSize) -> FrameTargets:
    """``targets`` with their class constants scaled by their tracks' learned sizes."""
    classes = targets.classes
    hyp = scale_hypotheses(classes.hypotheses, size)
    return targets._replace(classes=classes._replace(hypotheses=hyp))


def learn_frame(frame: FrameState, size: TrackSize, evidence_time_s: float) -> FloatArray:
    """``(2, n)`` each target's size belief after this frame (:func:`learn`): this frame's
    evidence where its box is not cut by the image border (where a nearer box may cut it,
    only evidence that it is bigger), weighed by :func:`evidence_weight`; a target whose track
    failed the distance gate starts from the class prior again."""
    targets, match, size_cues, fused, distance = frame
    usable = np.ones(targets.boxes_px.shape[0], dtype=bool)
    cuts = targets.border_cuts
    if cuts is not None:
        usable &= ~(cuts.sides | cuts.top | cuts.bottom)
    weight = evidence_weight(match.elapsed_s, match.continued, evidence_time_s)
    restarted = match.continued & ~distance.continued
    if restarted.any():
        weight[restarted] = 0.0
        size = size._replace(
            log_scale=np.where(restarted, 0.0, size.log_scale),
            log_var=np.where(restarted, size.prior_log_var, size.log_var),
        )
    if fused.ground is None:
        return np.stack([size.log_scale, size.log_var])
    return learn(size, fused.size, fused.ground, weight, usable, size_cues.hidden)


def size_columns(rows: FloatArray, class_height_m: FloatArray) -> dict[str, FloatArray]:
    """The record columns of the size beliefs ``rows`` ``(2, n)``: ``size_scale`` (the
    track's dimensions over its class prior's), ``size_log_sigma`` (1σ of its log) and
    ``track_height_m`` (the class height times the scale, m)."""
    scale = np.exp(rows[0])
    return {
        "size_scale": scale,
        "size_log_sigma": np.sqrt(rows[1]),
        "track_height_m": class_height_m * scale,
    }


class LearnedSizes:
    """Each track's own size, learned over its track (the estimator's ``size_learning``).

    Args:
        evidence_time_s: τ, the time over which a track's ground-contact evidence about its
            size is one independent observation, seconds (:func:`evidence_weight`).
    """

    def __init__(self, evidence_time_s: float) -> None:
        self.evidence_time_s = evidence_time_s

    def before_frame(self, targets: FrameTargets, match: TrackMatch) -> TrackSize:
        """Each target's size belief before this frame: its track's, else the class prior."""
        stored = match.before.size_rows if match.continued_rows.size else None
        return track_size(stored, match.continued, targets.classes.height_log_sigma)

    def after_frame(self, frame: FrameState, size: TrackSize) -> FloatArray:
        """``(2, n)`` each target's size belief after ``frame`` (:func:`learn_frame`), from its
        belief ``size`` before it."""
        return learn_frame(frame, size, self.evidence_time_s)
