"""``ours-offline``: ``ours`` over a whole drive at once, for log analysis (not causal).

When the whole drive is available, each vehicle's distance at a frame may use what its track
shows later as well as earlier. :class:`OursOfflineEstimator` runs in two passes over the
frames it was given:

1. **Learning** (while the frames stream in): ``ours`` with per-track size learning
   (:mod:`~slopedist.estimators.ours.size_learning`), causal; its estimates are what
   :meth:`~OursOfflineEstimator.estimate` returns frame by frame. A track's size belief at its
   last frame holds the evidence of all its frames (the size is constant over a track, so
   filtering to the end is smoothing).
2. **Smoothing** (:meth:`~OursOfflineEstimator.finish`): ``ours`` again, every box's size
   cues computed with the final size belief of its pass-1 track (:class:`FinalSizes`: no
   further learning), its filter states kept (:class:`FilterLog`), then a Rauch–Tung–Striebel
   backward pass over each track's distance filter
   (:func:`~slopedist.estimators.ours.filter.rts_smooth_rows`).

Its figures are reported under its own name (``ours-offline``), never mixed with the causal
``ours``: the causal estimator is untouched by this module. The records' ``sigma_m`` is the
smoothed filter's uncertainty plus the per-vehicle part the filter cannot average away.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.estimators.base import EstimateStatus, FrameEstimates, FrameInput
from slopedist.estimators.ours import filter as kf
from slopedist.estimators.ours import road_bend
from slopedist.estimators.ours.config import OursAblation, OursConfig, size_evidence_time
from slopedist.estimators.ours.estimator import OursEstimator
from slopedist.estimators.ours.records import FrameState, FrameTargets, TargetGradient, TrackMatch
from slopedist.estimators.ours.size_learning import LearnedSizes, TrackSize

FloatArray = NDArray[np.float64]

MOTION_COLUMNS = ("speed_mps", "speed_sigma_mps", "ttc_s", "ttc_sigma_s")

BoxKey = tuple[float, ...]
"""A box of the drive: its frame's timestamp and its edges (s, px)."""


def _box_keys(t: float, boxes: FloatArray) -> list[BoxKey]:
    return [(t, *map(float, b)) for b in boxes]


class OursOfflineEstimator(OursEstimator):
    """``ours`` smoothed over the whole drive (see the module docstring).

    :meth:`estimate` gives the causal pass's estimates as the frames come; the offline ones
    come from :meth:`finish`, once the drive has ended (pipelines call it:
    :meth:`~slopedist.streaming.step.FrameStep.finish`). Options as :class:`OursEstimator`'s
    (``size_learning`` is always on here).
    """

    name: ClassVar[str] = "ours-offline"
    offline: ClassVar[bool] = True

    def __init__(
        self,
        camera: Camera,
        config: OursConfig | None = None,
        ablation: OursAblation | None = None,
        **overrides: Any,
    ) -> None:
        overrides["size_learning"] = True
        super().__init__(camera, config, ablation, **overrides)

    def reset(self) -> None:
        super().reset()
        self._frames: list[FrameInput] = []
        self._causal: list[FloatArray] = []
        """Of each frame the pass-1 columns the second pass needs, ``(3, n)``: track uid, size
        scale, its log σ (the rest of the estimates, some 40 columns, is not kept)."""

    def estimate(self, frame: FrameInput) -> FrameEstimates:
        est = super().estimate(frame)
        # the second pass needs the boxes, times and rotations, not the pixels: a drive's
        # images (or depth maps) held to its end would not fit in memory
        self._frames.append(dataclasses.replace(frame, image=None, depth_m=None))
        extra = est.extra
        self._causal.append(
            np.stack([extra["track_uid"], extra["size_scale"], extra["size_log_sigma"]])
        )
        return est

    def finish(self) -> list[FrameEstimates]:
        """The offline estimates of every frame given since :meth:`reset`, in order."""
        evidence_time = size_evidence_time(self.config, self.ablation)
        sizes = FinalSizes(_final_sizes(self._frames, self._causal), evidence_time)
        log = FilterLog(self.config.gradient_sigma_rad)
        second = OursEstimator(self.camera, self.config, self.ablation, sizes=sizes, recorder=log)
        estimates = []
        for frame in self._frames:
            log.start_frame()
            estimates.append(second.estimate(frame))
        return log.smoothed(estimates)


