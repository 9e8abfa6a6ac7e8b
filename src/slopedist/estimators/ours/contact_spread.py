"""How far the drive's ground contacts are off, read from all its targets at once, and how much
each target is trusted with the tighter contact (experimental setting ``learn_contact_spread``).

**The drive's contact spread.** A ground contact read under an angle error δ (the target's road
climbing relative to the ego's, the mount, the horizon's jitter) is off in inverse distance by
a constant, ``1/z_c = 1/z + δ/h`` (``h`` the camera height); a size cue read under a size
deviation ``b`` of the vehicle from its class by a factor, ``1/z_s ≈ (1 − b)/z``. Their gap in
angle units,

    ``a = h·(1/z_c − 1/z_s) ≈ δ + b·h/z``,

has the mean square ``E[a²] = V + S·x`` over the drive's targets, ``x = (h/z)²``: ``V`` the
contact's angle variance (rad²), ``S`` the size cues' relative variance. Near targets tell
``S``, far ones ``V``. The posterior geometric mean of ``V`` (``exp E[log V]``: a scale's
central value, which a long upper tail does not pull up) on a grid of ``(V, S)`` — a prior on ``S``
about the class's published height spread (log σ :data:`PRIOR_LOG_SIGMA_S`), a nearly flat one
on ``V`` (log σ :data:`PRIOR_LOG_SIGMA_V` about the configured spread, so that a flat road is
not held at the configured one) — over the configured contact variance, at most 1, is the scale
of the contact's angle variances (:attr:`ContactSpread.scale`). Each target's gaps count once
per :data:`CORRELATION_TIME_S` of its track; the evidence fades over :data:`MEMORY_S`.

**Two readings per target.** A drive's spread is an average: on a flat road with one hill a
target on the hill is off by far more. So each target is read twice, with the contact at the
drive's spread ("tight") and at the configured one ("wide"); the two are weighed by how well
each explains the target's cues (the marginal likelihood over its heading and size hypotheses)
and by the share of the drive's recent targets that the tight reading explained better
(:attr:`ContactSpread.tight_share`, an online EM estimate over :data:`SHARE_MEMORY_S`, in
[:data:`MIN_SHARE`, 1 − :data:`MIN_SHARE`]); the measurement is the mixture of the two
(:func:`mix_readings`), and so is its ground contact (what per-track size learning reads).
Causal: a frame's cues use the evidence of the frames before it.

Metres, seconds, radians; log distances ``ℓ = log(Z / 1 m)``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from slopedist.estimators.ours.fusion import LogCue
from slopedist.estimators.ours.recent_share import CORRELATION_TIME_S, RecentShare, fade
from slopedist.estimators.ours.records import FusedCues

FloatArray = NDArray[np.float64]

MEMORY_S = 2.0
"""The spread's evidence fades with this time constant, seconds (a crest or sag passes in a
few)."""

SHARE_MEMORY_S = 2.0
"""The tight reading's share fades with this time constant, seconds."""

MIN_SHARE = 0.05
"""Neither reading's share falls below this: each stays possible for every target."""

PRIOR_LOG_SIGMA_V = 3.0
"""Spread of the prior on log σ_δ about the configured contact spread (nearly flat)."""

PRIOR_LOG_SIGMA_S = 0.25
"""Spread of the prior on log σ_b about the class height's relative spread."""

GRID_SIGMA_DELTA_RAD = np.radians(np.geomspace(0.01, 4.0, 48))
"""The contact angle spreads σ_δ the posterior is evaluated on."""

GRID_SIGMA_SIZE = np.geomspace(0.01, 0.6, 32)
"""The size cues' relative spreads σ_b the posterior is evaluated on."""

X_EDGES = np.geomspace(1e-5, 1.0, 25)
"""Bin edges of ``x = (h/z)²`` (z from about 316 camera heights down to one)."""

_MAX_REMEMBERED_TRACKS = 1000
"""Beyond this many remembered tracks, those not seen for :data:`MEMORY_S` are forgotten."""


