"""How far the drive's ground contacts are off, read from each track's cues as its distance
changes (experimental setting ``learn_contact_angle``).

A ground contact read under an angle error δ (the target's road climbing relative to the
ego's, or the mount) sees the box bottom ``f·δ`` rows off, so its inverse distance is off by a
constant: ``1/z_c = 1/z + δ/h`` (``z`` the distance to the contact point, ``h`` the camera
height). A size cue read under a size deviation ``b`` of the vehicle from its class is off by
a factor: ``1/z_s = (1 − b)/z``. Their difference over a track,

    ``y = 1/z_c − 1/z_s = δ/h + b·x``,  ``x = 1/z_s``,

is a line in ``x`` whose intercept is the angle error and whose slope is the size deviation:
at one distance the two look alike (the cue gaps cannot tell them apart), but over a track whose
distance changes they do not. Each track's least-squares intercept gives ``δ̂ = a·h`` with its
variance (from the track's own residuals, counted once per :data:`CORRELATION_TIME_S`, the
pitch mode's correlation); the drive's angle-error variance ``V`` is the posterior mean on a
grid, under ``δ̂ᵢ ~ N(0, V + sᵢ²)`` and a log-normal prior about the configured spread
(``gradient_sigma_rad² + mount_sigma_rad²``, log σ :data:`PRIOR_LOG_SIGMA`). The ratio of the
two, at most 1 (a size cue whose error changes with distance, e.g. a box that grows as its
vehicle nears, reads as an intercept too, so only a smaller spread is evidence), is the scale of
the contact's per-vehicle angle variances; the estimator uses the tighter contact only for a
target whose height cue agrees with it (:func:`~slopedist.estimators.ours.frame_cues.
consistent_contact`). A closed track's evidence fades over :data:`MEMORY_S`. Causal: a frame's
cues use the tracks as they were before it.

Metres, seconds, radians.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slopedist.estimators.ours.recent_share import CORRELATION_TIME_S

FloatArray = NDArray[np.float64]

MIN_FRAMES = 5
"""A track tells its intercept from this many frames on."""

MEMORY_S = 10.0
"""The closed tracks' evidence fades with this time constant, seconds: the road changes (a
crest or sag curve passes in about this time at urban speeds)."""

PRIOR_LOG_SIGMA = 1.0
"""Spread of the prior on log σ_δ about the configured spread (a factor e either way)."""

GRID_SIGMA_RAD = np.radians(np.geomspace(0.005, 4.0, 64))
"""The angle spreads σ_δ the posterior is evaluated on."""


class ContactAngleEvidence:
    """The drive's ground-contact angle errors from its tracks (see the module). Each track
    keeps its sums ``n, Σx, Σy, Σxx, Σxy, Σyy`` and its first and last time.

    Args:
        prior_sigma_rad: the configured spread of the contact's angle error
            (``√(gradient_sigma_rad² + mount_sigma_rad²)``).
        max_age_s: a track unseen for longer is closed (its evidence kept, its sums freed).
    """

    def __init__(self, prior_sigma_rad: float, max_age_s: float) -> None:
        self._v0 = prior_sigma_rad**2
        self._max_age_s = max_age_s
        v = GRID_SIGMA_RAD**2
        self._grid_v = v
        z = np.log(GRID_SIGMA_RAD / prior_sigma_rad) / PRIOR_LOG_SIGMA
        self._log_prior = -0.5 * z * z
        self.reset()

    def reset(self) -> None:
        """Forget the drive."""
        self._tracks: dict[int, FloatArray] = {}
        self._closed = np.zeros(self._grid_v.shape)
        self._closed_time_s = float("nan")
        self._scale = 1.0

    @property
    def scale(self) -> float:
        """The posterior mean of the angle-error variance over the configured one, at most 1."""
        return self._scale

    def add(
        self,
        uid: NDArray[np.int64],
        inv_size_m: FloatArray,
        inv_contact_m: FloatArray,
        time_s: float,
        cam_height_m: float,
    ) -> None:
        """A frame's targets: track uids, ``1/z_s`` and ``1/z_c`` of their contact points
        (1/m; NaN: not usable), then the drive's scale renewed."""
        ok = np.isfinite(inv_size_m) & np.isfinite(inv_contact_m)
        for k in np.flatnonzero(ok):
            key = int(uid[k])
            x, y = float(inv_size_m[k]), float(inv_contact_m[k] - inv_size_m[k])
            sums = self._tracks.get(key)
            if sums is None:
                sums = self._tracks[key] = np.array([0.0, 0, 0, 0, 0, 0, time_s, time_s])
            sums[:6] += (1.0, x, y, x * x, x * y, y * y)
            sums[7] = time_s
        if self._closed_time_s == self._closed_time_s:  # not NaN: fade since the last frame
            self._closed *= np.exp(-max(time_s - self._closed_time_s, 0.0) / MEMORY_S)
        self._closed_time_s = time_s
        self._close_stale(time_s, cam_height_m)
        self._renew(cam_height_m)

    def _close_stale(self, time_s: float, cam_height_m: float) -> None:
        stale = [k for k, v in self._tracks.items() if time_s - v[7] > self._max_age_s]
        if not stale:
            return
        rows = np.array([self._tracks.pop(k) for k in stale])
        self._closed += self._log_likelihood(rows, cam_height_m)

    def _renew(self, cam_height_m: float) -> None:
        log_post = self._log_prior + self._closed
        if self._tracks:
            rows = np.array(list(self._tracks.values()))
            log_post = log_post + self._log_likelihood(rows, cam_height_m)
        w = np.exp(log_post - log_post.max())
        # at most 1: a size cue whose error changes with distance (a box that grows as its
        # vehicle nears) reads as an intercept too, so a larger spread is no evidence against
        # the contact; a smaller one is
        self._scale = min(float(np.sum(w * self._grid_v) / np.sum(w) / self._v0), 1.0)

    def _log_likelihood(self, rows: FloatArray, cam_height_m: float) -> FloatArray:
        """Summed log-likelihood over the grid of the tracks ``rows`` (their sums)."""
        delta, var = track_intercepts(rows, cam_height_m)
        ok = np.isfinite(delta) & np.isfinite(var)
        if not ok.any():
            return np.zeros(self._grid_v.shape)
        total = self._grid_v[:, None] + var[ok][None, :]
        ll = -0.5 * (np.log(total) + delta[ok][None, :] ** 2 / total)
        return np.asarray(ll.sum(axis=1))