def _final_sizes(frames: list[FrameInput], causal: list[FloatArray]) -> dict[BoxKey, FloatArray]:
    """Every box's pass-1 track's size belief at its last frame, ``(2,)`` (log scale, its
    variance), keyed by the box; boxes without one (unusable) are left out. ``causal``: each
    frame's pass-1 track uid, size scale and its log σ, ``(3, n)``."""
    final: dict[float, FloatArray] = {}
    rows: list[tuple[BoxKey, float]] = []
    for frame, (uid, scale, log_sigma) in zip(frames, causal, strict=True):
        log_scale = np.log(scale)
        log_var = log_sigma**2
        keys = _box_keys(frame.timestamp_s, frame.boxes.boxes)
        for i in np.flatnonzero(np.isfinite(uid) & np.isfinite(log_var)).tolist():
            final[float(uid[i])] = np.array([log_scale[i], log_var[i]])
            rows.append((keys[i], float(uid[i])))
    return {key: final[u] for key, u in rows}


class FinalSizes(LearnedSizes):
    """The sizes of the smoothing pass: every box's size is its pass-1 track's final belief
    (``seeds``, keyed by the box), learned no further; a box without one keeps its track's
    size with the class prior's variance."""

    def __init__(self, seeds: dict[BoxKey, FloatArray], evidence_time_s: float) -> None:
        super().__init__(evidence_time_s)
        self._seeds = seeds

    def before_frame(self, targets: FrameTargets, match: TrackMatch) -> TrackSize:
        prior = super().before_frame(targets, match)
        seeded = [self._seeds.get(k) for k in _box_keys(targets.time_s, targets.boxes_px)]
        log_scale, log_var = prior.log_scale.copy(), prior.prior_log_var.copy()
        for i, s in enumerate(seeded):
            if s is not None:
                log_scale[i], log_var[i] = s
        return TrackSize(log_scale, log_var, prior.prior_log_var)

    def after_frame(self, frame: FrameState, size: TrackSize) -> FloatArray:
        return np.stack([size.log_scale, size.log_var])


@dataclass
class _TargetLog:
    """What the smoothing pass keeps of each frame's targets (``(n,)`` or ``(5, n)``)."""

    good: NDArray[np.intp]
    uid: NDArray[np.int64]
    predicted: FloatArray
    updated: FloatArray
    elapsed_s: FloatArray
    extra_log_var: FloatArray
    noise_scale: FloatArray
    sigma_log_var: FloatArray | None  # what widens the σ only (road_bend.sigma_only_log_var)


