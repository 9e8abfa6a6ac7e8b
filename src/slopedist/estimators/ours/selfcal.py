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

The size cue is only as good as the class prior, so each target's box shape is checked against
its class first (``shape_gap``: the gap between its height and width cues at the heading that
explains it best, in σ of the class prior; :func:`~slopedist.estimators.ours.fusion.
shape_gap_sigma`): a box no vehicle of its class would give (a truck called ``Car``, a box of
part of a vehicle, two vehicles in one box) is left out, and the count of such boxes is kept
(:attr:`Calibration.n_shape_outliers`) so that a caller can tell a box source whose classes do
not describe its boxes.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import ConfigurationError
from slopedist.estimators.base import SelfCalibration as Calibration

_log = logging.getLogger(__name__)

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
        shape_gate_sigma: a target whose box shape is further than this from its class's
            (``shape_gap``, in σ) is left out (3, the usual outlier test, as ``ours``'
            ``consistency_gate_sigma``; not fitted).
        min_near_m, max_near_m: targets used (distance to the nearest face from the size cue).
    """

    mount_sigma_rad: float = math.radians(1.5)
    height_sigma_m: float = 0.2
    size_sigma_log: float = 0.09
    gradient_sigma_rad: float = math.radians(1.0)
    row_sigma_px: float = 4.0
    huber_k: float = 2.0
    shape_gate_sigma: float = 3.0
    min_near_m: float = 2.0
    max_near_m: float = 60.0

    def __post_init__(self) -> None:
        for name in (
            "mount_sigma_rad",
            "height_sigma_m",
            "size_sigma_log",
            "gradient_sigma_rad",
            "row_sigma_px",
            "huber_k",
            "shape_gate_sigma",
            "min_near_m",
            "max_near_m",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigurationError(
                    f"self-calibration {name} must be finite and > 0, got {value}"
                )


class SelfCalibrator:
    """Causal estimator of (θ0, h); feed it targets frame by frame with :meth:`update`.

    Args:
        f: focal length, pixels.
        mount_angle_rad: the configured θ0 (prior mean).
        height_m: the configured camera height (prior mean), metres.
        config: priors and noise levels.
    """

    def __init__(
        self, f: float, mount_angle_rad: float, height_m: float, config: SelfCalConfig | None = None
    ) -> None:
        self.f = float(f)
        self.config = config or SelfCalConfig()
        self.mount0 = float(mount_angle_rad)
        self.height0 = float(height_m)
        c = self.config
        self._prior_info = np.diag([1.0 / c.mount_sigma_rad**2, 1.0 / c.height_sigma_m**2])
        self._prior_mean = np.array([0.0, self.height0])
        self._omega_inv = np.diag([1.0 / c.size_sigma_log**2, 1.0 / c.gradient_sigma_rad**2])
        self.reset()

    def reset(self) -> None:
        """Forget every observation (new sequence)."""
        self._row_of: dict[int, int] = {}  # track key → row of the per-track sums
        # per track: Σ AᵀD⁻¹A, Σ AᵀD⁻¹U, Σ UᵀD⁻¹U (2×2 each), Σ AᵀD⁻¹y, Σ UᵀD⁻¹y (2 each) and
        # its current information matrix and vector (random effects marginalised)
        self._sums = np.zeros((0, _N_SUMS))
        self._info_tracks = np.zeros((2, 2))
        self._vec_tracks = np.zeros(2)
        self._n_obs = 0
        self._n_frames = 0
        self._n_shape_checked = 0
        self._n_shape_outliers = 0
        self._p = self._prior_mean.copy()
        self._cov = _inv2(self._prior_info)

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
        return Calibration(
            self.mount0 - float(self._p[0]),
            math.sqrt(self._cov[0, 0]),
            float(self._p[1]),
            math.sqrt(self._cov[1, 1]),
            float(self._p[0]),
            self._n_obs,
            len(self._row_of),
            self._n_shape_checked,
            self._n_shape_outliers,
            self._n_frames,
        )

    def track_jackknife(self) -> FloatArray:
        """2×2 covariance of (δ, h) from the spread of the leave-one-vehicle-out estimates.

        Each vehicle's contribution (its information matrix and vector, random effects
        marginalised) is taken out of the final normal equations in turn; the jackknife
        covariance ``(n − 1)/n · Σ (p₍ᵢ₎ − p̄)(p₍ᵢ₎ − p̄)ᵀ`` of those ``n`` solutions measures how
        much the estimate rests on vehicles that disagree with the others — beyond the
        model's own covariance when the vehicles scatter more than the random effects allow
        (not vehicles of the class prior, boxes of only part of a vehicle). Zeros with fewer
        than three vehicles.
        """
        n = len(self._row_of)
        if n < 3:
            return np.zeros((2, 2))
        sums = self._sums[:n]
        info = self._prior_info + self._info_tracks
        vec = self._prior_info @ self._prior_mean + self._vec_tracks
        without = _inv2(info[None] - sums[:, _INFO].reshape(-1, 2, 2))
        p = (without @ (vec[None] - sums[:, _VEC])[..., None])[..., 0]
        d = p - p.mean(axis=0)
        return (n - 1) / n * (d.T @ d)

    def update(
        self,
        track_keys: NDArray[np.int64],
        bottom_px: FloatArray,
        horizon_px: FloatArray,
        theta_rad: FloatArray,
        near_m: FloatArray,
        shape_gap: FloatArray | None = None,
    ) -> None:
        """Add one frame's targets and refresh the estimate.

        Args:
            track_keys: ``(N,)`` an id per vehicle (the same for all frames of one track).
            bottom_px: ``(N,)`` box bottom rows.
            horizon_px: ``(N,)`` eq. 5 rows of the configured ego gradient θ.
            theta_rad: ``(N,)`` that θ (for the ``1/cos²θ`` factor).
            near_m: ``(N,)`` size-cue distance to the nearest face, metres.
            shape_gap: ``(N,)`` how far each box's shape is from its class's, in σ (NaN:
                not checked); beyond ``shape_gate_sigma`` the target is left out and counted.
        """
        c = self.config
        self._n_frames += 1
        ok = (
            np.isfinite(bottom_px)
            & np.isfinite(horizon_px)
            & np.isfinite(near_m)
            & np.isfinite(theta_rad)
            & (near_m >= c.min_near_m)
            & (near_m <= c.max_near_m)
        )
        if shape_gap is not None:
            checked = ok & np.isfinite(shape_gap)
            outlier = checked & (shape_gap > c.shape_gate_sigma)
            self._n_shape_checked += int(np.count_nonzero(checked))
            self._n_shape_outliers += int(np.count_nonzero(outlier))
            ok &= ~outlier
        m = int(np.count_nonzero(ok))
        if not m:
            return
        f = self.f
        y = (bottom_px - horizon_px)[ok]
        a0 = -f / np.cos(theta_rad[ok]) ** 2
        a1 = f / near_m[ok]
        A = np.stack([a0, a1], axis=1)
        U = np.stack([a1 * self._p[1], np.full(m, -f)], axis=1)
        d = np.full(m, c.row_sigma_px**2)
        resid = y - A @ self._p
        total = np.sqrt(
            d + (U[:, 0] * c.size_sigma_log) ** 2 + (U[:, 1] * c.gradient_sigma_rad) ** 2
        )
        z = np.abs(resid) / total
        w = np.where(z > c.huber_k, c.huber_k / np.maximum(z, 1e-12), 1.0)
        inv_d = w / d
        Ad, Ud = A * inv_d[:, None], U * inv_d[:, None]
        add = np.concatenate(
            [
                (Ad[:, :, None] * A[:, None, :]).reshape(m, 4),
                (Ad[:, :, None] * U[:, None, :]).reshape(m, 4),
                (Ud[:, :, None] * U[:, None, :]).reshape(m, 4),
                Ad * y[:, None],
                Ud * y[:, None],
                np.zeros((m, 6)),
            ],
            axis=1,
        )
        rows = self._rows(np.asarray(track_keys)[ok].tolist())
        if len(set(rows.tolist())) == m:
            self._sums[rows, :_N_STATS] += add[:, :_N_STATS]
            rows_u = rows
        else:  # a key twice in one frame
            np.add.at(self._sums, rows, add)
            rows_u = np.unique(rows)
        sums = self._sums[rows_u]
        info, vec = self._track_info(sums)
        self._info_tracks += (info - sums[:, _INFO].reshape(-1, 2, 2)).sum(axis=0)
        self._vec_tracks += (vec - sums[:, _VEC]).sum(axis=0)
        sums[:, _INFO] = info.reshape(-1, 4)
        sums[:, _VEC] = vec
        self._sums[rows_u] = sums
        self._n_obs += m
        self._solve()

    def _rows(self, keys: list[int]) -> NDArray[np.intp]:
        """Rows of the per-track sums of these track keys (new keys get zeroed rows)."""
        row_of = self._row_of
        new = [k for k in dict.fromkeys(keys) if k not in row_of]
        if new:
            start = len(row_of)
            for i, k in enumerate(new):
                row_of[k] = start + i
            if start + len(new) > self._sums.shape[0]:  # grow by doubling
                grown = np.zeros((max(2 * self._sums.shape[0], start + len(new), 16), _N_SUMS))
                grown[:start] = self._sums[:start]
                self._sums = grown
        return np.array([row_of[k] for k in keys], dtype=np.intp)

    def _track_info(self, sums: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Information matrices ``(T, 2, 2)`` and vectors ``(T, 2)`` of tracks with their
        random effects marginalised: ``AA − AU·M·AUᵀ`` and ``Ay − AU·M·Uy`` with
        ``M = (Ω⁻¹ + UU)⁻¹``."""
        AA = sums[:, _AA].reshape(-1, 2, 2)
        AU = sums[:, _AU].reshape(-1, 2, 2)
        UU = sums[:, _UU].reshape(-1, 2, 2)
        M = _inv2(self._omega_inv + UU)
        AUM = AU @ M
        info = AA - AUM @ np.swapaxes(AU, -1, -2)
        vec = sums[:, _AY] - (AUM @ sums[:, _UY, None])[..., 0]
        return info, vec

    def _solve(self) -> None:
        info = self._prior_info + self._info_tracks
        vec = self._prior_info @ self._prior_mean + self._vec_tracks
        self._cov = _inv2(info)
        p = self._cov @ vec
        if np.all(np.isfinite(p)) and p[1] > 0:
            self._p = p


