"""Online self-calibration of the camera's mount angle θ0 and height h from the targets.

Convention: radians, metres, pixels; the horizon of a frame is the eq. 5 row of the ego gradient
θ the pipeline computes with the *configured* θ0 (``θ ≈ −θ0 + pitch change``).

Every target whose size cue is usable gives one equation. Its box bottom ``b`` sits
``f·h/Z_n`` rows below the true horizon (``Z_n`` = distance to its nearest face, from the size cue
alone, which needs neither θ0 nor, to first order, h); the true horizon is the configured one
moved by ``f·δ/cos²θ`` rows up, ``δ`` being the error of the configured θ0 (true θ0 = configured θ0
− δ). So

    ``y = b − v_θ = −(f/cos²θ)·δ + (f/Z_n)·h + noise``

is linear in ``p = (δ, h)``. The noise has two parts that stay with a vehicle for its whole track
(random effects): its size differs from the class prior (``f·h/Z_n·ηH``, ηH ~ N(0, σ_η²)) and its
road climbs relative to the ego's (``−f·α``, α ~ N(0, σ_α²)); the rest (pixel noise, the ego
gradient's error) is independent per frame. The estimate is the generalised least-squares
solution with these per-track random effects (Woodbury identity, accumulated incrementally per
track) under a Gaussian prior centred on the configured calibration, with Huber weights against
outliers (a wrong class, a false detection). It is causal and converges as tracks accumulate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from slopedist.errors import ConfigurationError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SelfCalConfig:
    """Priors and noise levels of the self-calibration (radians, metres, pixels).

    Attributes:
        mount_sigma_rad: prior 1σ of the configured mount angle θ0.
        height_sigma_m: prior 1σ of the configured camera height.
        size_sigma_log: per-track spread of the size cue (log), the ηH random effect.
        gradient_sigma_rad: per-track spread of target road gradients, the α random effect.
        row_sigma_px: independent per-frame noise of ``b − v`` (pixels, box edge and ego pitch).
        huber_k: Huber threshold on standardised residuals.
        min_near_m, max_near_m: targets used (distance to the nearest face from the size cue).
    """

    mount_sigma_rad: float = math.radians(1.5)
    height_sigma_m: float = 0.2
    size_sigma_log: float = 0.09
    gradient_sigma_rad: float = math.radians(1.0)
    row_sigma_px: float = 4.0
    huber_k: float = 2.0
    min_near_m: float = 2.0
    max_near_m: float = 60.0

    def __post_init__(self) -> None:
        for name in ("mount_sigma_rad", "height_sigma_m", "size_sigma_log", "gradient_sigma_rad",
                     "row_sigma_px", "huber_k", "min_near_m", "max_near_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigurationError(f"self-calibration {name} must be finite and > 0, "
                                         f"got {value}")


@dataclass(frozen=True)
class Calibration:
    """A self-calibration result.

    Attributes:
        mount_angle_rad: estimated θ0 (radians, the camera's convention).
        mount_angle_sigma_rad: its 1σ.
        height_m: estimated camera height (m).
        height_sigma_m: its 1σ.
        horizon_offset_rad: δ, the correction added to the ego gradient θ (θ + δ).
        n_observations: targets used so far.
        n_tracks: vehicles (tracks) they came from.
    """

    mount_angle_rad: float
    mount_angle_sigma_rad: float
    height_m: float
    height_sigma_m: float
    horizon_offset_rad: float
    n_observations: int
    n_tracks: int


@dataclass
class _TrackSums:
    """Per-track sufficient statistics (A: design (·,2), U: random-effect loadings (·,2))."""

    AA: FloatArray = field(default_factory=lambda: np.zeros((2, 2)))
    AU: FloatArray = field(default_factory=lambda: np.zeros((2, 2)))
    UU: FloatArray = field(default_factory=lambda: np.zeros((2, 2)))
    Ay: FloatArray = field(default_factory=lambda: np.zeros(2))
    Uy: FloatArray = field(default_factory=lambda: np.zeros(2))
    n: int = 0


class SelfCalibrator:
    """Causal estimator of (θ0, h); feed it targets frame by frame with :meth:`update`.

    Args:
        f: focal length, pixels.
        mount_angle_rad: the configured θ0 (prior mean).
        height_m: the configured camera height (prior mean), metres.
        config: priors and noise levels.
    """

    def __init__(self, f: float, mount_angle_rad: float, height_m: float,
                 config: SelfCalConfig | None = None) -> None:
        self.f = float(f)
        self.config = config or SelfCalConfig()
        self.mount0 = float(mount_angle_rad)
        self.height0 = float(height_m)
        c = self.config
        self._prior_info = np.diag([1.0 / c.mount_sigma_rad ** 2, 1.0 / c.height_sigma_m ** 2])
        self._prior_mean = np.array([0.0, self.height0])
        self._omega_inv = np.diag([1.0 / c.size_sigma_log ** 2, 1.0 / c.gradient_sigma_rad ** 2])
        self.reset()

    def reset(self) -> None:
        """Forget every observation (new sequence)."""
        self._tracks: dict[int, _TrackSums] = {}
        self._info_tracks = np.zeros((2, 2))
        self._vec_tracks = np.zeros(2)
        self._n_obs = 0
        self._p = self._prior_mean.copy()
        self._cov = np.linalg.inv(self._prior_info)

    @property
    def horizon_offset_rad(self) -> float:
        """Current δ (add to the ego gradient θ)."""
        return float(self._p[0])

    @property
    def height_m(self) -> float:
        """Current camera height estimate, metres."""
        return float(self._p[1])

    @property
    def covariance(self) -> FloatArray:
        """2×2 covariance of (δ, h)."""
        return self._cov.copy()

    def calibration(self) -> Calibration:
        """The current estimate with its uncertainty."""
        sd = np.sqrt(np.diag(self._cov))
        return Calibration(self.mount0 - float(self._p[0]), float(sd[0]), float(self._p[1]),
                           float(sd[1]), float(self._p[0]), self._n_obs, len(self._tracks))

    def update(self, track_keys: NDArray[np.int64], bottom_px: FloatArray, horizon_px: FloatArray,
               theta_rad: FloatArray, near_m: FloatArray) -> None:
        """Add one frame's targets and refresh the estimate.

        Args:
            track_keys: ``(N,)`` an id per vehicle (the same for all frames of one track).
            bottom_px: ``(N,)`` box bottom rows.
            horizon_px: ``(N,)`` eq. 5 rows of the configured ego gradient θ.
            theta_rad: ``(N,)`` that θ (for the ``1/cos²θ`` factor).
            near_m: ``(N,)`` size-cue distance to the nearest face, metres.
        """
        c = self.config
        ok = (np.isfinite(bottom_px) & np.isfinite(horizon_px) & np.isfinite(near_m)
              & np.isfinite(theta_rad) & (near_m >= c.min_near_m) & (near_m <= c.max_near_m))
        if not np.any(ok):
            return
        f = self.f
        keys = np.asarray(track_keys)[ok]
        y = (bottom_px - horizon_px)[ok]
        a0 = -f / np.cos(theta_rad[ok]) ** 2
        a1 = f / near_m[ok]
        A = np.stack([a0, a1], axis=1)
        U = np.stack([a1 * self._p[1], np.full(a1.shape, -f)], axis=1)
        d = np.full(y.shape, c.row_sigma_px ** 2)
        resid = y - A @ self._p
        total = np.sqrt(d + (U[:, 0] * c.size_sigma_log) ** 2
                        + (U[:, 1] * c.gradient_sigma_rad) ** 2)
        z = np.abs(resid) / total
        w = np.where(z > c.huber_k, c.huber_k / np.maximum(z, 1e-12), 1.0)
        d = d / w
        for k in np.unique(keys):
            m = keys == k
            self._add_track_rows(int(k), A[m], U[m], y[m], d[m])
        self._n_obs += int(ok.sum())
        self._solve()

    def _add_track_rows(self, key: int, A: FloatArray, U: FloatArray, y: FloatArray,
                        d: FloatArray) -> None:
        sums = self._tracks.get(key)
        if sums is None:
            sums = self._tracks[key] = _TrackSums()
        else:
            info, vec = self._track_info(sums)
            self._info_tracks -= info
            self._vec_tracks -= vec
        inv_d = 1.0 / d
        sums.AA += (A * inv_d[:, None]).T @ A
        sums.AU += (A * inv_d[:, None]).T @ U
        sums.UU += (U * inv_d[:, None]).T @ U
        sums.Ay += (A * inv_d[:, None]).T @ y
        sums.Uy += (U * inv_d[:, None]).T @ y
        sums.n += len(y)
        info, vec = self._track_info(sums)
        self._info_tracks += info
        self._vec_tracks += vec

    def _track_info(self, s: _TrackSums) -> tuple[FloatArray, FloatArray]:
        """Information matrix and vector of one track with its random effects marginalised."""
        M = np.linalg.inv(self._omega_inv + s.UU)
        info = s.AA - s.AU @ M @ s.AU.T
        vec = s.Ay - s.AU @ M @ s.Uy
        return info, vec

    def _solve(self) -> None:
        info = self._prior_info + self._info_tracks
        vec = self._prior_info @ self._prior_mean + self._vec_tracks
        self._cov = np.asarray(np.linalg.inv(info), dtype=float)
        p = self._cov @ vec
        if np.all(np.isfinite(p)) and p[1] > 0:
            self._p = p
