"""Fusion of the log-distance cues of ``ours``: the size cues under the class prior, independent
cues by inverse variance, censoring by upper bounds, and mixtures over heading hypotheses.

Pure, vectorised functions (no state). A cue is a :class:`LogCue`: ``ℓ = log(Z / 1 m)`` with Z
a target's centre depth (camera z), its variance split into a white part (independent from frame
to frame) and a per-vehicle part. The last axis of a cue is the hypotheses' (heading × body-style
mode), leading axes the targets'.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special

if TYPE_CHECKING:
    from slopedist.estimators.ours.cues import SizeCue

FloatArray = NDArray[np.float64]

_HALF_LOG_2PI = 0.5 * float(np.log(2.0 * np.pi))
_INV_SQRT_2PI = 1.0 / float(np.sqrt(2.0 * np.pi))


class LogCue(NamedTuple):
    """A log-distance estimate ``ℓ = log Z`` with its error split in two.

    Attributes:
        mean: ℓ (Z in metres).
        var: total variance of ℓ.
        var_white: the part independent from frame to frame (pixel noise, horizon jitter);
            the rest (``var − var_white``) stays with a vehicle over its track.
        loglik: log-likelihood of the cues' mutual consistency (compares heading hypotheses;
            0 where a single cue was available).
    """

    mean: FloatArray
    var: FloatArray
    var_white: FloatArray
    loglik: FloatArray


def fuse_size_cues(
    height: SizeCue,
    width: SizeCue,
    sigma_log_h: FloatArray | float,
    sigma_log_w: FloatArray | float,
    corr_hw: FloatArray | float,
) -> LogCue:
    """Fuse the height and width cues (log distances) under the class size prior.

    ``y_h = ℓ − c_h·ηH + n_h`` and ``y_w = ℓ − c_w·ηW + n_w`` (``y`` the cue's mean, ``c`` its
    lever), with ``(ηH, ηW)`` the vehicle's log size deviations from its class (spreads
    ``sigma_log_h``, ``sigma_log_w``, correlation ``corr_hw``) and ``n`` measurement noise
    (white variances ``var_white`` plus other per-vehicle variances ``var_other``, e.g. from the
    length): the generalised least-squares estimate of ℓ. A non-finite width cue leaves the
    height cue alone.
    """
    r_h_white, r_w_white = height.var_white, width.var_white
    yh, yw = np.asarray(height.mean, dtype=float), np.asarray(width.mean, dtype=float)
    C11, C22, C12 = _size_covariance(height, width, sigma_log_h, sigma_log_w, corr_hw)
    # den > 0 unless both cues are exact (C is a covariance); a missing width gives NaN
    den = C11 + C22 - C12 - C12
    inv_den = 1.0 / den
    a_h = (C22 - C12) * inv_den
    a_w = (C11 - C12) * inv_den
    diff = yh - yw
    mean = yw + a_h * diff
    var = (C11 * C22 - C12 * C12) * inv_den
    white = a_h * a_h * r_h_white + a_w * a_w * r_w_white
    loglik = (diff * diff * inv_den + np.log(den)) * -0.5 - _HALF_LOG_2PI
    both = np.isfinite(den)
    return LogCue(
        np.where(both, mean, yh),
        np.where(both, var, C11),
        np.where(both, white, np.broadcast_to(r_h_white, np.shape(yh))),
        np.where(both, loglik, 0.0),
    )


def _size_covariance(
    height: SizeCue,
    width: SizeCue,
    sigma_log_h: FloatArray | float,
    sigma_log_w: FloatArray | float,
    corr_hw: FloatArray | float,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The covariance ``(C11, C22, C12)`` of the height and width cues' errors under the class
    size prior (:func:`fuse_size_cues`)."""
    sh = height.lever * np.asarray(sigma_log_h)
    sw = width.lever * np.asarray(sigma_log_w)
    C11 = sh * sh + height.var_white + height.var_other
    C22 = sw * sw + width.var_white + width.var_other
    return C11, C22, corr_hw * sh * sw


def size_cue_weights(
    cues: tuple[SizeCue, SizeCue], spreads: tuple[FloatArray, FloatArray], corr_hw: FloatArray
) -> FloatArray:
    """The height cue's weight ``a_h`` in :func:`fuse_size_cues` of the ``(height, width)``
    cues under the class spreads ``(sigma_log_h, sigma_log_w)`` (the width's weight is
    ``1 − a_h``; NaN where the width cue is missing, i.e. the height cue alone)."""
    C11, C22, C12 = _size_covariance(*cues, *spreads, corr_hw)
    return np.asarray((C22 - C12) / (C11 + C22 - C12 - C12))