def track_intercepts(rows: FloatArray, cam_height_m: float) -> tuple[FloatArray, FloatArray]:
    """Each track's angle error ``δ̂ = a·h`` (rad) and its variance (rad²) from its sums
    ``rows`` ``(T, 8)`` (see :class:`ContactAngleEvidence`); NaN with fewer than
    :data:`MIN_FRAMES` frames or no spread of distance."""
    n, sx, sy, sxx, sxy, syy = (rows[:, i] for i in range(6))
    with np.errstate(divide="ignore", invalid="ignore"):
        mx, my = sx / n, sy / n
        cxx = sxx - n * mx * mx
        cxy = sxy - n * mx * my
        cyy = syy - n * my * my
        slope = cxy / cxx
        a = my - slope * mx
        resid = np.maximum(cyy - slope * cxy, 0.0) / (n - 2.0)
        duration = rows[:, 7] - rows[:, 6]
        n_eff = np.clip(duration / CORRELATION_TIME_S + 1.0, 1.0, n)
        var_a = resid * (1.0 / n + mx * mx / cxx) * (n / n_eff)
    bad = (n < MIN_FRAMES) | ~(cxx > 1e-9 * sxx)  # no spread of distance (to rounding)
    h = cam_height_m
    return np.where(bad, np.nan, a * h), np.where(bad, np.nan, var_a * h * h)