class FilterLog:
    """The smoothing pass's record of every frame's distance filters (the estimator's
    ``recorder``), and the smoothing of its tracks (:meth:`smoothed`).

    Args:
        gradient_sigma_rad: the estimator's target-gradient prior spread (for the σ that the
            road bend adds, :func:`~slopedist.estimators.ours.road_bend.sigma_only_log_var`).
    """

    def __init__(self, gradient_sigma_rad: float) -> None:
        self._gradient_sigma_rad = gradient_sigma_rad
        self.frames: list[_TargetLog | None] = []

    def start_frame(self) -> None:
        """A frame begins (one with no usable box keeps nothing)."""
        self.frames.append(None)

    def record(
        self,
        good: NDArray[np.intp],
        frame: FrameState,
        gradient: TargetGradient,
        uid: NDArray[np.int64],
    ) -> None:
        """Keep the filter states of the frame's usable boxes ``good``."""
        targets, match, _, fused, distance = frame
        n = uid.shape[0]
        elapsed = np.full(n, np.nan)
        elapsed[match.continued] = match.elapsed_s
        predicted = distance.predicted_rows
        meas = fused.measurement
        self.frames[-1] = _TargetLog(
            good.copy(),
            uid,
            np.full((5, n), np.nan) if predicted is None else predicted,
            distance.filter_rows.copy(),
            np.where(distance.continued, elapsed, np.nan),
            meas.var - meas.var_white,
            np.ones(n) if distance.noise_scale is None else distance.noise_scale,
            road_bend.sigma_only_log_var(targets, fused, gradient, self._gradient_sigma_rad),
        )

    def smoothed(self, estimates: list[FrameEstimates]) -> list[FrameEstimates]:
        """``estimates`` (this pass's, one per frame) with each track's distance, σ, speed and
        time to collision replaced by the smoothed ones where the row is ``ok`` (the σ of the
        speed and time to collision widened by the track's noise scale, as ``ours`` does).
        The list is changed in place (each frame's estimates replaced by a changed copy in turn,
        so that the drive's estimates are never held twice) and returned."""
        logs = [log for log in self.frames if log is not None]
        if not logs:
            return estimates
        uid = np.concatenate([log.uid for log in logs])
        pred = np.concatenate([log.predicted for log in logs], axis=1)
        upd = np.concatenate([log.updated for log in logs], axis=1)
        dt = np.concatenate([log.elapsed_s for log in logs])
        smooth = upd.copy()
        multi = np.zeros(uid.size, dtype=bool)  # rows of tracks with more than one update
        order = np.argsort(uid, kind="stable")  # each track's rows, in time order
        bounds = np.flatnonzero(np.diff(uid[order])) + 1
        for rows in np.split(order, bounds):
            if rows.size > 1:
                smooth[:, rows] = kf.rts_smooth_rows(upd[:, rows], pred[:, rows], dt[rows])
                multi[rows] = True
        extra = np.concatenate([log.extra_log_var for log in logs])
        dist, sigma = kf.distance_moments_rows(smooth, extra)
        if any(log.sigma_log_var is not None for log in logs):  # the distance stays as it is
            sigma_only = [
                np.zeros(log.uid.size) if log.sigma_log_var is None else log.sigma_log_var
                for log in logs
            ]
            sigma = kf.distance_moments_rows(smooth, extra + np.concatenate(sigma_only))[1]
        speed, speed_sd, ttc, ttc_sd = kf.motion_moments_rows(smooth)
        widen = np.sqrt(np.maximum(np.concatenate([log.noise_scale for log in logs]), 1.0))
        speed_sd, ttc_sd = speed_sd * widen, ttc_sd * widen  # the noise the track shows, as ours
        out = estimates  # each frame's replaced by its copy in turn: never two of the drive
        k = 0
        for f, log in enumerate(self.frames):
            if log is None:
                continue
            out[f] = _copy(out[f])
            m = log.uid.size
            part = slice(k, k + m)
            _replace_rows(
                out[f],
                log.good,
                dist[part],
                sigma[part],
                multi[part],
                (speed[part], speed_sd[part], ttc[part], ttc_sd[part]),
            )
            k += m
        return out


def _copy(est: FrameEstimates) -> FrameEstimates:
    return FrameEstimates(
        est.theta_rad.copy(),
        est.theta_adj_rad.copy(),
        est.delta_y_px.copy(),
        est.v_px.copy(),
        est.distance_m.copy(),
        est.reason.copy(),
        est.reference.copy(),
        {k: v.copy() for k, v in est.extra.items()},
        est.status.copy(),
        est.cut.copy(),
    )


def _replace_rows(
    est: FrameEstimates,
    rows: NDArray[np.intp],
    centre_m: FloatArray,
    sigma_m: FloatArray,
    tracked: NDArray[np.bool_],
    motion: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
) -> None:
    """Put the smoothed centre distances of the targets ``rows`` into ``est`` (in place) where
    they are ``ok``: ``distance_m`` and the nearest face move with the centre; the smoothed
    motion (speed, its σ, time to collision, its σ) where the track has more than one update
    (``tracked``)."""
    ok = est.status[rows] == EstimateStatus.OK.value
    r = rows[ok]
    shift = centre_m[ok] - est.extra["distance_centre_m"][r]
    est.distance_m[r] += shift
    est.extra["distance_centre_m"][r] += shift
    est.extra["distance_nearest_face_m"][r] += shift
    est.extra["sigma_m"][r] = sigma_m[ok]
    moving = ok & tracked
    for name, values in zip(MOTION_COLUMNS, motion, strict=True):
        est.extra[name][rows[moving]] = values[moving]
