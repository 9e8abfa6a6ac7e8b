"""σ of the height cue's camera height above the target's road (``road_bend_sigma``).

The height cue (:func:`~slopedist.estimators.ours.cues.height_cue`) sees the roof of a vehicle
whose roof is below the camera: how much of it depends on the camera's height ``h'`` above the
*target's* road plane, which the cue takes as ``h``, the height over the ego's road. That holds
when the target's road is the chord from the road under the camera to the target's contact point,
whose gradient relative to the ego's is the target gradient ``α̂`` the estimator measures from the
box's offset below the horizon (:func:`~slopedist.estimators.ours.cues.target_gradient`). A road
that bends in between (the foot of a hill, a crest) gives the target its own gradient ``α``:
``h' − h = Z_n·(tan α − tan α̂)`` (``Z_n`` the distance to the contact point). Under the gradient
prior ``α ~ N(0, σ_g²)`` the ground contact already uses, ``α − α̂`` has the second moment
``α̂² + var(α̂) + σ_g²``: small on a planar road, as large as the target's measured climb on a
hill. The variance this adds to the fused log distance is
``(w·a_h·∂ℓ_h/∂h)²·Z_n²·(α̂² + var(α̂) + σ_g²)`` (``a_h`` the height cue's share of the size
fusion, ``w`` the size cues' share of the fused distance); it widens ``sigma_m`` only, the
distance stays the fusion's.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slopedist.estimators.ours import vehicle_types
from slopedist.estimators.ours.fusion import LogCue, size_cue_weights
from slopedist.estimators.ours.records import FrameTargets, FusedCues, SizeCues, TargetGradient

FloatArray = NDArray[np.float64]


def fused_camera_lever(
    size: SizeCues,
    spreads: tuple[FloatArray, FloatArray],
    corr_hw: FloatArray,
    size_cue: LogCue,
    ground: LogCue | None,
    height_lever: FloatArray | None,
) -> FloatArray | None:
    """``∂ℓ/∂h'`` of the fused log distance per hypothesis: the height cue's lever times its
    share of the size fusion and the size cues' share of the fused distance (1 without a finite
    ground contact); None without ``height_lever``."""
    if height_lever is None:
        return None
    lever = size_cue_weights((size.height, size.width), spreads, corr_hw) * height_lever
    lever = np.where(np.isnan(lever), height_lever, lever)  # NaN: the height cue alone
    if ground is None:
        return np.asarray(lever)
    w = 1.0 / (1.0 + size_cue.var / ground.var)  # 1 where the ground contact's variance is inf
    w = np.where(np.isnan(w), 1.0, w)  # NaN: no ground contact
    return np.asarray(w * lever)


def road_bend_log_var(
    lever: FloatArray,
    distance_m: FloatArray,
    half_extent_m: FloatArray,
    gradient_rad: FloatArray,
    gradient_var_rad2: FloatArray,
    gradient_sigma_rad: float,
) -> FloatArray:
    """``(n,)`` variance (log distance²) of the camera height above the target's road: ``lever``
    (``∂ℓ/∂h'``, 1/m) times ``Z_n·σ(α − α̂)`` with ``Z_n`` the centre distance less the half
    extent (m) and the target gradient ``α̂`` with its variance (rad, rad²)."""
    near = np.maximum(distance_m - half_extent_m, 0.0)
    spread2 = gradient_rad * gradient_rad + gradient_var_rad2 + gradient_sigma_rad**2
    return np.asarray((lever * near) ** 2 * spread2)


def sigma_only_log_var(
    targets: FrameTargets, fused: FusedCues, gradient: TargetGradient, gradient_sigma_rad: float
) -> FloatArray | None:
    """``(n,)`` what widens σ only (log distance²; None: nothing): a generic class's size types
    (:func:`~slopedist.estimators.ours.vehicle_types.sigma_log_var`) and, with
    ``fused.camera_lever``, the camera height above the target's road
    (:func:`road_bend_log_var`, at the frame's measured
    distance, prior spread ``gradient_sigma_rad``)."""
    sigma_only = vehicle_types.sigma_log_var(targets.classes.type_moments, fused)
    if fused.camera_lever is None:
        return sigma_only
    bend = road_bend_log_var(
        fused.camera_lever,
        np.exp(fused.measurement.mean),
        fused.half_extent_m,
        gradient.track_mean_rad,
        gradient.track_var_rad2 + gradient.obs_var_other_rad2,
        gradient_sigma_rad,
    )
    return bend if sigma_only is None else sigma_only + bend
