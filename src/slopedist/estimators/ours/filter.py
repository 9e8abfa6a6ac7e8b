"""The Kalman filters of ``ours``: pure, vectorised functions on state arrays.

Distance filter, per track, state ``(ℓ, r)``: ``ℓ`` the log of the centre distance Z (m) and
``r = Ż/Z`` the relative rate (1/s), so ``−1/r`` is the time to collision of an approaching
target. Motion is constant velocity in Z with white-noise acceleration; ``Z' = Z + Ż·dt`` gives
``ℓ' = ℓ + log(1 + r·dt)`` and ``r' = r/(1 + r·dt)``. The measurement is the frame's fused
log-distance; only the part of its error that is independent from frame to frame (box-edge
pixel noise, the vanishing line's jitter) is filtered — the part that stays with a vehicle (its
size against the class prior, its road's gradient) cannot be averaged away and is added back to
the reported uncertainty.

Gradient filter, per track: the target's road gradient α (radians, relative to the ego
gradient) is a random walk.

Arrays broadcast over leading dimensions (targets).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

MIN_GROWTH = 0.2
"""Smallest growth factor ``1 + r·dt`` of a prediction: a target is never propagated through
the camera."""


@dataclass(frozen=True)
class ProcessNoise:
    """Process noise spectral densities.

    Attributes:
        accel_mps2: relative acceleration, m/s² per √s (white-noise acceleration).
        gradient_rad: random walk of a target's road gradient α, rad per √s.
    """

    accel_mps2: float = 2.0
    gradient_rad: float = float(np.radians(0.5))


def cv_predict_rows(s: FloatArray, dt_s: FloatArray, accel_mps2: float) -> FloatArray:
    """Propagate distance filters over ``dt_s`` seconds (constant velocity, white-noise
    acceleration of density ``accel_mps2``, m/s² per √s).

    ``s`` ``(5, m)``: the state rows ℓ, r, P_ℓℓ, P_ℓr, P_rr, one column per track; returns the
    predicted rows. The growth factor ``1 + r·dt`` is kept ≥ :data:`MIN_GROWTH`.
    """
    log_z, r, p00, p01, p11 = s
    dt = np.asarray(dt_s, dtype=float)
    grow = np.maximum(r * dt + 1.0, MIN_GROWTH)
    ig = 1.0 / grow
    f01 = dt * ig
    out = np.empty(s.shape)
    lp = log_z + np.log(grow)
    out[0] = lp
    out[1] = r * ig
    qdt = np.exp(lp * -2.0) * (accel_mps2 * accel_mps2) * dt
    a = p01 + f01 * p11
    ig2 = ig * ig
    out[2] = p00 + f01 * (p01 + a) + qdt * dt * dt * (1.0 / 3.0)
    out[3] = ig2 * a + qdt * dt * 0.5
    out[4] = ig2 * ig2 * p11 + qdt
    return out


def start_rows(log_z: FloatArray, var: FloatArray, rate_sigma_per_s: float) -> FloatArray:
    """State rows ``(5, n)`` (see :func:`cv_predict_rows`) of filters that start at the log
    distances ``log_z`` with variance ``var`` and zero rate (prior spread
    ``rate_sigma_per_s``, 1/s)."""
    s = np.zeros((5, log_z.shape[0]))
    s[0] = log_z
    s[2] = var
    s[4] = rate_sigma_per_s * rate_sigma_per_s
    return s


def cv_update_rows(s: FloatArray, y: FloatArray, r: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Update the state rows ``s`` (see :func:`cv_predict_rows`) with measurements ``y`` of ℓ
    of variance ``r``: the updated rows and the normalised innovation squared."""
    log_z, rate, p00, p01, p11 = s
    inv_S = 1.0 / (p00 + r)
    nu = y - log_z
    k0 = p00 * inv_S
    k1 = p01 * inv_S
    out = np.empty(s.shape)
    out[0] = log_z + k0 * nu
    out[1] = rate + k1 * nu
    out[2] = p00 - k0 * p00
    out[3] = p01 - k0 * p01
    out[4] = p11 - k1 * p01
    return out, nu * nu * inv_S


