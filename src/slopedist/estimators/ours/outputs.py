"""What ``ours`` reports for each box: the columns of its records, from the filters and cues
of a frame (:func:`box_estimates`), placed among the frame's boxes (:func:`scatter`).

Distances in metres (to the vehicle's centre unless moved to another reference point), angles in
radians, image rows in pixels, speeds in m/s, times in seconds.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.estimators.base import FrameEstimates, ReferencePoint
from slopedist.estimators.ours import cues, road_bend
from slopedist.estimators.ours import filter as kf
from slopedist.estimators.ours.records import (
    CalibrationInUse,
    DistanceFilterResult,
    FrameTargets,
    FusedCues,
    TargetGradient,
)

FloatArray = NDArray[np.float64]


EXTRA_COLUMNS = (
    "sigma_m",
    "distance_centre_m",
    "distance_nearest_face_m",
    "speed_mps",
    "speed_sigma_mps",
    "ttc_s",
    "ttc_sigma_s",
    "target_gradient_rad",
    "target_gradient_sigma_rad",
    "yaw_rad",
    "distance_size_m",
    "distance_ground_contact_m",
    "distance_width_m",
    "cue_gap_sigma",
    "odd_size_prob",
    "size_scale",
    "size_log_sigma",
    "track_height_m",
    "track_uid",
    "calib_mount_angle_rad",
    "calib_mount_angle_sigma_rad",
    "calib_height_m",
    "calib_height_sigma_m",
)
"""Method-specific columns of ``ours`` (all float; NaN where not defined)."""


class BoxEstimates(NamedTuple):
    """Outputs of the usable boxes of a frame (see :data:`EXTRA_COLUMNS` for the extras; the
    self-calibration columns are added by the caller)."""

    distance_m: FloatArray
    theta_adj_rad: FloatArray
    v_px: FloatArray
    delta_y_px: FloatArray
    sigma_m: FloatArray
    distance_nearest_face_m: FloatArray
    speed_mps: FloatArray
    speed_sigma_mps: FloatArray
    ttc_s: FloatArray
    ttc_sigma_s: FloatArray
    target_gradient_rad: FloatArray
    target_gradient_sigma_rad: FloatArray
    yaw_rad: FloatArray
    distance_size_m: FloatArray
    distance_ground_contact_m: FloatArray
    distance_width_m: FloatArray
    cue_gap_sigma: FloatArray
    track_uid: FloatArray
    odd_size_prob: FloatArray | None = None
    size_scale: FloatArray | None = None
    size_log_sigma: FloatArray | None = None
    track_height_m: FloatArray | None = None


OUTPUT_KEYS = ("distance_m", "theta_adj_rad", "v_px", "delta_y_px", *EXTRA_COLUMNS)
"""Every per-box output column of :meth:`OursEstimator.estimate`."""


def scatter(values: dict[str, FloatArray], rows: NDArray[np.intp], n: int) -> dict[str, FloatArray]:
    """Per-box outputs of length ``n`` for every :data:`OUTPUT_KEYS`: ``values`` (of the boxes
    ``rows``) placed in NaN-filled columns; keys without values stay NaN."""
    out = {k: np.full(n, np.nan) for k in OUTPUT_KEYS}
    for k, v in values.items():
        out[k][rows] = v
    return out


def box_estimates(
    cam: Camera,
    yaw_grid_rad: FloatArray,
    targets: FrameTargets,
    fused: FusedCues,
    distance: DistanceFilterResult,
    gradient: TargetGradient,
    uid: NDArray[np.int64],
    theta_rad: float,
    calib: CalibrationInUse,
    gradient_sigma_rad: float = 0.0,
) -> BoxEstimates:
    """The outputs: the filtered centre distance with its σ and motion, the target gradient,
    the most likely heading (of the grid ``yaw_grid_rad``) and the two cues' own distances.
    With ``fused.camera_lever``, σ adds the camera height above the target's road
    (:func:`~slopedist.estimators.ours.road_bend.road_bend_log_var`, prior spread
    ``gradient_sigma_rad``)."""
    f = cam.f
    filt = distance.filter_rows
    meas = fused.measurement
    persistent = meas.var - meas.var_white
    dist, sigma = kf.distance_moments_rows(filt, persistent)
    sigma_only = road_bend.sigma_only_log_var(targets, fused, gradient, gradient_sigma_rad)
    if sigma_only is not None:  # the distance stays the class's own: its σ only widens
        sigma = kf.distance_moments_rows(filt, persistent + sigma_only)[1]
    speed, speed_sd, ttc, ttc_sd = _motion_outputs(filt, distance.continued)
    if distance.noise_scale is not None:  # the noise the track shows, when it is larger
        widen = np.sqrt(np.maximum(distance.noise_scale, 1.0))
        speed_sd, ttc_sd = speed_sd * widen, ttc_sd * widen
    v_frame = cam.c_y - f * math.tan(theta_rad)
    theta_adj = theta_rad + gradient.gradient_rad  # the target's road: θ + α
    ground = cues.ground_contact_cue(
        targets.boxes_px[:, 3], v_frame, f, calib.height_m, fused.half_extent_m
    )
    return BoxEstimates(
        distance_m=dist,
        theta_adj_rad=theta_adj,
        v_px=cam.c_y - f * np.tan(theta_adj),
        delta_y_px=gradient.delta_y_px,
        sigma_m=sigma,
        distance_nearest_face_m=dist - fused.half_extent_m,
        speed_mps=speed,
        speed_sigma_mps=speed_sd,
        ttc_s=ttc,
        ttc_sigma_s=ttc_sd,
        target_gradient_rad=gradient.gradient_rad,
        target_gradient_sigma_rad=np.sqrt(gradient.gradient_var_rad2),
        yaw_rad=yaw_grid_rad[fused.heading_weights.argmax(axis=1)],
        distance_size_m=gradient.size_distance_m,
        distance_ground_contact_m=ground,
        distance_width_m=np.exp(fused.width_log),
        cue_gap_sigma=fused.cue_gap_sigma,
        track_uid=uid.astype(float),
        odd_size_prob=fused.odd_size_prob,
    )


def _motion_outputs(
    filt: FloatArray, continued: NDArray[np.bool_]
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Speed (m/s), its σ, time to collision (s) and its σ; NaN for a track's first frame."""
    speed, speed_sd, ttc, ttc_sd = (
        np.where(continued, a, np.nan) for a in kf.motion_moments_rows(filt)
    )
    return speed, speed_sd, ttc, ttc_sd


