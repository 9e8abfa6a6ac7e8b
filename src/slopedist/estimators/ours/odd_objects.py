"""The per-track check of ``ours`` that a target's size is its class's: the odd-object mode's
evidence, carried over the track.

A class's size prior has a rare **odd-object** mode (:class:`~slopedist.estimators.ours.fusion.
SizeMode`, option ``odd_object_weight``): a concrete block, a covered trailer or a partly hidden
truck boxed as ``Car`` has a size no vehicle of its class has, so its size cues say little and
the fusion follows the ground contact. One frame weighs the mode by how well each mode explains
the disagreement of its cues (the hypotheses' log-likelihood); a vehicle keeps its size over
its track, so the track also carries the evidence of its past frames: the log-likelihood ratio
``λ = log p(cues | odd) − log p(cues | not odd)`` of each frame (read from the mode's posterior
and prior odds), summed with the weight
``min(1, dt/τ)`` (:func:`~slopedist.estimators.ours.size_learning.evidence_weight`: consecutive
frames share the target road's gradient error, so only one frame per τ seconds is independent
evidence; τ the size-learning time, 4 s from the gradient priors). That sum is added to the
odd mode's log prior in the next frame; that log prior is the drive's share of odd boxes so far
(:class:`OddShare`), the configured weight before its first target.

Pure functions of arrays; per-target arrays are ``(n,)``, per-hypothesis ones ``(n, M·K)``
(``M`` size modes × ``K`` headings, mode-major). Log-likelihoods are natural logarithms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slopedist.estimators.ours.config import (
    OursAblation,
    OursConfig,
    carries_state,
    size_evidence_time,
)
from slopedist.estimators.ours.recent_share import RecentShare
from slopedist.estimators.ours.records import DistanceFilterResult, FrameTargets, TrackMatch
from slopedist.estimators.ours.size_learning import evidence_weight

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def carried_evidence(match: TrackMatch) -> FloatArray:
    """``(n,)`` each target's odd-object evidence from its track's past frames (0 for a target
    that starts a track)."""
    evidence = np.zeros(match.rows.shape[0])
    if match.continued_rows.size:
        evidence[match.continued] = match.before.odd_evidence
    return evidence


def with_evidence(
    log_prior: FloatArray, evidence: FloatArray, odd_mode: int, n_headings: int
) -> FloatArray:
    """The hypotheses' log prior ``(n, M·K)`` with each target's track evidence added to the
    odd mode's ``K`` columns (the odds of the modes, not normalised: the posterior weights
    are)."""
    out = np.array(log_prior, dtype=float)
    block = slice(odd_mode * n_headings, (odd_mode + 1) * n_headings)
    out[:, block] += evidence[:, None]
    return out


def frame_log_ratio(odd_prob: FloatArray, prior_log_odds: FloatArray) -> FloatArray:
    """``(n,)`` this frame's log-likelihood ratio of the odd mode over the others: the log
    odds of its posterior probability ``odd_prob`` minus those of its prior (the mode's prior
    plus the track's evidence, ``prior_log_odds``), Bayes' rule read backwards. The posterior
    log odds are taken at most :data:`MAX_LOG_ODDS` (a probability of 1 in float64)."""
    # within (0, 1) so that both logarithms are finite (a sum of weights may round to 1 or
    # above, or underflow to 0); NaN (no weights) stays NaN
    p = np.minimum(np.maximum(odd_prob, 1e-300), 1.0 - 2.0**-53)
    log_odds = np.log(p) - np.log1p(-p)
    return np.minimum(np.maximum(log_odds, -MAX_LOG_ODDS), MAX_LOG_ODDS) - prior_log_odds


MAX_LOG_ODDS = 36.0
"""Largest posterior log odds read from a probability (1 − 2⁻⁵³ has log odds 36.7)."""

MAX_EVIDENCE = 20.0
"""Bound of a track's evidence (nats, either sign): well inside the log odds a probability
resolves, so a frame can always be read back (:func:`frame_log_ratio`), and a long track can
still change its mind within a few τ when its cues change (a vehicle no longer hidden)."""


def updated_evidence(
    evidence: FloatArray,
    log_ratio: FloatArray,
    weight: FloatArray,
    restarted: BoolArray | None,
) -> FloatArray:
    """``(n,)`` the track evidence after this frame: ``evidence + weight·log_ratio`` within
    ±:data:`MAX_EVIDENCE` (a non-finite ratio adds nothing); a target whose track failed the
    distance gate (``restarted``; None: none did) starts afresh from 0."""
    add = weight * log_ratio
    total = np.minimum(np.maximum(evidence + add, -MAX_EVIDENCE), MAX_EVIDENCE)
    ok = np.isfinite(add)
    if restarted is None:
        return np.where(ok, total, evidence)
    ok &= ~restarted
    return np.where(ok, total, np.where(restarted, 0.0, evidence))


def of_class_priors(
    odd_prob: FloatArray | None, sized: NDArray[np.bool_] | None
) -> FloatArray | None:
    """``(n,)`` the odd-object posterior ``odd_prob`` of the targets read with their class
    prior, NaN for those whose size the detector gives (``sized``; None: none): a measured size
    has no odd-object mode (:meth:`~slopedist.estimators.ours.hypotheses.Hypotheses.log_prior`),
    so such a frame is no evidence of one for its track nor for the drive's share."""
    if odd_prob is None or sized is None:
        return odd_prob
    return np.where(sized, np.nan, odd_prob)


@dataclass(frozen=True)
class OddObjectCheck:
    """The per-track odd-object check of an estimator's options (:meth:`of`); it does
    nothing when ``odd_mode`` is None.

    Attributes:
        odd_mode: index of the odd-object mode among the size modes (None: no check, as
            without an odd-object mode or without tracks).
        n_headings: ``K``, the heading hypotheses per mode.
        prior_log_odds: the odd mode's prior log odds against the other modes.
        evidence_time_s: τ, seconds (one independent frame per τ).
    """

    odd_mode: int | None
    n_headings: int
    prior_log_odds: float
    evidence_time_s: float

    @classmethod
    def of(cls, config: OursConfig, ablation: OursAblation, n_headings: int) -> OddObjectCheck:
        """The check of an estimator's options."""
        modes = ablation.size_modes
        odd = next((k for k, (mode, _) in enumerate(modes) if mode.odd), None)
        weight = modes[odd][1] if odd is not None else 0.5
        log_odds = float(np.log(weight) - np.log1p(-weight))
        return cls(
            odd if carries_state(config, ablation) else None,
            n_headings,
            log_odds,
            size_evidence_time(config, ablation),
        )

    def carried(self, match: TrackMatch, targets: FrameTargets) -> FloatArray | None:
        """:func:`carried_evidence`; None without a check or when the frame's classes are
        read as generic (vehicle types instead of size modes)."""
        if self.odd_mode is None or targets.classes.type_log_weight is not None:
            return None
        return carried_evidence(match)

    def prior(
        self, log_prior: FloatArray, evidence: FloatArray | None, offset: float = 0.0
    ) -> FloatArray:
        """:func:`with_evidence` (``log_prior`` itself without evidence); ``offset``: the
        drive's learned log odds over the configured ones (:class:`OddShare`)."""
        if evidence is None or self.odd_mode is None:
            return log_prior
        return with_evidence(log_prior, evidence + offset, self.odd_mode, self.n_headings)

    def after_frame(
        self,
        evidence: FloatArray | None,
        odd_prob: FloatArray | None,
        match: TrackMatch,
        distance: DistanceFilterResult,
        offset: float = 0.0,
    ) -> FloatArray | None:
        """``(n,)`` the tracks' evidence after this frame (None without ``evidence``): its
        log-likelihood ratio (:func:`frame_log_ratio` of the odd mode's posterior probability
        ``odd_prob`` and its prior with ``evidence``) weighed by ``min(1, dt/τ)``; a track
        that failed the distance gate starts afresh."""
        if evidence is None or odd_prob is None:
            return None
        weight = evidence_weight(match.elapsed_s, match.continued, self.evidence_time_s)
        ratio = frame_log_ratio(odd_prob, self.prior_log_odds + offset + evidence)
        restarted = match.continued & ~distance.continued
        return updated_evidence(evidence, ratio, weight, restarted)


class OddShare:
    """The drive's share of odd-object boxes, learned online (``learn_odd_share``, on by
    default).

    The odd mode's prior weight (``odd_object_weight``) is the share of boxes whose size is not
    their class's. That share is the box source's as much as the traffic's: a box source that
    fits vehicles loosely (LiDAR clusters, a class-blind detector's van called ``car``) has
    many. The drive's share is the running mean posterior odd probability of its recent
    targets (:class:`~slopedist.estimators.ours.recent_share.RecentShare`: :data:`PRIOR_COUNT`
    pseudo-observations of the configured weight, fading over :data:`MEMORY_S`), at most
    :data:`MAX_SHARE`. It is causal: a frame's prior is the share of the frames before it.
    """

    def __init__(self, prior_log_odds: float) -> None:
        """``prior_log_odds``: the configured weight's log odds (:attr:`OddObjectCheck.
        prior_log_odds`)."""
        self._log_odds0 = prior_log_odds
        self._odd = RecentShare(1.0 / (1.0 + math.exp(-prior_log_odds)), PRIOR_COUNT, MEMORY_S)

    def reset(self) -> None:
        """Forget the drive."""
        self._odd.reset()

    @property
    def share(self) -> float:
        """The drive's odd share so far (at most :data:`MAX_SHARE`)."""
        return min(self._odd.share, MAX_SHARE)

    @property
    def log_odds_offset(self) -> float:
        """The learned share's log odds minus the configured weight's (nats)."""
        s = self.share
        return math.log(s) - math.log1p(-s) - self._log_odds0

    def update(self, odd_prob: FloatArray, time_s: float) -> None:
        """Add a frame's targets' posterior odd probabilities ``(n,)`` (NaN: no size cue) at
        ``time_s`` (s)."""
        self._odd.add(odd_prob[np.isfinite(odd_prob)], time_s)


PRIOR_COUNT = 60.0
"""Weight of the configured share, in target observations (about 30 s of two targets)."""

MEMORY_S = 10.0
"""The share's evidence fades with this time constant, seconds."""

MAX_SHARE = 0.5
"""The share stays below this: a box's size stays more often its class's than not."""