def random_walk_update(
    mean: FloatArray,
    var: FloatArray,
    dt_s: FloatArray | float,
    rate: float,
    obs: FloatArray,
    obs_var: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Predict a scalar random walk over ``dt_s`` then update it with ``obs`` (variance
    ``obs_var``); non-finite observations only predict."""
    v = var + rate * rate * np.asarray(dt_s, dtype=float) if rate else np.asarray(var)
    ok = np.isfinite(obs + obs_var)
    k = np.where(ok, v / np.where(ok, v + obs_var, 1.0), 0.0)
    return mean + k * np.where(ok, obs - mean, 0.0), (1.0 - k) * v


def distance_moments_rows(
    s: FloatArray, extra_log_var: FloatArray | float = 0.0
) -> tuple[FloatArray, FloatArray]:
    """Mean and standard deviation of ``Z = exp(ℓ)`` (log-normal, metres) of the state rows
    ``s`` (see :func:`cv_predict_rows`); ``extra_log_var`` adds variance of ℓ that the filter
    does not hold (the persistent part)."""
    s2 = np.maximum(s[2] + extra_log_var, 0.0)
    mean = np.exp(s[0] + s2 * 0.5)
    return mean, mean * np.sqrt(np.expm1(s2))


def motion_moments_rows(s: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Relative speed ``Ż = r·Z`` (m/s, negative when approaching) and its 1σ (first order),
    and the time to collision ``−Z/Ż = −1/r`` (s) and its 1σ (NaN unless the target
    approaches) of the state rows ``s`` (see :func:`cv_predict_rows`)."""
    log_z, r, p00, p01, p11 = s
    z = np.exp(log_z)
    speed = r * z
    var = speed * speed * p00 + (speed + speed) * z * p01 + z * z * p11
    speed_sd = np.sqrt(np.maximum(var, 0.0))
    away = r >= 0.0
    r_ = np.where(away, -1.0, r)
    ttc = np.where(away, np.nan, -1.0 / r_)
    ttc_sd = np.where(away, np.nan, np.sqrt(np.maximum(p11, 0.0)) / (r_ * r_))
    return speed, speed_sd, ttc, ttc_sd


def rts_smooth_rows(updated: FloatArray, predicted: FloatArray, dt_s: FloatArray) -> FloatArray:
    """Rauch–Tung–Striebel smoothing of one track's distance filter (offline use).

    ``updated`` ``(5, N)``: the filter's state rows after each of the track's N updates, in
    time order (as :func:`cv_update_rows` gives them); ``predicted`` ``(5, N)``: the rows
    predicted for each update from the one before (column 0 is not read); ``dt_s`` ``(N,)``:
    the time from the previous update (element 0 is not read). Returns the smoothed rows
    ``(5, N)``: each state given every measurement of the track, before and after. The
    transition's Jacobian is that of :func:`cv_predict_rows` at the updated state
    (``ℓ' = ℓ + log(1 + r·dt)``, ``r' = r/(1 + r·dt)``); the camera rotation's depth shift
    the filter added to ℓ is a constant and does not enter it.
    """
    out = np.array(updated, dtype=float)
    n = out.shape[1]
    for k in range(n - 2, -1, -1):
        log_z, r, p00, p01, p11 = updated[:, k]
        dt = float(dt_s[k + 1])
        ig = 1.0 / max(r * dt + 1.0, 0.2)
        F = np.array([[1.0, dt * ig], [0.0, ig * ig]])
        P = np.array([[p00, p01], [p01, p11]])
        xp = predicted[:2, k + 1]
        Pp = np.array(
            [[predicted[2, k + 1], predicted[3, k + 1]], [predicted[3, k + 1], predicted[4, k + 1]]]
        )
        C = P @ F.T @ np.linalg.inv(Pp)
        xs_next = out[:2, k + 1]
        Ps_next = np.array([[out[2, k + 1], out[3, k + 1]], [out[3, k + 1], out[4, k + 1]]])
        x = np.array([log_z, r]) + C @ (xs_next - xp)
        Ps = P + C @ (Ps_next - Pp) @ C.T
        out[:, k] = (x[0], x[1], Ps[0, 0], 0.5 * (Ps[0, 1] + Ps[1, 0]), Ps[1, 1])
    return out
