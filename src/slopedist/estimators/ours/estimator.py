"""``ours``: size and ground-contact cues fused per target, tracked over time, self-calibrating.

For every box and every heading hypothesis ψ the estimator computes

1. the **height cue** (:func:`~slopedist.estimators.ours.cues.height_cue`): distance from the box
   height and the class's height prior, exact for a 3D box (roof and footprint in perspective);
2. the **width cue** (:func:`~slopedist.estimators.ours.cues.width_cue`): from the box width,
   the class's width and length and ψ — a car seen at an angle shows its side, so the heading is
   a hypothesis, weighed by how it reconciles width and height and by a prior of aligned traffic;
3. the **ground-contact cue**: eq. 1 with the vanishing line of the ego gradient θ (eq. 4–5), as
   the paper, plus the target's own continuous road gradient α; a size cue whose box side
   lies on a nearer target's box and that says farther than the ground contact by more than
   noise explains is taken as cut short by occlusion (censored) and loses weight,

and fuses them by their propagated uncertainties in an extended Kalman filter per track whose
state is log-distance, relative rate, the vehicle's size deviation from its class prior and α
(:mod:`~slopedist.estimators.ours.filter`). The distance reported is to the vehicle's centre
(KITTI's z); ``distance_nearest_face_m`` is the distance to its nearest face. The mount angle
and height are re-estimated online from the targets (:mod:`~slopedist.estimators.ours.selfcal`).

Everything is causal: the streaming pipeline and the batch one give identical numbers, and
:meth:`OursEstimator.reset` forgets all state.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Protocol

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
from slopedist.estimators.ours import frame_cues, fusion, odd_objects, size_learning
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
from slopedist.estimators.ours.fusion import LogCue
from slopedist.estimators.ours.priors import yaw_grid, yaw_prior_weights
from slopedist.estimators.ours.records import (
    EXTRA_COLUMNS,
    BoxEstimates,
    CalibrationInUse,
    DistanceFilterResult,
    FrameState,
    FrameTargets,
    FusedCues,
    TargetGradient,
    TrackMatch,
    scatter,
)
from slopedist.estimators.ours.selfcal import (
    Calibration,
    SelfCalibrator,
    estimator_calibration_warning,
    self_calibrates,
)
from slopedist.estimators.ours.size_learning import LearnedSizes
from slopedist.estimators.ours.tracks import Tracks, TrackUpdate
from slopedist.io.detections.boxes import frame_pixel_boxes, table_box_problems

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


_BOX_NOISE_PRIOR_COUNT = 200
"""Weight (in edge samples) of the configured box noise in its online estimate."""

SELFCAL_MAX_LOG_SIGMA = 0.15
"""Classes whose height prior is looser than this (relative) do not feed the self-calibration."""


class OursEstimator(Estimator):
    """slopedist's own estimator; see the module docstring.

    Args:
        camera: intrinsics and the (possibly rough) mount.
        config: options (default :class:`OursConfig`).
        sizes: where the tracks' own sizes come from with ``size_learning`` (default: learned
            over each track, :class:`~slopedist.estimators.ours.size_learning.LearnedSizes`).
        recorder: given each frame's filter states, predictions included (an offline pass's
            smoothing: :mod:`~slopedist.estimators.ours.offline`); None: nothing is kept.
        ablation: experimental settings (default :class:`OursAblation`).
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
        grid = yaw_grid() if abl.yaw_hypotheses else np.zeros(1)
        self._yaw = grid
        self._log_yaw_prior = (
            np.log(yaw_prior_weights(grid, abl.yaw_prior)) if grid.size > 1 else np.zeros(1)
        )
        self.selfcal = SelfCalibrator(
            camera.f, camera.mount_angle_rad, camera.height_m, abl.selfcal
        )
        self._theta_rest = float(geo.rest_gradient(camera.mount_angle_rad))
        self._size_modes = [m for m, _ in abl.size_modes]
        generic = tuple(config.generic_classes)
        self._classes = ClassTable(
            abl.priors,
            grid,
            () if config.generic_sigma_only else generic,
            abl.type_mixture,
            len(self._size_modes),
            generic if config.generic_sigma_only else (),
        )
        self._mode_spreads = fusion.ModeSpreads(self._size_modes, grid.size)
        self._type_spreads = fusion.ModeSpreads(  # a generic class: its types take the modes' place
            self._size_modes[:1], grid.size * len(abl.type_mixture)
        )
        self._log_mode = np.repeat(np.log([p for _, p in abl.size_modes]), grid.size)
        self._odd_check = odd_objects.OddObjectCheck.of(config, abl, grid.size)
        self._fixed_calib = CalibrationInUse(
            0.0, config.mount_sigma_rad, camera.height_m, config.height_sigma_m
        )
        self._reference = ReferencePoint(config.reference)  # one of REFERENCES (OursConfig)
        self._border = ImageBorder(camera)
        self.reset()

    def reset(self) -> None:
        """Forget all tracks and the self-calibration (new sequence)."""
        self.tracks = Tracks.empty(self._yaw.size)
        self.selfcal.reset()
        self._next_uid = 0
        self._border.reset()
        self._d2_sum = 0.0
        self._d2_count = 0

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

    # -- one frame -------------------------------------------------------------------------

    def estimate(self, frame: FrameInput) -> FrameEstimates:
        n = frame.boxes.boxes.shape[0]
        seen = frame_pixel_boxes(frame.boxes)  # what the border cuts: the frame's pixels
        # the reasons of unusable_box_reasons(frame, needs_rotation=False, camera)
        reasons = table_box_problems(frame.boxes, self._border.known_size)
        good = np.flatnonzero(reasons == "")
        theta_in = float(frame.theta_rad)
        calib = self._calibration_in_use()
        theta_ok = math.isfinite(theta_in)
        theta_f = (theta_in if theta_ok else self._theta_rest) + calib.horizon_offset_rad
        abl = self.ablation
        jitter = abl.theta_sigma_rad if theta_ok else abl.no_rotation_theta_sigma_rad
        self._drop_stale(frame.timestamp_s)  # before association: the same whether or not the
        # caller also passes the frames with no boxes
        values: dict[str, FloatArray] = {}
        edges = None  # (good, 4): which edges of the usable boxes the image border cuts
        if good.size:
            edges = self._border.cut_edges(seen[good])
            box_values = self._estimate_boxes(frame, good, theta_f, jitter, calib, edges)
            values = {k: v for k, v in zip(BoxEstimates._fields, box_values) if v is not None}
            if abl.self_calibrate:
                values.update(self._calibration_columns(good.size))
        out = scatter(values, good, n)
        est = FrameEstimates(
            theta_rad=np.full(n, theta_in),
            theta_adj_rad=out["theta_adj_rad"],
            delta_y_px=out["delta_y_px"],
            v_px=out["v_px"],
            distance_m=out["distance_m"],
            reason=reasons,
            reference=np.full(n, self._reference.value, dtype=object),
            extra={k: out[k] for k in EXTRA_COLUMNS},
            cut=np.full(n, "", dtype=object),
        )
        # centre to nearest face, before the border cuts settle
        half_extent = est.distance_m - est.extra["distance_nearest_face_m"]
        if self._border.known_size is not None and edges is not None:
            cut = np.zeros((n, 4), dtype=bool)
            cut[good] = edges
            settle_border_cuts(est, cut, abl.use_width, abl.use_ground_contact)
            bounded = est.status == EstimateStatus.UPPER_BOUND.value
            if bounded.any():  # the nearest face of a bound is a bound (the same cue)
                face = est.extra["distance_nearest_face_m"]
                face[bounded] = est.distance_m[bounded] - half_extent[bounded]
        est.withhold_uncertain(self.config.max_relative_sigma)
        est.extra["distance_centre_m"] = est.distance_m.copy()
        if self._reference is not ReferencePoint.CENTRE:  # the nearest face (or its foot)
            est.distance_m -= half_extent
        est.withhold_distances()  # a withheld distance is in no column
        return est

    def _calibration_columns(self, n: int) -> dict[str, FloatArray]:
        """The self-calibration in use, as columns of ``n`` boxes."""
        cal = self.selfcal.calibration()
        names = ("mount_angle_rad", "mount_angle_sigma_rad", "height_m", "height_sigma_m")
        return {f"calib_{k}": np.full(n, getattr(cal, k)) for k in names}

    def _estimate_boxes(
        self,
        frame: FrameInput,
        good: NDArray[np.intp],
        theta_rad: float,
        jitter_rad: float,
        calib: CalibrationInUse,
        cut_edges: NDArray[np.bool_],
    ) -> BoxEstimates:
        """All outputs for the usable boxes ``good`` of ``frame`` (and the state updates).

        ``theta_rad`` is the ego gradient θ plus the calibration's horizon offset, ``jitter_rad``
        its per-frame noise; ``cut_edges`` ``(len(good), 4)``: the boxes' edges the image border
        cuts (:meth:`~slopedist.estimators.ours.border.ImageBorder.cut_edges`). Per (target,
        hypothesis) quantities are ``(n, K)`` arrays (``(n, M·K)`` over ``M`` size modes or
        vehicle types); the class constants come as such planes from one gather
        (:class:`ClassTable`), so that the arithmetic of a frame's few targets never broadcasts.
        """
        abl = self.ablation
        cam = self.camera
        targets = self._frame_targets(frame, good, cut_edges)
        match = self._match_tracks(targets, frame.R_world_cam)
        track_size = None
        if self._sizes is not None:  # the tracks' own sizes in the class constants
            track_size = self._sizes.before_frame(targets, match)
            targets = size_learning.with_track_size(targets, track_size)
        size = frame_cues.size_cues(abl, cam, targets, calib)
        ground = None
        if abl.use_ground_contact:
            alpha, alpha_var = frame_cues.contact_gradient_prior(
                abl.gradient_feedback, self.config.gradient_sigma_rad, match
            )
            ground = frame_cues.ground_contact_cue(
                abl, cam, targets, size.bounds, alpha, alpha_var, theta_rad, jitter_rad, calib
            )
            if abl.occlusion_aware and targets.boxes_px.shape[0] > 1:
                size = frame_cues.occlusion_adjusted(abl, targets, size, ground)
        log_prior = self._log_prior(match, targets)
        odd = self._odd_check.carried(match, targets)  # the tracks' odd-object evidence
        fused = frame_cues.fuse_hypotheses(
            targets,
            size,
            ground,
            self._odd_check.prior(log_prior, odd),
            self._mode_spreads if targets.classes.type_log_weight is None else self._type_spreads,
            abl.consistency_gate_sigma,
            size.height.camera_lever if abl.road_bend_sigma else None,
        )
        distance = self._filter_distance(match, fused.measurement, frame.R_world_cam)
        odd = self._odd_check.after_frame(odd, fused.odd_size_prob, match, distance)
        gradient = frame_cues.target_gradient(
            self.config.gradient_sigma_rad,
            cam,
            targets,
            match,
            fused,
            distance.rows,
            theta_rad,
            jitter_rad,
            calib.height_m,
        )
        state = FrameState(targets, match, size, fused, distance)
        size_rows = None
        if self._sizes is not None and track_size is not None:  # this frame's evidence
            size_rows = self._sizes.after_frame(state, track_size)
        uid = self._update_tracks(
            targets, match, fused, distance, gradient, frame.R_world_cam, size_rows, odd
        )
        if self._recorder is not None:
            self._recorder.record(good, state, gradient, uid)
        if abl.self_calibrate and math.isfinite(frame.theta_rad):  # not a θ it assumed
            shape_gap = frame_cues.shape_gap(targets, size)
            self._feed_selfcal(targets, shape_gap, fused, gradient, uid, theta_rad, calib)
        out = frame_cues.box_estimates(
            cam,
            self._yaw,
            targets,
            fused,
            distance,
            gradient,
            uid,
            theta_rad,
            calib,
            self.config.gradient_sigma_rad,
        )
        if size_rows is not None:
            out = out._replace(**size_learning.size_columns(size_rows, targets.classes.height_m))
        return out

    # -- the steps of a frame, in order -----------------------------------------------------

    def _frame_targets(
        self, frame: FrameInput, good: NDArray[np.intp], cut_edges: NDArray[np.bool_]
    ) -> FrameTargets:
        """The usable boxes ``good``, their class constants and border cuts (``cut_edges``)."""
        table = frame.boxes
        return FrameTargets(
            table.boxes[good],
            table.track_id[good],
            self._classes.gather(table.cls[good]),
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

    def _log_prior(self, match: TrackMatch, targets: FrameTargets) -> FloatArray:
        """``(n, K·modes)`` log prior of the hypotheses (headings × body-style modes, or
        headings × vehicle types when a target's class is generic)."""
        log_heading_prior = None
        if self.ablation.yaw_memory and match.continued_rows.size:
            log_heading_prior = frame_cues.carried_heading_prior(
                match, self._log_yaw_prior, self.ablation.yaw_memory_s
            )
        type_weight = targets.classes.type_log_weight
        if type_weight is not None:
            if log_heading_prior is None:
                log_heading_prior = np.broadcast_to(
                    self._log_yaw_prior, (match.rows.shape[0], self._yaw.size)
                )
            n_types = type_weight.shape[1]
            return np.tile(log_heading_prior, n_types) + np.repeat(
                type_weight, self._yaw.size, axis=1
            )
        if log_heading_prior is None:
            log_heading_prior = np.broadcast_to(
                self._log_yaw_prior, (match.rows.shape[0], self._yaw.size)
            )
        return np.tile(log_heading_prior, len(self._size_modes)) + self._log_mode

    def _filter_distance(
        self, match: TrackMatch, measurement: LogCue, R_now: FloatArray | None
    ) -> DistanceFilterResult:
        """:func:`~slopedist.estimators.ours.frame_cues.filter_distance`, with the depth change
        the camera's rotation ``R_now`` gives each continued track."""
        ratio = None
        if self.ablation.motion_model and match.continued_rows.size:
            ratio = self._continued_depth_ratios(match, R_now)
        return frame_cues.filter_distance(
            self.ablation, match, measurement, ratio, self._recorder is not None
        )

    def _continued_depth_ratios(self, match: TrackMatch, R_now: FloatArray | None) -> FloatArray:
        """``Z_now/Z_last`` of the continued tracks' box centres from the camera's rotation."""
        if match.depth_ratio is not None:
            return match.depth_ratio[match.continued_rows]
        cam = self.camera
        before = match.before
        return depth_ratios(before.last_box_px, cam.f, cam.c_x, cam.c_y, before.R_world_cam, R_now)

    def _update_tracks(
        self,
        targets: FrameTargets,
        match: TrackMatch,
        fused: FusedCues,
        distance: DistanceFilterResult,
        gradient: TargetGradient,
        R_now: FloatArray | None,
        size_rows: FloatArray | None = None,
        odd_evidence: FloatArray | None = None,
    ) -> NDArray[np.int64]:
        """Write this frame into the tracks (when any state is carried); the track uid of
        every target."""
        abl = self.ablation
        if not carries_state(self.config, abl):
            return self._new_uids(targets.boxes_px.shape[0])
        belief: FloatArray | None = None
        if abl.yaw_memory:  # the heading belief a track carries (only read with yaw_memory)
            belief = frame_cues.heading_belief(fused, abl.yaw_evidence_weight, self._yaw.size)
        return self._store(
            TrackUpdate(
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
        )

    def _feed_selfcal(
        self,
        targets: FrameTargets,
        shape_gap: FloatArray,
        fused: FusedCues,
        gradient: TargetGradient,
        uid: NDArray[np.int64],
        theta_rad: float,
        calib: CalibrationInUse,
    ) -> None:
        """Give the self-calibration the targets of tightly sized classes whose box is not cut
        by the top or bottom border: bottom rows, nearest-face size distances, shape gaps (of a
        frame with a measured θ only: the caller skips one without a rotation or with an
        odometry jump, whose resting θ is no measurement)."""
        cam, n = self.camera, uid.shape[0]
        classes = targets.classes
        usable = (classes.height_log_sigma <= SELFCAL_MAX_LOG_SIGMA) & ~classes.generic
        cuts = targets.border_cuts
        if cuts is not None:
            usable &= ~cuts.top & ~cuts.bottom
        theta_cfg = theta_rad - calib.horizon_offset_rad
        v_cfg = cam.c_y - cam.f * math.tan(theta_cfg)
        near = np.where(usable, gradient.size_distance_m - fused.half_extent_m, np.nan)
        self.selfcal.update(
            uid, targets.boxes_px[:, 3], np.full(n, v_cfg), np.full(n, theta_cfg), near, shape_gap
        )

    def _new_uids(self, k: int) -> NDArray[np.int64]:
        uid = np.arange(self._next_uid, self._next_uid + k)
        self._next_uid += k
        return uid

    # -- state handling ---------------------------------------------------------------------

    def _store(self, update: TrackUpdate) -> NDArray[np.int64]:
        """Write the updated states back; returns the track uid of every target."""
        tr = self.tracks
        rows = update.rows
        cont = rows >= 0
        uid = np.empty(rows.shape[0], np.int64)
        uid[cont] = tr.uid[rows[cont]]
        tr.write_continued(update, cont)
        new = ~cont
        if new.any():
            new_uid = self._new_uids(int(np.count_nonzero(new)))
            uid[new] = new_uid
            self.tracks = tr.with_started(update, new, new_uid, self._log_yaw_prior)
        return uid

    def _drop_stale(self, t: float) -> None:
        tr = self.tracks
        age = self.config.max_age_s + 1e-9
        if len(tr) and t - tr.last_time_s.min() > age:  # the oldest is stale
            self.tracks = tr.take(t - tr.last_time_s <= age)

    def _calibration_in_use(self) -> CalibrationInUse:
        if self.ablation.self_calibrate:
            cov = self.selfcal.covariance
            return CalibrationInUse(
                self.selfcal.horizon_offset_rad,
                math.sqrt(cov[0, 0]),
                self.selfcal.height_m,
                math.sqrt(cov[1, 1]),
            )
        return self._fixed_calib


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
