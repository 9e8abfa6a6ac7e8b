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

IDX_LOG_Z, IDX_RATE = 0, 1


@dataclass(frozen=True)
class ProcessNoise:
    """Process noise spectral densities.

    Attributes:
        accel_mps2: relative acceleration, m/s² per √s (white-noise acceleration).
        gradient_rad: random walk of a target's road gradient α, rad per √s.
    """

    accel_mps2: float = 2.0
    gradient_rad: float = float(np.radians(0.5))


def cv_predict(
    x: FloatArray, P: FloatArray, dt_s: FloatArray, accel_mps2: float
) -> tuple[FloatArray, FloatArray]:
    """Propagate ``(..., 2)`` states and ``(..., 2, 2)`` covariances over ``dt_s`` seconds.

    The growth factor ``1 + r·dt`` is kept ≥ 0.2 so a target is never propagated through the
    camera.
    """
    x = np.array(x, dtype=float, copy=True)
    dt = np.asarray(dt_s, dtype=float)
    grow = np.maximum(1.0 + x[..., IDX_RATE] * dt, 0.2)
    f01 = dt / grow
    f11 = 1.0 / (grow * grow)
    x[..., IDX_LOG_Z] += np.log(grow)
    x[..., IDX_RATE] /= grow
    p00, p01, p11 = P[..., 0, 0], P[..., 0, 1], P[..., 1, 1]
    q = accel_mps2 ** 2 * np.exp(-2.0 * x[..., IDX_LOG_Z])
    dt2 = dt * dt
    out = np.empty(P.shape)
    out[..., 0, 0] = p00 + 2 * f01 * p01 + f01 * f01 * p11 + q * (dt2 * dt) / 3
    out[..., 0, 1] = out[..., 1, 0] = f11 * (p01 + f01 * p11) + q * dt2 / 2
    out[..., 1, 1] = f11 * f11 * p11 + q * dt
    return x, out


def cv_update(
    x: FloatArray, P: FloatArray, y: FloatArray, r: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Update ``(ℓ, r)`` with a measurement ``y`` of ℓ of variance ``r``.

    Returns the new state, covariance and the normalised innovation squared.
    """
    p00, p01, p11 = P[..., 0, 0], P[..., 0, 1], P[..., 1, 1]
    S = p00 + r
    nu = y - x[..., IDX_LOG_Z]
    k0, k1 = p00 / S, p01 / S  # the gain (P is symmetric)
    x_new = np.empty(x.shape)
    x_new[..., IDX_LOG_Z] = x[..., IDX_LOG_Z] + k0 * nu
    x_new[..., IDX_RATE] = x[..., IDX_RATE] + k1 * nu
    P_new = np.empty(P.shape)
    P_new[..., 0, 0] = p00 - k0 * p00
    P_new[..., 0, 1] = P_new[..., 1, 0] = p01 - k0 * p01
    P_new[..., 1, 1] = p11 - k1 * p01
    return x_new, P_new, nu * nu / S


def random_walk_update(
    mean: FloatArray, var: FloatArray, dt_s: FloatArray | float, rate: float, obs: FloatArray,
    obs_var: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Predict a scalar random walk over ``dt_s`` then update it with ``obs`` (variance
    ``obs_var``); non-finite observations only predict."""
    v = var + rate * rate * np.asarray(dt_s, dtype=float) if rate else np.asarray(var)
    ok = np.isfinite(obs + obs_var)
    if np.count_nonzero(ok) == ok.size:
        k = v / (v + obs_var)
        return mean + k * (obs - mean), (1.0 - k) * v
    k = np.where(ok, v / np.where(ok, v + obs_var, 1.0), 0.0)
    return mean + k * np.where(ok, obs - mean, 0.0), (1.0 - k) * v


def distance_moments(
    x: FloatArray, P: FloatArray, extra_log_var: FloatArray | float = 0.0
) -> tuple[FloatArray, FloatArray]:
    """Mean and standard deviation of ``Z = exp(ℓ)`` (log-normal), metres.

    ``extra_log_var`` adds variance of ℓ that the filter does not hold (the persistent part).
    """
    s2 = np.maximum(P[..., 0, 0] + extra_log_var, 0.0)
    mean = np.exp(x[..., IDX_LOG_Z] + 0.5 * s2)
    return mean, mean * np.sqrt(np.expm1(s2))


def speed_moments(x: FloatArray, P: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Relative speed ``Ż = r·Z`` (m/s, negative when approaching) and its 1σ (first order)."""
    z = np.exp(x[..., IDX_LOG_Z])
    r = x[..., IDX_RATE]
    j_l, j_r = r * z, z
    var = j_l * j_l * P[..., 0, 0] + 2 * j_l * j_r * P[..., 0, 1] + j_r * j_r * P[..., 1, 1]
    return r * z, np.sqrt(np.maximum(var, 0.0))


def ttc_moments(x: FloatArray, P: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Time to collision ``−Z/Ż = −1/r`` (s) and its 1σ; NaN unless the target approaches."""
    r = x[..., IDX_RATE]
    approaching = r < 0
    r_ = np.where(approaching, r, -1.0)
    sigma = np.sqrt(np.maximum(P[..., 1, 1], 0.0)) / (r_ * r_)
    return np.where(approaching, -1.0 / r_, np.nan), np.where(approaching, sigma, np.nan)
