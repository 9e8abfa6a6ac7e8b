"""``ours``: size and ground-contact cues fused per target, tracked over time, self-calibrating.

A frame (:meth:`OursEstimator.estimate`) goes through these steps, in order:

1. **usable boxes**: the boxes with no problem (``reason`` empty), their class constants (with
   the vehicle size a box carries, a detector's, in place of its class prior's:
   :mod:`slopedist.io.detections.sizes`) and the edges the image border cuts
   (:mod:`~slopedist.estimators.ours.border`);
2. **the horizon**: the ego gradient θ with the self-calibration's offset, its jitter and the
   camera mount in use;
3. **tracks**: each box continues a live track (by its track id, else by IoU with the track's
   predicted box: :mod:`~slopedist.estimators.ours.association`) or starts one; a track's own
   size replaces the class prior's with ``size_learning``
   (:mod:`~slopedist.estimators.ours.size_learning`);
4. **the cues** per (target, hypothesis) (:mod:`~slopedist.estimators.ours.frame_cues`): the
   height cue (:func:`~slopedist.estimators.ours.cues.height_cue`, exact for a 3D box), the
   width cue (:func:`~slopedist.estimators.ours.cues.width_cue`, for each heading ψ) and the
   ground contact (eq. 1 with the vanishing line of θ, eq. 4–5); a size cue that a nearer
   target's box may cut is censored (:mod:`~slopedist.estimators.ours.occlusion`);
5. **the fusion over the hypotheses** (headings × size modes, or × vehicle types for a generic
   class: :mod:`~slopedist.estimators.ours.hypotheses`): the cues fused by their propagated
   uncertainties, the hypotheses collapsed by their posterior weights;
6. **the filters** of each track (:mod:`~slopedist.estimators.ours.track_filters`): the distance
   (a constant-velocity Kalman filter on log distance: :mod:`~slopedist.estimators.ours.filter`)
   and the target's road gradient α; the track's odd-object evidence and learned size;
7. **the tracks written**, the self-calibration fed
   (:mod:`~slopedist.estimators.ours.selfcal`);
8. **the records** (:mod:`~slopedist.estimators.ours.outputs`): the distance to the vehicle's
   centre (KITTI's z) with its σ, speed and time to collision; a box the border cuts on every
   cue is an upper bound; a box too uncertain is withheld; the distance is moved to the
   reference point asked for.

Everything is causal: the streaming pipeline and the batch one give identical numbers, and
:meth:`OursEstimator.reset` forgets all state.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from slopedist.core import geometry as geo
from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.estimators.base import (
    EstimateStatus,
    Estimator,
    FrameEstimates,
    FrameInput,
    ReferencePoint,
)
from slopedist.estimators.ours import frame_cues, hypotheses, odd_objects, outputs, size_learning
from slopedist.estimators.ours import track_filters as filters
from slopedist.estimators.ours.association import (
    associate,
    box_noise_sums,
    depth_ratios,
    moved_boxes,
    turn_boxes,
)
from slopedist.estimators.ours.border import ImageBorder, border_cuts_of, settle_border_cuts
from slopedist.estimators.ours.class_table import ClassTable
from slopedist.estimators.ours.config import (
    OursAblation,
    OursConfig,
    carries_state,
    configs_of,
    size_evidence_time,
)
from slopedist.estimators.ours.contact_angle import ContactAngleEvidence
from slopedist.estimators.ours.contact_spread import ContactSpread, mix_readings, tight_weights
from slopedist.estimators.ours.fusion import LogCue
from slopedist.estimators.ours.outputs import EXTRA_COLUMNS
from slopedist.estimators.ours.priors import resolve_prior
from slopedist.estimators.ours.records import (
    CalibrationInUse,
    DistanceFilterResult,
    FrameState,
    FrameTargets,
    FusedCues,
    SizeCues,
    TargetGradient,
    TrackMatch,
)
from slopedist.estimators.ours.road_roughness import HorizonJitter, RoadRoughness
from slopedist.estimators.ours.selfcal import (
    Calibration,
    SelfCalibrator,
    estimator_calibration_warning,
    self_calibrates,
)
from slopedist.estimators.ours.size_learning import LearnedSizes, TrackSize
from slopedist.estimators.ours.tracks import Tracks, TrackUpdate
from slopedist.io.detections.boxes import frame_pixel_boxes, table_box_problems
from slopedist.io.detections.sizes import size_arrays

__all__ = [
    "EXTRA_COLUMNS",
    "OursAblation",
    "OursConfig",
    "OursEstimator",
    "OursSelfCalibratingEstimator",
]

FloatArray = NDArray[np.float64]


class FilterRecorder(Protocol):
    """What keeps each frame's filter states (an offline pass's smoothing)."""

    def record(
        self,
        good: NDArray[np.intp],
        frame: FrameState,
        gradient: TargetGradient,
        uid: NDArray[np.int64],
    ) -> None:
        """The filter states ``frame`` of the frame's usable boxes ``good`` (their rows in the
        frame), their target gradients and track uids."""


class FrameHorizon(NamedTuple):
    """The horizon a frame's cues use.

    Attributes:
        theta_rad: the ego gradient θ (the frame's; a camera at rest's when it has none) plus
            the calibration's horizon offset δ.
        jitter_rad: its per-frame noise.
        calib: the camera mount in use.
        measured: whether the frame's θ was measured (a frame without a rotation, or with an
            odometry jump, has none).
        gradient_sigma_rad: the target-gradient prior's spread for this frame
            (``gradient_sigma_rad``, scaled by the drive's road roughness with
            ``adapt_contact_trust``).
    """

    theta_rad: float
    jitter_rad: float
    calib: CalibrationInUse
    measured: bool
    gradient_sigma_rad: float


_BOX_NOISE_PRIOR_COUNT = 200
"""Weight (in edge samples) of the configured box noise in its online estimate."""

SELFCAL_MAX_LOG_SIGMA = 0.15
"""Classes whose height prior is looser than this (relative) do not feed the self-calibration."""


class OursEstimator(Estimator):
    """slopedist's own estimator; see the module docstring.

    Args:
        camera: intrinsics and the (possibly rough) mount.
        config: options (default :class:`OursConfig`).
        ablation: experimental settings (default :class:`OursAblation`).
        sizes: where the tracks' own sizes come from with ``size_learning`` (default: learned
            over each track, :class:`~slopedist.estimators.ours.size_learning.LearnedSizes`).
        recorder: given each frame's filter states, predictions included (an offline pass's
            smoothing: :mod:`~slopedist.estimators.ours.offline`); None: nothing is kept.
        **overrides: individual options of either, e.g. ``box_sigma_px=1.0`` or
            ``self_calibrate=True`` (:func:`~slopedist.estimators.ours.config.configs_of`).
    """

    name: ClassVar[str] = "ours"
    needs_rotation: ClassVar[bool] = True
    handles_border_cuts: ClassVar[bool] = True

    def __init__(
        self,
        camera: Camera,
        config: OursConfig | None = None,
        ablation: OursAblation | None = None,
        *,
        sizes: LearnedSizes | None = None,
        recorder: FilterRecorder | None = None,
        **overrides: Any,
    ) -> None:
        super().__init__(camera)
        if config is not None and not isinstance(config, OursConfig):
            raise ConfigurationError(f"ours option config must be an OursConfig, got {config!r}")
        if ablation is not None and not isinstance(ablation, OursAblation):
            raise ConfigurationError(
                f"ours option ablation must be an OursAblation, got {ablation!r}"
            )
        config, abl = configs_of(overrides, config, ablation)
        self.config = config
        self.ablation = abl
        evidence_time = size_evidence_time(config, abl)
        self._sizes = (sizes or LearnedSizes(evidence_time)) if config.size_learning else None
        self._recorder = recorder
        self._hypotheses = hypotheses.Hypotheses(abl)
        headings = self._hypotheses.yaw_rad
        self.selfcal = SelfCalibrator(
            camera.f, camera.mount_angle_rad, camera.height_m, abl.selfcal
        )
        self._theta_rest = float(geo.rest_gradient(camera.mount_angle_rad))
        generic = tuple(config.generic_classes)
        self._classes = ClassTable(
            abl.priors,
            headings,
            () if config.generic_sigma_only else generic,
            abl.type_mixture,
            len(self._hypotheses.size_modes),
            generic if config.generic_sigma_only else (),
        )
        self._odd_check = odd_objects.OddObjectCheck.of(config, abl, headings.size)
        self._odd_share = None
        if abl.learn_odd_share and self._odd_check.odd_mode is not None:
            self._odd_share = odd_objects.OddShare(self._odd_check.prior_log_odds)
        self._fixed_calib = CalibrationInUse(
            0.0, config.mount_sigma_rad, camera.height_m, config.height_sigma_m
        )
        self._reference = ReferencePoint(config.reference)  # one of REFERENCES (OursConfig)
        self._border = ImageBorder(camera)
        self._roughness = RoadRoughness() if abl.adapt_contact_trust else None
        self._jitter = HorizonJitter(abl.theta_sigma_rad) if abl.learn_horizon_jitter else None
        self._contact_angle = None
        if abl.learn_contact_angle:
            prior = math.hypot(config.gradient_sigma_rad, config.mount_sigma_rad)
            self._contact_angle = ContactAngleEvidence(prior, config.max_age_s)
        self._contact_spread = None
        if abl.learn_contact_spread:
            car = resolve_prior("Car", abl.priors)
            self._contact_spread = ContactSpread(
                math.sqrt(
                    config.gradient_sigma_rad**2
                    + config.mount_sigma_rad**2
                    + abl.theta_sigma_rad**2
                ),
                car.height_sigma_m / car.height_m,
            )
        self.reset()

    def reset(self) -> None:
        """Forget all tracks and the self-calibration (new sequence)."""
        self.tracks = Tracks.empty(self._hypotheses.yaw_rad.size)
        self.selfcal.reset()
        self._next_uid = 0
        self._border.reset()
        self._d2_sum = 0.0
        self._d2_count = 0
        if self._roughness is not None:
            self._roughness.reset()
        if self._contact_angle is not None:
            self._contact_angle.reset()
        if self._contact_spread is not None:
            self._contact_spread.reset()
        if self._odd_share is not None:
            self._odd_share.reset()
        if self._jitter is not None:
            self._jitter.reset()

    @property
    def box_sigma_px(self) -> float:
        """Current box-edge noise (pixels): the configured prior, refined online.

        Each edge's second difference over three consecutive, evenly spaced updates of a track
        has variance 6σ² when the edges move smoothly; the estimate pools them with
        ``_BOX_NOISE_PRIOR_COUNT`` pseudo-observations of the prior.
        """
        s0 = self.config.box_sigma_px
        if not self.ablation.adapt_box_noise:
            return s0
        n0 = _BOX_NOISE_PRIOR_COUNT
        return math.sqrt((n0 * s0 * s0 + self._d2_sum / 6.0) / (n0 + self._d2_count))

    def calibration(self) -> Calibration:
        """The current self-calibration (the configured one, with its prior σ, before any data)."""
        return self.selfcal.calibration()

    @property
    def self_calibrates(self) -> bool:
        """Whether the mount is re-estimated online (option ``self_calibrate``)."""
        return self_calibrates(self)

    def calibration_jackknife(self) -> FloatArray:
        """:meth:`~slopedist.estimators.ours.selfcal.SelfCalibrator.track_jackknife`."""
        return self.selfcal.track_jackknife()

    def end_warnings(self) -> list[str]:
        """:func:`~slopedist.estimators.ours.selfcal.estimator_calibration_warning`, if any."""
        warning = estimator_calibration_warning(self)
        return [] if warning is None else [warning]

    # -- one frame, step by step ------------------------------------------------------------

    def estimate(self, frame: FrameInput) -> FrameEstimates:
        n = frame.boxes.boxes.shape[0]
        # the reasons of unusable_box_reasons(frame, needs_rotation=False, camera)
        reasons = table_box_problems(frame.boxes, self._border.known_size)
        good = np.flatnonzero(reasons == "")
        horizon = self._frame_horizon(frame.theta_rad, frame.timestamp_s if n else None)
        self._drop_stale_tracks(frame.timestamp_s)  # before association: the same whether or
        # not the caller also passes the frames with no boxes
        values: dict[str, FloatArray] = {}
        cut_edges = None  # (good, 4): which edges of the usable boxes the image border cuts
        if good.size:
            cut_edges = self._border.cut_edges(frame_pixel_boxes(frame.boxes)[good])
            values = self._estimate_targets(frame, good, cut_edges, horizon)
        est = outputs.frame_estimates(values, good, n, frame.theta_rad, reasons, self._reference)
        half_extent = est.distance_m - est.extra["distance_nearest_face_m"]  # centre to face
        if self._border.known_size is not None and cut_edges is not None:
            self._bound_cut_boxes(est, good, cut_edges, half_extent)
        est.withhold_uncertain(self.config.max_relative_sigma)
        outputs.move_to_reference(est, self._reference, half_extent)
        est.withhold_distances()  # a withheld distance is in no column
        return est

    def _estimate_targets(
        self,
        frame: FrameInput,
        good: NDArray[np.intp],
        cut_edges: NDArray[np.bool_],
        horizon: FrameHorizon,
    ) -> dict[str, FloatArray]:
        """The output columns of the usable boxes ``good`` of ``frame`` (and the state
        updates); ``cut_edges`` ``(len(good), 4)``: the boxes' edges the image border cuts."""
        abl = self.ablation
        targets = self._frame_targets(frame, good, cut_edges)
        match = self._match_tracks(targets, frame.R_world_cam)
        size_before = None
        if self._sizes is not None:  # the tracks' own sizes in the class constants
            size_before = self._sizes.before_frame(targets, match)
            targets = size_learning.with_track_size(targets, size_before)
        size = frame_cues.size_cues(abl, self.camera, targets, horizon.calib)
        ground = self._ground_contact_cue(targets, match, size, horizon)
        size = self._censor_occluded(targets, size, ground)
        odd = self._odd_check.carried(match, targets)  # the tracks' odd-object evidence
        fused = self._fuse_hypotheses(targets, match, size, ground, odd)
        if self._contact_spread is not None and ground is not None:
            fused = self._mix_contact_readings(targets, match, size, odd, fused, horizon)
        distance = self._filter_distance(match, fused.measurement, frame.R_world_cam)
        odd_prob = odd_objects.of_class_priors(fused.odd_size_prob, targets.classes.sized)
        odd = self._odd_check.after_frame(
            odd, odd_prob, match, distance, self._odd_log_odds_offset()
        )
        gradient = self._target_gradient(targets, match, fused, distance, horizon)
        state = FrameState(targets, match, size, fused, distance)
        size_after = self._learn_sizes(state, size_before)
        uid = self._update_tracks(state, gradient, frame.R_world_cam, size_after, odd)
        if self._odd_share is not None and odd_prob is not None:
            self._odd_share.update(odd_prob, targets.time_s)
        if self._contact_angle is not None:
            self._feed_contact_angle(state, gradient, uid, horizon)
        if self._contact_spread is not None:
            self._feed_contact_spread(state, gradient, uid, horizon)
        if self._recorder is not None:
            self._recorder.record(good, state, gradient, uid)
        if abl.self_calibrate and horizon.measured:  # not a θ it assumed
            self._feed_selfcal(state, gradient, uid, horizon)
        out = outputs.box_estimates(
            self.camera,
            self._hypotheses.yaw_rad,
            targets,
            fused,
            distance,
            gradient,
            uid,
            horizon.theta_rad,
            horizon.calib,
            horizon.gradient_sigma_rad,
        )
        if size_after is not None:
            out = out._replace(**size_learning.size_columns(size_after, targets.classes.height_m))
        values = {k: v for k, v in zip(out._fields, out, strict=True) if v is not None}
        if abl.self_calibrate:
            values.update(self._calibration_columns(good.size))
        return values

    def _frame_horizon(self, theta_rad: float, time_s: float | None) -> FrameHorizon:
        """The horizon of a frame at ``time_s`` whose ego gradient is ``theta_rad`` (NaN:
        unknown); with ``adapt_contact_trust`` the frame's θ joins the drive's roughness first
        (unless ``time_s`` is None: a frame without boxes, which a batch run skips) and the
        jitter and target-gradient spread are scaled by it."""
        calib = self._calibration_in_use()
        measured = math.isfinite(theta_rad)
        theta = (float(theta_rad) if measured else self._theta_rest) + calib.horizon_offset_rad
        abl = self.ablation
        jitter = abl.theta_sigma_rad if measured else abl.no_rotation_theta_sigma_rad
        gradient_sigma = self.config.gradient_sigma_rad
        if self._jitter is not None and measured:
            if time_s is not None:
                self._jitter.update(time_s, float(theta_rad))
            jitter = self._jitter.sigma_rad
        if self._roughness is not None:
            if measured and time_s is not None:
                self._roughness.update(time_s, float(theta_rad) - self._theta_rest)
                jitter *= math.sqrt(self._roughness.scale)
            gradient_sigma *= math.sqrt(self._roughness.scale)
        if self._contact_spread is not None:
            root = math.sqrt(self._contact_spread.scale)
            jitter *= root
            gradient_sigma *= root
            calib = calib._replace(horizon_offset_sigma_rad=calib.horizon_offset_sigma_rad * root)
        if self._contact_angle is not None:
            root = math.sqrt(self._contact_angle.scale)
            gradient_sigma *= root
            calib = calib._replace(horizon_offset_sigma_rad=calib.horizon_offset_sigma_rad * root)
        return FrameHorizon(theta, jitter, calib, measured, gradient_sigma)

    def _calibration_in_use(self) -> CalibrationInUse:
        """The self-calibration's mount when self-calibrating, else the configured one."""
        if self.ablation.self_calibrate:
            cov = self.selfcal.covariance
            return CalibrationInUse(
                self.selfcal.horizon_offset_rad,
                math.sqrt(cov[0, 0]),
                self.selfcal.height_m,
                math.sqrt(cov[1, 1]),
            )
        return self._fixed_calib

    def _drop_stale_tracks(self, t: float) -> None:
        """Drop the tracks not seen for longer than ``max_age_s`` at time ``t``."""
        tr = self.tracks
        age = self.config.max_age_s + 1e-9
        if len(tr) and t - tr.last_time_s.min() > age:  # the oldest is stale
            self.tracks = tr.take(t - tr.last_time_s <= age)

    def _frame_targets(
        self, frame: FrameInput, good: NDArray[np.intp], cut_edges: NDArray[np.bool_]
    ) -> FrameTargets:
        """The usable boxes ``good``, their class constants (with the vehicle sizes the boxes
        carry in place of their class prior's) and border cuts (``cut_edges``)."""
        table = frame.boxes
        return FrameTargets(
            table.boxes[good],
            table.track_id[good],
            self._classes.gather(table.cls[good], size_arrays(table.extra, good)),
            border_cuts_of(cut_edges),
            self.box_sigma_px,
            frame.timestamp_s,
        )

    def _match_tracks(self, targets: FrameTargets, R_now: FloatArray | None) -> TrackMatch:
        """Associate the boxes with the live tracks and gather the continued tracks' states."""
        abl = self.ablation
        cam = self.camera
        tr = self.tracks
        t = targets.time_s
        boxes, ids = targets.boxes_px, targets.track_ids
        predicted = None
        # the boxes' image motion serves IoU association (id-less boxes) and the noise estimate
        box_motion = abl.adapt_box_noise or bool((ids < 0).any())
        last_boxes = tr.last_box_px.T
        if not len(tr):  # (no track is ever stored unless carries_state)
            rows = np.full(boxes.shape[0], -1, np.int64)
            turned, depth_ratio = last_boxes, np.ones(0)
        elif box_motion:
            R_last = tr.R_world_cam.transpose(2, 0, 1)  # (T, 3, 3)
            turned, depth_ratio = turn_boxes(last_boxes, cam.f, cam.c_x, cam.c_y, R_last, R_now)
            predicted = moved_boxes(tr, turned, t)
            rows = associate(tr, boxes, ids, abl.min_iou, predicted)
        else:
            rows = associate(tr, boxes, ids, abl.min_iou)
            turned, depth_ratio = last_boxes, None  # the depth ratios of the continued only
        continued = rows >= 0
        r_old = rows[continued]
        before = tr.take(r_old)
        elapsed = t - before.last_time_s
        grad_var = before.gradient_var_rad2 + abl.process.gradient_rad**2 * elapsed  # predicted
        if abl.adapt_box_noise and r_old.size and predicted is not None:
            d2_sum, d2_count = box_noise_sums(
                tr, boxes[continued] - predicted[r_old], r_old, t, self.box_sigma_px
            )
            self._d2_sum += d2_sum
            self._d2_count += d2_count
        return TrackMatch(
            rows, continued, r_old, before, elapsed, grad_var, turned, depth_ratio, box_motion
        )

    def _ground_contact_cue(
        self, targets: FrameTargets, match: TrackMatch, size: SizeCues, horizon: FrameHorizon
    ) -> LogCue | None:
        """The ground-contact cue per hypothesis (None without ``use_ground_contact``), with
        the target gradient prior it assumes; a box cut at the bottom adds its bound to the
        size cues' (``size.bounds``)."""
        abl = self.ablation
        if not abl.use_ground_contact:
            return None
        alpha, alpha_var = filters.contact_gradient_prior(
            abl.gradient_feedback, horizon.gradient_sigma_rad, match
        )
        ground = frame_cues.ground_contact_cue(
            abl,
            self.camera,
            targets,
            size.bounds,
            alpha,
            alpha_var,
            horizon.theta_rad,
            horizon.jitter_rad,
            horizon.calib,
        )
        if self._contact_angle is None or self._contact_angle.scale >= 1.0:
            return ground
        # a contact trusted more than configured only where the height cue agrees with it
        wide = self._configured_contact_cue(targets, match, horizon.theta_rad, horizon.jitter_rad)
        return frame_cues.consistent_contact(
            targets, size, ground, wide, abl.consistency_gate_sigma
        )

    def _configured_contact_cue(
        self, targets: FrameTargets, match: TrackMatch, theta_rad: float, jitter_rad: float
    ) -> LogCue:
        """The ground-contact cue with the configured trust (target gradient and mount
        spreads as configured, horizon jitter ``jitter_rad``), without bounds."""
        abl = self.ablation
        alpha, alpha_var = filters.contact_gradient_prior(
            abl.gradient_feedback, self.config.gradient_sigma_rad, match
        )
        return frame_cues.ground_contact_cue(
            abl,
            self.camera,
            targets,
            [],
            alpha,
            alpha_var,
            theta_rad,
            jitter_rad,
            self._calibration_in_use(),
        )

    def _mix_contact_readings(
        self,
        targets: FrameTargets,
        match: TrackMatch,
        size: SizeCues,
        odd: FloatArray | None,
        tight: FusedCues,
        horizon: FrameHorizon,
    ) -> FusedCues:
        """``tight`` (the cues read with the drive's contact spread) mixed with the cues read
        with the configured contact (``learn_contact_spread``), and the tight reading's
        posterior weights given to the drive's share."""
        spread = self._contact_spread
        if spread is None or spread.scale >= 1.0:  # the two readings are one
            return tight
        abl = self.ablation
        jitter = abl.theta_sigma_rad if horizon.measured else abl.no_rotation_theta_sigma_rad
        wide_cue = self._configured_contact_cue(targets, match, horizon.theta_rad, jitter)
        wide = self._fuse_hypotheses(targets, match, size, wide_cue, odd)
        weight = tight_weights(tight, wide, spread.tight_share)
        spread.add_posterior(weight, targets.time_s)
        return mix_readings(tight, wide, weight)

    def _censor_occluded(
        self, targets: FrameTargets, size: SizeCues, ground: LogCue | None
    ) -> SizeCues:
        """The size cues with those a nearer target's box may cut censored against the ground
        contact (``occlusion_aware``; :func:`~slopedist.estimators.ours.frame_cues.
        occlusion_adjusted`)."""
        if ground is None or not self.ablation.occlusion_aware or targets.boxes_px.shape[0] < 2:
            return size
        return frame_cues.occlusion_adjusted(self.ablation, targets, size, ground)

    def _fuse_hypotheses(
        self,
        targets: FrameTargets,
        match: TrackMatch,
        size: SizeCues,
        ground: LogCue | None,
        odd_evidence: FloatArray | None,
    ) -> FusedCues:
        """The cues fused per hypothesis and collapsed over them; the hypotheses' prior holds
        the tracks' odd-object evidence."""
        abl = self.ablation
        log_prior = self._hypotheses.log_prior(match, targets)
        return hypotheses.fuse_hypotheses(
            targets,
            size,
            ground,
            self._odd_check.prior(log_prior, odd_evidence, self._odd_log_odds_offset()),
            self._hypotheses.spreads(targets),
            abl.consistency_gate_sigma,
            size.height.camera_lever if abl.road_bend_sigma else None,
        )

    def _odd_log_odds_offset(self) -> float:
        """The drive's learned odd-object log odds over the configured ones
        (``learn_odd_share``; 0 without): the same through a frame, learned after it."""
        return self._odd_share.log_odds_offset if self._odd_share is not None else 0.0

    def _filter_distance(
        self, match: TrackMatch, measurement: LogCue, R_now: FloatArray | None
    ) -> DistanceFilterResult:
        """:func:`~slopedist.estimators.ours.track_filters.filter_distance`, with the depth
        change the camera's rotation ``R_now`` gives each continued track."""
        ratio = None
        if self.ablation.motion_model and match.continued_rows.size:
            ratio = self._continued_depth_ratios(match, R_now)
        return filters.filter_distance(
            self.ablation, match, measurement, ratio, self._recorder is not None
        )

    def _continued_depth_ratios(self, match: TrackMatch, R_now: FloatArray | None) -> FloatArray:
        """``Z_now/Z_last`` of the continued tracks' box centres from the camera's rotation."""
        if match.depth_ratio is not None:
            return match.depth_ratio[match.continued_rows]
        cam = self.camera
        before = match.before
        return depth_ratios(before.last_box_px, cam.f, cam.c_x, cam.c_y, before.R_world_cam, R_now)

    def _target_gradient(
        self,
        targets: FrameTargets,
        match: TrackMatch,
        fused: FusedCues,
        distance: DistanceFilterResult,
        horizon: FrameHorizon,
    ) -> TargetGradient:
        """:func:`~slopedist.estimators.ours.track_filters.target_gradient` of the frame."""
        return filters.target_gradient(
            horizon.gradient_sigma_rad,
            self.camera,
            targets,
            match,
            fused,
            distance.rows,
            horizon.theta_rad,
            horizon.jitter_rad,
            horizon.calib.height_m,
        )

    def _learn_sizes(self, state: FrameState, size_before: TrackSize | None) -> FloatArray | None:
        """``(2, n)`` each target's size belief after this frame (None without
        ``size_learning``)."""
        if self._sizes is None or size_before is None:
            return None
        return self._sizes.after_frame(state, size_before)

    def _update_tracks(
        self,
        state: FrameState,
        gradient: TargetGradient,
        R_now: FloatArray | None,
        size_rows: FloatArray | None,
        odd_evidence: FloatArray | None,
    ) -> NDArray[np.int64]:
        """Write this frame into the tracks (when any state is carried); the track uid of
        every target."""
        targets, match, _, fused, distance = state
        abl = self.ablation
        if not carries_state(self.config, abl):
            return self._new_uids(targets.boxes_px.shape[0])
        belief: FloatArray | None = None
        if abl.yaw_memory:  # the heading belief a track carries (only read with yaw_memory)
            n_headings = self._hypotheses.yaw_rad.size
            belief = hypotheses.heading_belief(fused, abl.yaw_evidence_weight, n_headings)
        update = TrackUpdate(
            distance.rows,
            targets.track_ids,
            distance.filter_rows,
            belief,
            gradient.track_mean_rad,
            gradient.track_var_rad2,
            gradient.obs_var_other_rad2,
            targets.boxes_px,
            targets.time_s,
            np.eye(3) if R_now is None else np.asarray(R_now, dtype=float),
            match.turned_boxes_px if match.box_motion else None,
            size_rows,
            odd_evidence,
            distance.noise_scale,
        )
        tr = self.tracks
        continued = update.rows >= 0
        uid = np.empty(continued.shape[0], np.int64)
        uid[continued] = tr.uid[update.rows[continued]]
        tr.write_continued(update, continued)
        new = ~continued
        if new.any():  # the tracks are replaced only when one starts (see tracks.py)
            new_uid = self._new_uids(int(np.count_nonzero(new)))
            uid[new] = new_uid
            log_prior = self._hypotheses.log_yaw_prior
            self.tracks = tr.with_started(update, new, new_uid, log_prior)
        return uid

    def _new_uids(self, k: int) -> NDArray[np.int64]:
        uid = np.arange(self._next_uid, self._next_uid + k)
        self._next_uid += k
        return uid

    def _feed_selfcal(
        self,
        state: FrameState,
        gradient: TargetGradient,
        uid: NDArray[np.int64],
        horizon: FrameHorizon,
    ) -> None:
        """Give the self-calibration the targets of tightly sized classes whose box is not cut
        by the top or bottom border: bottom rows, nearest-face size distances, shape gaps (of a
        frame with a measured θ only: the caller skips one without a rotation or with an
        odometry jump, whose resting θ is no measurement)."""
        targets, fused = state.targets, state.fused
        cam, n = self.camera, uid.shape[0]
        classes = targets.classes
        usable = (classes.height_log_sigma <= SELFCAL_MAX_LOG_SIGMA) & ~classes.generic
        cuts = targets.border_cuts
        if cuts is not None:
            usable &= ~cuts.top & ~cuts.bottom
        theta_cfg = horizon.theta_rad - horizon.calib.horizon_offset_rad
        v_cfg = cam.c_y - cam.f * math.tan(theta_cfg)
        near = np.where(usable, gradient.size_distance_m - fused.half_extent_m, np.nan)
        shape_gap = frame_cues.shape_gap(targets, state.size_cues)
        self.selfcal.update(
            uid, targets.boxes_px[:, 3], np.full(n, v_cfg), np.full(n, theta_cfg), near, shape_gap
        )

    def _inverse_distances(
        self, state: FrameState, gradient: TargetGradient, horizon: FrameHorizon
    ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        """Each target's inverse distance to its contact point by its size cues and by its
        ground contact under the frame's horizon (1/m), and which targets give both (positive,
        the box not cut at the top or bottom by the border)."""
        targets, fused = state.targets, state.fused
        cam = self.camera
        v = cam.c_y - cam.f * math.tan(horizon.theta_rad)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv_size = 1.0 / (gradient.size_distance_m - fused.half_extent_m)
            inv_contact = (targets.boxes_px[:, 3] - v) / (cam.f * horizon.calib.height_m)
        usable = (inv_size > 0) & (inv_contact > 0)
        cuts = targets.border_cuts
        if cuts is not None:
            usable &= ~cuts.top & ~cuts.bottom
        return inv_size, inv_contact, usable

    def _feed_contact_angle(
        self,
        state: FrameState,
        gradient: TargetGradient,
        uid: NDArray[np.int64],
        horizon: FrameHorizon,
    ) -> None:
        """Give the contact-angle evidence the inverse contact-point distances of the size
        cues and of the ground contact of the usable boxes (:meth:`_inverse_distances`; of a
        frame with a measured θ only)."""
        if self._contact_angle is None or not horizon.measured:
            return
        inv_size, inv_contact, usable = self._inverse_distances(state, gradient, horizon)
        self._contact_angle.add(
            uid,
            np.where(usable, inv_size, np.nan),
            inv_contact,
            state.targets.time_s,
            horizon.calib.height_m,
        )

    def _feed_contact_spread(
        self,
        state: FrameState,
        gradient: TargetGradient,
        uid: NDArray[np.int64],
        horizon: FrameHorizon,
    ) -> None:
        """Give the contact spread each usable target's cue gap in angle units and its
        ``(h/z)²`` (:meth:`_inverse_distances`, and no nearer box may cut it; of a frame with
        a measured θ only)."""
        if self._contact_spread is None or not horizon.measured:
            return
        inv_size, inv_contact, usable = self._inverse_distances(state, gradient, horizon)
        if state.size_cues.hidden is not None:
            usable &= ~state.size_cues.hidden
        h = horizon.calib.height_m
        gap = np.where(usable, h * (inv_contact - inv_size), np.nan)
        self._contact_spread.add_gaps(uid, gap, (h * inv_size) ** 2, state.targets.time_s)

    def _calibration_columns(self, n: int) -> dict[str, FloatArray]:
        """The self-calibration in use, as columns of ``n`` boxes."""
        cal = self.selfcal.calibration()
        names = ("mount_angle_rad", "mount_angle_sigma_rad", "height_m", "height_sigma_m")
        return {f"calib_{k}": np.full(n, getattr(cal, k)) for k in names}

    def _bound_cut_boxes(
        self,
        est: FrameEstimates,
        good: NDArray[np.intp],
        cut_edges: NDArray[np.bool_],
        half_extent: FloatArray,
    ) -> None:
        """The states of the boxes the image border cuts
        (:func:`~slopedist.estimators.ours.border.settle_border_cuts`); the nearest face of an
        upper bound is a bound too (the same cue), ``half_extent`` nearer."""
        cut = np.zeros((est.distance_m.shape[0], 4), dtype=bool)
        cut[good] = cut_edges
        settle_border_cuts(est, cut, self.ablation.use_width, self.ablation.use_ground_contact)
        bounded = est.status == EstimateStatus.UPPER_BOUND.value
        if bounded.any():
            face = est.extra["distance_nearest_face_m"]
            face[bounded] = est.distance_m[bounded] - half_extent[bounded]


class OursSelfCalibratingEstimator(OursEstimator):
    """``ours`` that also estimates the camera's mount angle θ0 and height online
    (``self_calibrate=True``): for a rough calibration."""

    name: ClassVar[str] = "ours-selfcal"

    def __init__(
        self,
        camera: Camera,
        config: OursConfig | None = None,
        ablation: OursAblation | None = None,
        **overrides: Any,
    ) -> None:
        if ablation is None:
            overrides.setdefault("self_calibrate", True)
        super().__init__(camera, config, ablation, **overrides)