class ContactSpread:
    """The drive's contact angle variance from its targets' cue gaps, and the tight reading's
    share (see the module).

    Args:
        prior_sigma_rad: the configured spread of the contact's angle error (horizon jitter,
            target gradient and mount together).
        prior_size_sigma: the class prior's relative size spread (the car's height's).
    """

    def __init__(self, prior_sigma_rad: float, prior_size_sigma: float) -> None:
        self._v0 = prior_sigma_rad**2
        v, s = np.meshgrid(GRID_SIGMA_DELTA_RAD**2, GRID_SIGMA_SIZE**2, indexing="ij")
        self._grid_v, self._grid_s = v, s
        zv = np.log(GRID_SIGMA_DELTA_RAD / prior_sigma_rad) / PRIOR_LOG_SIGMA_V
        zs = np.log(GRID_SIGMA_SIZE / prior_size_sigma) / PRIOR_LOG_SIGMA_S
        self._log_prior = -0.5 * (zv[:, None] ** 2 + zs[None, :] ** 2)
        self.reset()

    def reset(self) -> None:
        """Forget the drive."""
        n_bins = X_EDGES.shape[0] - 1
        self._count = np.zeros(n_bins)
        self._sum_a2 = np.zeros(n_bins)
        self._sum_x = np.zeros(n_bins)
        self._last_seen_s: dict[int, float] = {}
        self._gap_time_s = math.nan
        self._scale = 1.0
        self._tight = RecentShare(0.5, 1.0, SHARE_MEMORY_S)

    @property
    def scale(self) -> float:
        """The posterior geometric mean of the contact's angle variance over the configured
        one, at most 1."""
        return self._scale

    @property
    def tight_share(self) -> float:
        """The share of the drive's recent targets the tight reading explained better: the
        running mean of their posterior weights, one pseudo-target at ½."""
        return float(np.clip(self._tight.share, MIN_SHARE, 1.0 - MIN_SHARE))

    def add_gaps(
        self, uid: NDArray[np.int64], gap_rad: FloatArray, x: FloatArray, time_s: float
    ) -> None:
        """A frame's targets: track uids, gaps ``a`` (rad; NaN: not usable) and ``x = (h/z)²``,
        then the scale renewed."""
        left = fade(time_s - self._gap_time_s, MEMORY_S)
        self._count *= left
        self._sum_a2 *= left
        self._sum_x *= left
        self._gap_time_s = time_s
        ok = np.isfinite(gap_rad) & np.isfinite(x) & (x > 0)
        weight = np.array([self._weight(int(u), time_s) for u in uid[ok].tolist()])
        if weight.size:
            b = np.clip(np.searchsorted(X_EDGES, x[ok]) - 1, 0, X_EDGES.shape[0] - 2)
            np.add.at(self._count, b, weight)
            np.add.at(self._sum_a2, b, weight * gap_rad[ok] ** 2)
            np.add.at(self._sum_x, b, weight * x[ok])
        self._renew()

    def add_posterior(self, tight_weight: FloatArray, time_s: float) -> None:
        """A frame's targets' posterior weights of the tight reading at ``time_s``
        (:meth:`~slopedist.estimators.ours.recent_share.RecentShare.add`)."""
        self._tight.add(tight_weight, time_s)

    def _weight(self, uid: int, time_s: float) -> float:
        """How much of an independent observation a track's gap of this frame is: the time
        since its previous frame over :data:`CORRELATION_TIME_S`, at most 1 (1 for a new
        track)."""
        last = self._last_seen_s.get(uid)
        self._last_seen_s[uid] = time_s
        if len(self._last_seen_s) > _MAX_REMEMBERED_TRACKS:  # forget the tracks long gone
            self._last_seen_s = {
                k: t for k, t in self._last_seen_s.items() if time_s - t < MEMORY_S
            }
        if last is None:
            return 1.0
        return float(np.clip((time_s - last) / CORRELATION_TIME_S, 0.0, 1.0))

    def _renew(self) -> None:
        used = self._count > 1e-9
        if not used.any():
            return
        n = self._count[used]
        x = self._sum_x[used] / n
        total = self._grid_v[..., None] + self._grid_s[..., None] * x
        log_post = self._log_prior - 0.5 * np.sum(
            n * np.log(total) + self._sum_a2[used] / total, axis=-1
        )
        w = np.exp(log_post - log_post.max())
        log_v = float(np.sum(w * np.log(self._grid_v)) / np.sum(w))
        self._scale = min(math.exp(log_v) / self._v0, 1.0)


def tight_weights(tight: FusedCues, wide: FusedCues, tight_share: float) -> FloatArray:
    """``(n,)`` each target's posterior weight of the tight reading: the marginal likelihoods
    of its cues over its hypotheses under each reading, with the prior ``tight_share``."""
    log_tight = np.logaddexp.reduce(tight.log_prior + tight.loglik, axis=1)
    log_wide = np.logaddexp.reduce(wide.log_prior + wide.loglik, axis=1)
    log_odds = log_tight - log_wide + math.log(tight_share / (1.0 - tight_share))
    return np.asarray(0.5 * (1.0 + np.tanh(0.5 * log_odds)))


def mix_readings(tight: FusedCues, wide: FusedCues, weight: FloatArray) -> FusedCues:
    """The tight reading with its measurement and its ground contact replaced by the mixtures
    of both readings' (``weight`` ``(n,)`` the tight one's; :func:`mix_cues`)."""
    ground = tight.ground
    if ground is not None and wide.ground is not None:
        ground = mix_cues(ground, wide.ground, weight)
    return tight._replace(
        measurement=mix_cues(tight.measurement, wide.measurement, weight), ground=ground
    )


def mix_cues(a: LogCue, b: LogCue, weight: FloatArray) -> LogCue:
    """The mixture of the cues ``a`` (weight ``weight``) and ``b``: its mean and variance, the
    weighted white variance and ``a``'s log-likelihood."""
    w = weight
    mean = w * a.mean + (1.0 - w) * b.mean
    spread = a.mean - b.mean
    var = w * a.var + (1.0 - w) * b.var + w * (1.0 - w) * spread * spread
    white = w * a.var_white + (1.0 - w) * b.var_white
    return LogCue(mean, var, white, a.loglik)