_AA, _AU, _UU, _AY, _UY = slice(0, 4), slice(4, 8), slice(8, 12), slice(12, 14), slice(14, 16)
_N_STATS = 16
"""Columns of the per-track sufficient statistics (then the track's information: 4 + 2)."""
_INFO, _VEC = slice(16, 20), slice(20, 22)
_N_SUMS = 22


def _inv2(M: FloatArray) -> FloatArray:
    """Inverse of 2×2 matrices ``(..., 2, 2)`` in closed form."""
    a, b, c, d = M[..., 0, 0], M[..., 0, 1], M[..., 1, 0], M[..., 1, 1]
    det = a * d - b * c
    out = np.empty(M.shape)
    out[..., 0, 0] = d / det
    out[..., 0, 1] = -b / det
    out[..., 1, 0] = -c / det
    out[..., 1, 1] = a / det
    return out


def self_calibrates(estimator: object) -> bool:
    """Whether ``estimator`` calibrates θ0 and h online (``ours-selfcal``: its experimental
    setting ``self_calibrate``)."""
    return bool(getattr(getattr(estimator, "ablation", None), "self_calibrate", False))


def uncalibrated_warning(name: str, calibration: Calibration) -> str | None:
    """The warning for a self-calibrating method ``name`` that never calibrated (None when it
    did): no frame had a measured rotation (θ), or none of theirs had a usable target; its
    records' ``calib_*`` columns then stay at the configured mount angle and height."""
    if calibration.n_observations:
        return None
    why = (
        "no frame had a measured rotation (θ; see the odometry states)"
        if calibration.n_frames == 0
        else f"none of the {calibration.n_frames} frames with a measured rotation had a usable "
        "target (a vehicle of a tightly sized class, near enough, not cut by the border)"
    )
    return (
        f"warning: {name} did not self-calibrate: {why}; the records' calib_* columns are the "
        "configured mount angle and height"
    )


def estimator_calibration_warning(estimator: object) -> str | None:
    """:func:`uncalibrated_warning` of ``estimator`` when it self-calibrates (at the end of a
    run or of an ``estimate``); None for any other method or one that calibrated."""
    calibration = getattr(estimator, "calibration", None)
    if not self_calibrates(estimator) or calibration is None:
        return None
    return uncalibrated_warning(str(getattr(estimator, "name", "ours-selfcal")), calibration())


def warn_if_uncalibrated(estimator: object) -> None:
    """Log :func:`estimator_calibration_warning` (a run's warnings go to the log, which
    ``batch`` keeps per drive)."""
    message = estimator_calibration_warning(estimator)
    if message is not None:
        _log.warning("%s", message)