def frame_estimates(
    values: dict[str, FloatArray],
    good: NDArray[np.intp],
    n: int,
    theta_rad: float,
    reasons: NDArray[np.object_],
    reference: ReferencePoint,
) -> FrameEstimates:
    """A frame's estimates of its ``n`` boxes: ``values`` (:data:`OUTPUT_KEYS` columns of the
    usable boxes ``good``; NaN for the others), the frame's ego gradient ``theta_rad`` and the
    boxes' ``reasons``; the statuses follow from the reasons."""
    out = scatter(values, good, n)
    return FrameEstimates(
        theta_rad=np.full(n, float(theta_rad)),
        theta_adj_rad=out["theta_adj_rad"],
        delta_y_px=out["delta_y_px"],
        v_px=out["v_px"],
        distance_m=out["distance_m"],
        reason=reasons,
        reference=np.full(n, reference.value, dtype=object),
        extra={k: out[k] for k in EXTRA_COLUMNS},
        cut=np.full(n, "", dtype=object),
    )


def move_to_reference(
    est: FrameEstimates, reference: ReferencePoint, half_extent_m: FloatArray
) -> None:
    """Keep the centre distances in ``distance_centre_m`` and move ``distance_m`` to the
    ``reference`` point (in place): the nearest face, or its foot, is ``half_extent_m`` nearer
    than the centre."""
    est.extra["distance_centre_m"] = est.distance_m.copy()
    if reference is not ReferencePoint.CENTRE:
        est.distance_m -= half_extent_m