class SizeMode(NamedTuple):
    """A mode of the size prior: how the class's relative size spreads widen in it.

    The typical vehicle of a class is the default mode. A body style of atypical height (a
    sports car, a pick-up, a box van labelled ``Car``) widens the height spread by
    ``height_factor``. An **odd object**, one whose size is not its class's at all (a concrete
    block or a covered trailer boxed as ``Car``, a truck partly hidden), has every dimension's
    relative spread at least ``log_sigma_floor``: its size cues then say little, and where they
    disagree with the ground contact the fusion follows the ground contact, instead of being
    pulled by a confident class size.

    Attributes:
        height_factor: multiplier of the class's relative height spread (1: the class's).
        log_sigma_floor: the smallest relative spread (of the logarithm) of the height and the
            width in this mode; 0: the class's (not an odd-object mode).
    """

    height_factor: float = 1.0
    log_sigma_floor: float = 0.0

    @property
    def odd(self) -> bool:
        """Whether this is the odd-object mode."""
        return self.log_sigma_floor > 0.0


class ModeSpreads:
    """How size modes widen a class's relative spreads, per hypothesis ``(n, M·K)`` (``M``
    modes, ``K`` columns each, mode-major).

    Args:
        modes: the size modes.
        n_columns: ``K``, the hypotheses per mode.

    Attributes:
        modes: the size modes.
        odd: index of the odd-object mode (:attr:`SizeMode.odd`), or None.
    """

    def __init__(self, modes: Sequence[SizeMode], n_columns: int) -> None:
        self.modes = tuple(modes)
        self.odd = next((k for k, mode in enumerate(self.modes) if mode.odd), None)
        self._height_factor = np.repeat([m.height_factor for m in self.modes], n_columns)
        self._floor = np.repeat([m.log_sigma_floor for m in self.modes], n_columns)

    def spreads(
        self, sigma_log_h: FloatArray, sigma_log_w: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """The class's relative height and width spreads in each size mode, per hypothesis:
        from ``sigma_log_h``, ``sigma_log_w`` ``(n, M·K)``, the class's repeated over the
        modes, the height's times its mode's factor, both at least its mode's floor."""
        return (
            np.maximum(sigma_log_h * self._height_factor, self._floor),
            np.maximum(sigma_log_w, self._floor),
        )


def shape_gap_sigma(
    height: SizeCue,
    width: SizeCue,
    sigma_log_h: FloatArray | float,
    sigma_log_w: FloatArray | float,
    corr_hw: FloatArray | float,
) -> FloatArray:
    """How far a box's shape is from its class's, in standard deviations: the gap between the
    height and the width cue ``|y_h − y_w| / √var(y_h − y_w)`` under the class size prior (as
    :func:`fuse_size_cues`), at the heading hypothesis that explains it best (the minimum over
    the last axis). A box of a vehicle of another type (a truck called ``Car``) or of part of
    one has a height and width no heading of the class gives together. ``(n,)``; NaN without
    a width cue.
    """
    sh = height.lever * np.asarray(sigma_log_h)
    sw = width.lever * np.asarray(sigma_log_w)
    c12 = np.asarray(corr_hw) * sh * sw
    den = (
        sh * sh
        + height.var_white
        + height.var_other
        + sw * sw
        + width.var_white
        + width.var_other
        - c12
        - c12
    )
    gap = np.abs(np.asarray(height.mean) - np.asarray(width.mean)) / np.sqrt(den)
    finite = np.isfinite(gap)
    return np.where(finite.any(axis=-1), np.min(np.where(finite, gap, np.inf), axis=-1), np.nan)


def fuse_log_cues(a: LogCue, b: LogCue) -> LogCue:
    """Inverse-variance fusion of two independent log-distance cues.

    The white variance is propagated with the same weights; ``loglik`` adds the consistency of
    the two cues to ``a``'s. Where ``b`` is missing (NaN) the result is ``a``.
    """
    ok = np.isfinite(b.mean + b.var) & (b.var > 0.0)
    vb = np.where(ok, b.var, 1.0)
    mb = np.where(ok, b.mean, 0.0)
    wb_white = np.where(ok, b.var_white, 0.0)
    tot = a.var + vb  # > 0: vb > 0 and a.var ≥ 0
    inv_tot = 1.0 / tot
    wa = vb * inv_tot
    wb = a.var * inv_tot
    diff = a.mean - mb
    mean = mb + wa * diff
    var = a.var * wa
    white = wa * wa * a.var_white + wb * wb * wb_white
    ll = (diff * diff * inv_tot + np.log(tot)) * -0.5 - _HALF_LOG_2PI
    return LogCue(
        np.where(ok, mean, a.mean),
        np.where(ok, var, a.var),
        np.where(ok, white, a.var_white),
        a.loglik + np.where(ok, ll, 0.0),
    )


def censor_upper(cue: LogCue, bound: ArrayLike, bound_var: ArrayLike, where: ArrayLike) -> LogCue:
    """Condition a log-distance cue on an upper bound ``ℓ ≤ bound`` known up to noise of
    variance ``bound_var`` (a censored measurement), where ``where`` is true and the bound finite.

    A box cut by the image border shows less than its vehicle: the size cue of a cut dimension
    says *at least this far*, so the vehicle is at most that far, and a box whose bottom is cut
    has its ground contact below the image, so at most as far as the cut row says. With the
    Gaussian ``cue`` ``N(μ, v)`` and the bound's likelihood ``Φ((bound − ℓ)/s)``, the posterior's
    moments are those of a truncated normal: with ``a = (bound − μ)/√(v + s²)`` and
    ``λ = φ(a)/Φ(a)``, ``μ' = μ − v·λ/√(v + s²)``, ``v' = v·(1 − v·λ(λ + a)/(v + s²))``; the
    white part shrinks in the same ratio and ``log Φ(a)`` is added to ``loglik`` (it weighs the
    heading hypotheses). A bound far above the estimate changes nothing.
    """
    mu, var = cue.mean, cue.var
    tot = var + np.asarray(bound_var, dtype=float)
    root = np.sqrt(tot)
    a = (np.asarray(bound, dtype=float) - mu) / root
    log_cdf = special.log_ndtr(a)
    lam = np.exp(-0.5 * a * a - log_cdf) * _INV_SQRT_2PI
    factor = 1.0 - var / tot * lam * (lam + a)
    use = np.asarray(where, dtype=bool) & np.isfinite(a)
    censored = (mu - var / root * lam, var * factor, cue.var_white * factor, cue.loglik + log_cdf)
    return LogCue(*(np.where(use, new, old) for new, old in zip(censored, cue, strict=True)))


def collapse_hypotheses(cue: LogCue, log_weight: ArrayLike) -> tuple[LogCue, FloatArray]:
    """Moment-match a mixture over the last axis (heading hypotheses) into one log cue.

    The spread of the hypotheses' means counts as per-vehicle variance. Returns the cue and the
    normalised weights.
    """
    lw = np.asarray(log_weight, dtype=float)
    w = np.exp(lw - np.maximum.reduce(lw, axis=-1, keepdims=True))
    w /= np.add.reduce(w, axis=-1, keepdims=True)
    return mix_hypotheses(cue, w), w


def mix_hypotheses(cue: LogCue, weight: FloatArray) -> LogCue:
    """:func:`collapse_hypotheses` with normalised weights (summing to 1 over the last axis)."""
    mean = np.add.reduce(weight * cue.mean, axis=-1)
    dev = cue.mean - mean[..., None]
    var = np.add.reduce(weight * (cue.var + dev * dev), axis=-1)
    white = np.add.reduce(weight * cue.var_white, axis=-1)
    return LogCue(mean, var, np.minimum(white, var), np.zeros(mean.shape))


def widen_to_mixture(cue: LogCue, mean_weight: FloatArray, weight: FloatArray) -> LogCue:
    """One log cue from hypotheses ``(..., K)``: the mean of the weights ``mean_weight``, the
    variance of the whole mixture ``weight`` about that mean (both normalised over the last
    axis): the other hypotheses widen the cue, they do not move it."""
    mean = np.add.reduce(mean_weight * cue.mean, axis=-1)
    dev = cue.mean - mean[..., None]
    var = np.add.reduce(weight * (cue.var + dev * dev), axis=-1)
    white = np.add.reduce(mean_weight * cue.var_white, axis=-1)
    return LogCue(mean, var, np.minimum(white, var), np.zeros(mean.shape))


def check_consistency(
    fused: LogCue, size: LogCue, ground: LogCue, gate_sigma: float
) -> tuple[LogCue, FloatArray]:
    """The cue consistency check: the gap between the size cue and the ground contact in
    standard deviations of their difference, ``(ℓ_size − ℓ_ground)/√(var_size + var_ground)``
    (NaN where the ground contact is missing), and the fused cue with its variance widened,
    where the gap exceeds ``gate_sigma``, to at least that of an even mixture of the two cues
    (``(var_size + var_ground)/2 + Δ²/4``): one of them is wrong and which one is unknown, so
    the track's σ says so and its gate keeps it. The mean is left as the fusion put it."""
    diff = size.mean - ground.mean
    total = size.var + ground.var
    with np.errstate(invalid="ignore", divide="ignore"):
        gap = diff / np.sqrt(total)
    apart = np.abs(gap) > gate_sigma  # False for NaN
    if not apart.any():
        return fused, gap
    mixture = 0.5 * total + 0.25 * diff * diff
    var = np.where(apart, np.maximum(fused.var, mixture), fused.var)
    return LogCue(fused.mean, var, fused.var_white, fused.loglik), gap


def inflate(cue: LogCue, mask: NDArray[np.bool_], factor: float) -> LogCue:
    """The cue with its variances multiplied by ``factor`` where ``mask``."""
    return LogCue(
        cue.mean,
        np.where(mask, cue.var * factor, cue.var),
        np.where(mask, cue.var_white * factor, cue.var_white),
        cue.loglik,
    )


def shrink_to_prior(
    mean: FloatArray, var: FloatArray, prior_sigma: float
) -> tuple[FloatArray, FloatArray]:
    """Combine an estimate (mean, var; var may be inf) with a zero-mean prior of spread
    ``prior_sigma``: the posterior mean and variance."""
    s2 = prior_sigma * prior_sigma
    finite = np.isfinite(var)
    v = np.where(finite, var, 1.0)
    return (np.where(finite, mean * s2 / (s2 + v), 0.0), np.where(finite, s2 * v / (s2 + v), s2))
