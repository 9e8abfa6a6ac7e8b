"""Typed records passed between the per-frame steps of ``ours`` and its output columns.

Named tuples. Per-target arrays are ``(n,)``; per (target,
heading hypothesis) arrays are ``(n, K)``. Distances in metres (camera frame: x right, y down,
z forward; a target's distance is its centre's z), log distances ``ℓ = log(Z / 1 m)``, angles in
radians, image coordinates in pixels (rows grow downwards), times in seconds.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slopedist.estimators.ours.class_table import TargetClasses
from slopedist.estimators.ours.cues import SizeCue
from slopedist.estimators.ours.fusion import LogCue
from slopedist.estimators.ours.tracks import Tracks

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


class CalibrationInUse(NamedTuple):
    """The camera mount used for a frame.

    Attributes:
        horizon_offset_rad: offset δ added to the ego gradient θ (the self-calibrated mount
            angle minus the configured one; 0 when not self-calibrating).
        horizon_offset_sigma_rad: its uncertainty.
        height_m: camera height above the road.
        height_sigma_m: its uncertainty.
    """

    horizon_offset_rad: float
    horizon_offset_sigma_rad: float
    height_m: float
    height_sigma_m: float


class BorderCuts(NamedTuple):
    """Which boxes touch the image border, ``(n,)`` flags each."""

    sides: BoolArray
    top: BoolArray
    bottom: BoolArray


class FrameTargets(NamedTuple):
    """The usable boxes of a frame, with what every later step reads from them.

    Attributes:
        boxes_px: ``(n, 4)`` (left, top, right, bottom).
        track_ids: ``(n,)`` the boxes' track ids (−1: none).
        classes: their class constants.
        border_cuts: boxes touching the image border (None: no box does).
        box_sigma_px: box-edge noise used for this frame (before this frame's boxes refine it).
        time_s: the frame's timestamp.
    """

    boxes_px: FloatArray
    track_ids: IntArray
    classes: TargetClasses
    border_cuts: BorderCuts | None
    box_sigma_px: float
    time_s: float

    def edge_px(self, k: int) -> FloatArray:
        """``(n, 1)`` edge ``k`` (0 left, 1 top, 2 right, 3 bottom) of every box, a column
        that broadcasts over the hypotheses."""
        return self.boxes_px[:, k : k + 1]


class UpperBound(NamedTuple):
    """A censoring bound ``ℓ ≤ log_bound`` (noise variance ``var``) where ``rows`` (n, 1)."""

    log_bound: FloatArray
    var: FloatArray
    rows: BoolArray


class SizeCues(NamedTuple):
    """The two size cues per hypothesis, the upper bounds of cues cut by the border and
    ``hidden`` ``(n,)``: the boxes a nearer box may cut (None: not checked)."""

    height: SizeCue
    width: SizeCue
    bounds: list[UpperBound]
    hidden: BoolArray | None = None


class TrackMatch(NamedTuple):
    """This frame's boxes matched to the live tracks.

    Attributes:
        rows: ``(n,)`` column of the track each box continues, −1 for a new track.
        continued: ``(n,)`` ``rows >= 0``.
        continued_rows: ``rows[continued]``.
        before: those ``m`` tracks as they were before this frame (a copy).
        elapsed_s: ``(m,)`` time since those tracks' last update.
        gradient_var_rad2: ``(m,)`` their gradient variance predicted to now (random walk).
        turned_boxes_px: ``(T, 4)`` every track's last box turned with the camera (pixels).
        depth_ratio: ``(T,)`` the camera rotation's depth ratio per track, or None when only
            the continued tracks' are needed (computed later).
        box_motion: whether the tracks' box motion is updated (id-less boxes or the box-noise
            estimate need it).
    """

    rows: IntArray
    continued: BoolArray
    continued_rows: IntArray
    before: Tracks
    elapsed_s: FloatArray
    gradient_var_rad2: FloatArray
    turned_boxes_px: FloatArray
    depth_ratio: FloatArray | None
    box_motion: bool


class FusedCues(NamedTuple):
    """The cues fused and collapsed over the hypotheses.

    Attributes:
        measurement: ``(n,)`` the log distance measured this frame (all cues).
        size: ``(n,)`` the size cues alone.
        loglik: ``(n, K·modes)`` the hypotheses' cue-consistency log-likelihood.
        log_prior: ``(n, K·modes)`` their log prior.
        heading_weights: ``(n, K)`` posterior weight of each heading hypothesis.
        half_extent_m: ``(n,)`` posterior mean half depth extent (centre to nearest face).
        width_log: ``(n,)`` the width cue's log centre distance, mixed over the headings by
            their posterior weights (NaN without the width cue).
        cue_gap_sigma: ``(n,)`` the size cues' log distance minus the ground contact's, in
            standard deviations of their difference (NaN without the ground contact): beyond
            ``consistency_gate_sigma`` the cues disagree and the measurement's variance is
            widened to cover both.
        ground: ``(n,)`` the ground contact alone, mixed over the hypotheses (None without
            it).
        odd_size_prob: ``(n,)`` posterior probability of the odd-object size mode (0 without
            it): the target's size is not its class's.
        camera_lever: ``(n,)`` ``∂ℓ/∂h'`` of ``measurement`` (1/m), the camera height above
            the target's road through the height cue, mixed over the hypotheses (None: not
            computed; :mod:`~slopedist.estimators.ours.road_bend`).
    """

    measurement: LogCue
    size: LogCue
    loglik: FloatArray
    log_prior: FloatArray
    heading_weights: FloatArray
    half_extent_m: FloatArray
    width_log: FloatArray
    cue_gap_sigma: FloatArray
    ground: LogCue | None = None
    odd_size_prob: FloatArray | None = None
    camera_lever: FloatArray | None = None


class DistanceFilterResult(NamedTuple):
    """The distance filters after this frame.

    Attributes:
        filter_rows: ``(5, n)`` state rows (ℓ, Ż/Z, P_ℓℓ, P_ℓr, P_rr) of every target.
        rows: ``(n,)`` track column each box continues, −1 where it starts a track (the
            association's, minus the boxes that failed the gate).
        continued: ``(n,)`` whether the box continued its track's filter.
        predicted_rows: ``(5, n)`` the rows predicted for this frame from each continued
            track's last update (NaN where a track starts), when the estimator keeps them
            (offline smoothing), else None.
        noise_scale: ``(n,)`` each track's measurement-noise scale after this frame (1 where
            a track starts), or None when it is not estimated.
    """

    filter_rows: FloatArray
    rows: IntArray
    continued: BoolArray
    predicted_rows: FloatArray | None = None
    noise_scale: FloatArray | None = None


class FrameState(NamedTuple):
    """A frame's targets with their tracks, cues and distance filters: what the steps after
    the distance filter read.

    Attributes:
        targets: the usable boxes and their class constants.
        match: their tracks.
        size_cues: the size cues per hypothesis.
        fused: the cues fused and collapsed over the hypotheses.
        distance: the distance filters after this frame.
    """

    targets: FrameTargets
    match: TrackMatch
    size_cues: SizeCues
    fused: FusedCues
    distance: DistanceFilterResult


class TargetGradient(NamedTuple):
    """Each target's road gradient α relative to the ego's, from Δy and the size distance.

    Attributes:
        track_mean_rad, track_var_rad2: the track's random-walk estimate (before the prior).
        obs_var_other_rad2: per-vehicle variance of this frame's observation.
        gradient_rad, gradient_var_rad2: the estimate combined with the prior (reported).
        delta_y_px: box centre row minus the ego's horizon row.
        size_distance_m: the size cues' distance used.
    """

    track_mean_rad: FloatArray
    track_var_rad2: FloatArray
    obs_var_other_rad2: FloatArray
    gradient_rad: FloatArray
    gradient_var_rad2: FloatArray
    delta_y_px: FloatArray
    size_distance_m: FloatArray
