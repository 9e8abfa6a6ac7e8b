"""``ours``: size and ground-contact cues fused per target, tracked over time, self-calibrating.

For every box and every heading hypothesis ψ the estimator computes

1. the **height cue** (:func:`~slopedist.estimators.ours.cues.height_cue`): distance from the box
   height and the class's height prior, exact for a 3D box (roof and footprint in perspective);
2. the **width cue** (:func:`~slopedist.estimators.ours.cues.width_cue`): distance from the box
   width, the class's width and length and ψ — a car seen at an angle shows its side, so the
   heading is a hypothesis, weighted by how well it reconciles width and height and by a prior
   that most traffic is aligned with the road;
3. the **ground-contact cue**: eq. 1 with the vanishing line of the ego gradient θ (eq. 4–5), as
   the paper, plus the target's own continuous road gradient α; a size cue whose box side
   lies on a nearer target's box and that says farther than the ground contact by more than
   noise explains is taken as cut short by occlusion (censored) and loses weight,

and fuses them by their propagated uncertainties in an extended Kalman filter per track whose
state is log-distance, relative rate, the vehicle's size deviation from its class prior and α
(:mod:`~slopedist.estimators.ours.filter`). The distance reported is to the vehicle's centre
(KITTI's z); ``distance_nearest_face_m`` is the distance to its nearest face. The camera's mount
angle and height are re-estimated online from the targets
(:mod:`~slopedist.estimators.ours.selfcal`).

Everything is causal: the streaming pipeline and the batch one give identical numbers, and
:meth:`OursEstimator.reset` forgets all state.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from slopedist import geometry as geo
from slopedist.camera import Camera
from slopedist.detections.boxes import box_problems
from slopedist.errors import ConfigurationError
from slopedist.estimators.base import (
    Estimator,
    FrameEstimates,
    FrameInput,
    ReferencePoint,
)
from slopedist.estimators.ours import cues
from slopedist.estimators.ours import filter as kf
from slopedist.estimators.ours.cues import all_true, any_true
from slopedist.estimators.ours.priors import (
    DimensionPrior,
    YawPrior,
    prior_row,
    resolve_prior,
    yaw_grid,
    yaw_prior_weights,
)
from slopedist.estimators.ours.selfcal import Calibration, SelfCalConfig, SelfCalibrator
from slopedist.estimators.ours.tracking import (
    ROW_BOX_VEL,
    ROW_FILTER,
    ROW_GRAD_MEAN,
    ROW_GRAD_OTHER,
    ROW_GRAD_VAR,
    ROW_LAST_BOX,
    ROW_LAST_T,
    ROW_LOG_W,
    ROW_N_OBS,
    ROW_PREV_T,
    ROW_ROT,
    TrackArrays,
    associate,
    depth_ratios,
    moved_boxes,
    turn_boxes,
)

FloatArray = NDArray[np.float64]

EXTRA_COLUMNS = (
    "sigma_m",
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
    "track_uid",
    "calib_mount_angle_rad",
    "calib_mount_angle_sigma_rad",
    "calib_height_m",
    "calib_height_sigma_m",
)
"""Method-specific columns of ``ours`` (all float; NaN where not defined)."""

_BOX_NOISE_PRIOR_COUNT = 200
"""Weight (in edge samples) of the configured box noise in its online estimate."""

_MIN_NEAR_M = 0.5
"""Smallest distance to a target's nearest face the cues accept, metres."""

SELFCAL_MAX_LOG_SIGMA = 0.15
"""Classes whose height prior is looser than this (relative) do not feed the self-calibration."""


@dataclass(frozen=True)
class OursConfig:
    """Options of ``ours``.

    Defaults are physical priors set without looking at evaluation results, except
    ``yaw_prior`` and ``box_sigma_px``: those are fitted on the labels of the 13 shared KITTI
    tracking sequences (:func:`~slopedist.offline.ours_fitting.fit_parameters`: the
    distribution of the labels' headings; the spread of the labels' 2D box edges around their
    3D boxes' projection — never a distance error), and ``benchmarks/ours_kitti.py`` reports the
    figures with each sequence scored under the fit on the other twelve.

    The switches turn parts off for the ablation in ``benchmarks/ours_kitti.py``.

    Attributes:
        use_width: use the box-width cue.
        yaw_hypotheses: consider headings other than ψ = 0.
        use_ground_contact: fuse the ground-contact cue.
        gradient_feedback: use each target's continuous road gradient α (estimated over its
            track from Δy and the size distance) in its ground-contact cue, instead of the prior
            α ~ N(0, ``gradient_sigma_rad``). α is estimated and reported either way.
        motion_model: filter the distance over time (constant velocity; speed and TTC).
        yaw_memory: carry each track's heading belief over frames (tempered evidence).
        self_calibrate: estimate θ0 and h online.
        box_sigma_px: pixel noise of a box edge (the prior of the online estimate when
            ``adapt_box_noise``); fitted, see above (0.31 px: the labels' boxes are their 3D
            boxes' projections, rounded; a 3D detector's boxes, e.g. PointRCNN's, are
            projections of its own 3D boxes, whose errors act through the size and heading
            priors rather than as pixel noise).
        adapt_box_noise: estimate the box-edge noise online from the second differences of the
            tracks' box edges (10 Hz tracks are smooth, so what is left is detector noise).
        theta_sigma_rad: per-frame jitter of the ego gradient's vanishing line.
        no_rotation_theta_sigma_rad: the same when the frame has no rotation (θ of a camera at
            rest is used then).
        gradient_sigma_rad: prior spread of a target's road gradient relative to the ego's.
        height_sigma_m: camera-height uncertainty when not self-calibrating.
        mount_sigma_rad: mount-angle uncertainty when not self-calibrating.
        rate_sigma_per_s: prior spread of the relative rate Ż/Z of a new track.
        yaw_prior: heading prior (fitted, see above).
        atypical_height_weight: prior probability that a vehicle's height is atypical for its
            class (a sports car, a pick-up or a box van labelled ``Car``); 0 turns it off.
        atypical_height_factor: how much wider the height spread of such a vehicle is.
        yaw_evidence_weight: weight (0–1] of one frame's heading evidence in a track's belief
            (consecutive frames are not independent evidence).
        yaw_memory_s: time constant with which a track's heading belief relaxes to the prior.
        process: process noise of the filters.
        max_age_s: a track unseen for longer is dropped.
        min_iou: IoU needed to continue an id-less track.
        gate_sigma: a box further than this many σ from its track's prediction starts a new track.
        truncation_factor: noise multiplier of a cue whose box edge touches the image border
            (it keeps a weak weight, so that a box cut on every side still gets a distance).
        censor_border_cuts: such a cue also bounds the distance from above (a box cut by the
            border is smaller than its vehicle, so its size cue says at least as far as the
            vehicle is, and a cut bottom hides the ground contact below the image):
            :func:`~slopedist.estimators.ours.cues.censor_upper`.
        occlusion_aware: a box with an edge on a nearer target's box (its bottom lower in the
            image) may show only part of its vehicle (a box drawn around what is visible): its
            width or height cue, if it says farther than the ground contact by more than their
            noise explains, gets that excess as extra variance
            (:func:`~slopedist.estimators.ours.cues.hidden_sides`,
            :func:`~slopedist.estimators.ours.cues.occlusion_log_var`), so the fusion leans on
            the ground contact (and the self-calibration, which uses the size cue).
        occlusion_gate_sigma: the outlier test of the occlusion check, in standard deviations
            (3, the usual test): of the two cues' noise for the excess, of the box-edge noise
            for an edge touching a nearer box.
        priors: class → dimension prior (None = the built-in table).
        selfcal: self-calibration priors and noise levels.
    """

    use_width: bool = True
    yaw_hypotheses: bool = True
    use_ground_contact: bool = True
    gradient_feedback: bool = False
    motion_model: bool = True
    yaw_memory: bool = False
    self_calibrate: bool = False
    box_sigma_px: float = 0.31
    adapt_box_noise: bool = False
    theta_sigma_rad: float = math.radians(0.3)
    no_rotation_theta_sigma_rad: float = math.radians(1.0)
    gradient_sigma_rad: float = math.radians(1.0)
    height_sigma_m: float = 0.03
    mount_sigma_rad: float = math.radians(0.2)
    rate_sigma_per_s: float = 0.5
    yaw_prior: YawPrior = field(default_factory=YawPrior)
    atypical_height_weight: float = 0.0
    atypical_height_factor: float = 3.0
    yaw_evidence_weight: float = 0.3
    yaw_memory_s: float = 2.0
    process: kf.ProcessNoise = field(default_factory=kf.ProcessNoise)
    max_age_s: float = 1.0
    min_iou: float = 0.3
    gate_sigma: float = 5.0
    truncation_factor: float = 10.0
    censor_border_cuts: bool = True
    occlusion_aware: bool = True
    occlusion_gate_sigma: float = 3.0
    priors: dict[str, DimensionPrior] | None = None
    selfcal: SelfCalConfig = field(default_factory=SelfCalConfig)

    def __post_init__(self) -> None:
        for name in (
            "box_sigma_px",
            "theta_sigma_rad",
            "no_rotation_theta_sigma_rad",
            "gradient_sigma_rad",
            "height_sigma_m",
            "mount_sigma_rad",
            "rate_sigma_per_s",
            "yaw_memory_s",
            "max_age_s",
            "gate_sigma",
            "truncation_factor",
            "yaw_evidence_weight",
            "occlusion_gate_sigma",
        ):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ConfigurationError(
                    f"ours option {name} must be a finite number > 0, got {value!r}"
                )
        if not 0.0 <= self.min_iou <= 1.0:
            raise ConfigurationError(f"ours option min_iou must be in [0, 1], got {self.min_iou}")

    @property
    def tracking(self) -> bool:
        """Whether any state is carried from frame to frame (so boxes must be associated)."""
        return (
            self.motion_model or self.yaw_memory or self.gradient_feedback or self.adapt_box_noise
        )


class OursEstimator(Estimator):
    """slopedist's own estimator; see the module docstring.

    Args:
        camera: intrinsics and the (possibly rough) mount.
        config: options (default :class:`OursConfig`).
        **overrides: individual :class:`OursConfig` fields, e.g. ``self_calibrate=False``.
    """

    name: ClassVar[str] = "ours"
    needs_rotation: ClassVar[bool] = True

    def __init__(self, camera: Camera, config: OursConfig | None = None, **overrides: Any) -> None:
        super().__init__(camera)
        config = config or OursConfig()
        if overrides:
            known = {f.name for f in dataclasses.fields(OursConfig)}
            unknown = sorted(set(overrides) - known)
            if unknown:
                raise ConfigurationError(
                    f"unknown option(s) for method 'ours': {', '.join(unknown)} "
                    f"(known: {', '.join(sorted(known))})"
                )
            config = dataclasses.replace(config, **overrides)
        self.config = config
        grid = yaw_grid() if config.yaw_hypotheses else np.zeros(1)
        self._yaw = grid
        self._log_yaw_prior = (
            np.log(yaw_prior_weights(grid, config.yaw_prior)) if grid.size > 1 else np.zeros(1)
        )
        self.selfcal = SelfCalibrator(
            camera.f, camera.mount_angle_rad, camera.height_m, config.selfcal
        )
        self._theta_rest = float(
            geo.ego_road_gradient(np.eye(3), np.eye(3), camera.mount_angle_rad)
        )
        self._classes = _ClassTable(config.priors, grid)
        modes = [(1.0, 1.0 - config.atypical_height_weight)]
        if config.atypical_height_weight > 0:
            modes.append((config.atypical_height_factor, config.atypical_height_weight))
        self._height_modes = [k for k, _ in modes]  # spread factor of each body-style mode
        self._log_mode = np.repeat(np.log([p for _, p in modes]), grid.size)
        self._log_prior_all = (np.tile(self._log_yaw_prior, len(modes)) + self._log_mode)[None, :]
        self._log_prior_block = np.repeat(self._log_prior_all, 16, axis=0)
        self._fixed_calib = _CalibInUse(
            0.0, config.mount_sigma_rad, camera.height_m, config.height_sigma_m
        )
        self._image_size_known = bool(camera.image_width and camera.image_height)
        self.reset()

    def _log_prior_rows(self, n: int) -> FloatArray:
        """The log prior of the hypotheses (headings × body-style modes) for ``n`` targets,
        ``(n, K·modes)`` (a slice of a cached block: no broadcasting per frame)."""
        block = self._log_prior_block
        if block.shape[0] < n:
            block = self._log_prior_block = np.repeat(self._log_prior_all, 2 * n, axis=0)
        return block[:n]

    def reset(self) -> None:
        """Forget all tracks and the self-calibration (new sequence)."""
        self.tracks = TrackArrays.empty(self._yaw.size)
        self.selfcal.reset()
        self._next_uid = 0
        self._max_right = -math.inf
        self._max_bottom = -math.inf
        self._border_high = np.full(4, math.inf)  # box edges at or beyond touch the border
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
        if not self.config.adapt_box_noise:
            return s0
        n0 = _BOX_NOISE_PRIOR_COUNT
        return math.sqrt((n0 * s0 * s0 + self._d2_sum / 6.0) / (n0 + self._d2_count))

    def calibration(self) -> Calibration:
        """The current self-calibration (the configured one, with its prior σ, before any data)."""
        return self.selfcal.calibration()

    # -- one frame -------------------------------------------------------------------------

    def estimate(self, frame: FrameInput) -> FrameEstimates:
        boxes = frame.boxes.boxes
        n = boxes.shape[0]
        # every box finite with right > left and bottom > top (the common case, checked cheaply)
        all_usable = np.count_nonzero(boxes[:, 2:] > boxes[:, :2]) == 2 * n and bool(
            np.isfinite(np.add.reduce(boxes, axis=None))
        )
        usable = (
            (
                np.isfinite(boxes).all(axis=1)
                & (boxes[:, 2] > boxes[:, 0])
                & (boxes[:, 3] > boxes[:, 1])
            )
            if not all_usable
            else None
        )
        # the reasons of unusable_box_reasons(frame, needs_rotation=False)
        reasons = _object_column("", n) if all_usable else box_problems(boxes)
        theta_in = float(frame.theta_rad)
        calib = self._calibration_in_use()
        theta_ok = math.isfinite(theta_in)
        theta_f = (theta_in if theta_ok else self._theta_rest) + calib.delta
        jitter = (
            self.config.theta_sigma_rad if theta_ok else self.config.no_rotation_theta_sigma_rad
        )
        good = np.arange(n) if usable is None else np.flatnonzero(usable)
        self._drop_stale(frame.timestamp_s)  # before association: the same whether or not the
        # caller also passes the frames with no boxes
        values = (
            self._estimate_boxes(frame, good, all_usable, theta_f, jitter, calib)
            if good.size
            else {}
        )
        if self.config.self_calibrate and good.size:
            cal = self.selfcal.calibration()
            values["calib_mount_angle_rad"] = _filled(good.size, cal.mount_angle_rad)
            values["calib_mount_angle_sigma_rad"] = _filled(good.size, cal.mount_angle_sigma_rad)
            values["calib_height_m"] = _filled(good.size, cal.height_m)
            values["calib_height_sigma_m"] = _filled(good.size, cal.height_sigma_m)
        out = _scatter(values, _OUTPUT_KEYS, good if not all_usable else None, n)
        return FrameEstimates(
            theta_rad=_filled(n, theta_in),
            theta_adj_rad=out["theta_adj"],
            delta_y_px=out["delta_y"],
            v_px=out["v"],
            distance_m=out["distance"],
            reason=reasons,
            reference=_object_column(ReferencePoint.CENTRE.value, n),
            extra={k: out[k] for k in EXTRA_COLUMNS},
        )

    def _estimate_boxes(
        self,
        frame: FrameInput,
        good: NDArray[np.intp],
        all_good: bool,
        theta_f: float,
        jitter_rad: float,
        calib: _CalibInUse,
    ) -> dict[str, FloatArray]:
        """All outputs for the usable boxes ``good`` of ``frame`` (and the state updates).

        Per (target, heading hypothesis) quantities are ``(n, K)`` arrays; the class constants
        come as such planes from one gather (:class:`_ClassTable`), so that the arithmetic of a
        frame's few targets never broadcasts.
        """
        cfg = self.config
        cam = self.camera
        f = cam.f
        t = frame.timestamp_s
        table = frame.boxes
        B = table.boxes if all_good else table.boxes[good]
        ids = table.track_id if all_good else table.track_id[good]
        cls = self._classes
        ci = cls.rows(table.cls if all_good else table.cls[good])
        pri = cls.scalars[ci]  # (n, 10), columns as _ClassTable.scalars
        G = cls.planes[:, ci]  # (_N_PLANES, n, K), planes as _ClassTable.planes
        n = B.shape[0]
        h = calib.height
        sigma_px = self.box_sigma_px
        cuts = self._truncation(B)  # None when no box touches the image border
        e, var_e = G[_P_E], G[_P_VAR_E]
        ls_h, ls_w = G[_P_LS_H], G[_P_LS_W]
        # the box edges as contiguous (n, K) planes
        left, top, right, bottom = np.repeat(B.T[:, :, None], e.shape[1], axis=2)

        # --- size cues per (target, heading hypothesis) -----------------------------------
        tall = pri[:, 0] > h  # the roof above the camera
        hc = cues.height_cue_log(
            bottom - top,
            f,
            h,
            sigma_px,
            calib.sigma_height,
            G[_P_H],
            e,
            var_e,
            tall[:, None] if any_true(tall) else None,
        )
        y_h, c_h, r_h_white, r_h_other = hc
        if cfg.use_width:
            wc = cues.width_cue_log(
                left,
                right,
                f,
                cam.c_x,
                sigma_px,
                G[_P_HWC],
                G[_P_HWS],
                G[_P_HLC],
                G[_P_HLS],
                G[_P_E_MIN],
            )
            y_w, share_w, r_w_white = wc.mean, wc.lever, wc.var_white
            r_w_other = (1.0 - share_w) * G[_P_LS_L]
            r_w_other *= r_w_other
        else:
            y_w = r_w_white = r_w_other = share_w = np.full(e.shape, np.nan)
        # a dimension cut by the image border keeps a weak Gaussian weight and bounds the
        # distance from above (applied to the fused cue below)
        bounds: list[tuple[FloatArray, FloatArray, NDArray[np.bool_]]] = []
        if cuts is not None:
            trunc_lr, trunc_top, trunc_bottom = cuts
            infl = cfg.truncation_factor**2
            cut_h = (trunc_top | trunc_bottom)[:, None]
            if any_true(cut_h):
                if cfg.censor_border_cuts:
                    bounds.append((y_h, (c_h * ls_h) ** 2 + r_h_white + r_h_other, cut_h))
                r_h_white = np.where(cut_h, r_h_white * infl, r_h_white)
                r_h_other = np.where(cut_h, r_h_other * infl, r_h_other)
            if cfg.use_width and any_true(trunc_lr):
                if cfg.censor_border_cuts:
                    bounds.append(
                        (y_w, (share_w * ls_w) ** 2 + r_w_white + r_w_other, trunc_lr[:, None])
                    )
                r_w_white = np.where(trunc_lr[:, None], r_w_white * infl, r_w_white)

        # --- what the tracks carry --------------------------------------------------------
        R_now = frame.R_world_cam
        tr = self.tracks
        pred_boxes = None
        # the boxes' image motion serves IoU association (id-less boxes) and the noise estimate
        box_motion = cfg.adapt_box_noise or any_true(ids < 0)
        if not len(tr):  # (no track is ever stored unless cfg.tracking)
            rows = np.full(n, -1, np.int64)
            turned, depth_ratio = tr.last_box, np.ones(0)
        elif box_motion:
            turned, depth_ratio = turn_boxes(tr.last_box, f, cam.c_x, cam.c_y, tr.R_last, R_now)
            pred_boxes = moved_boxes(tr, turned, t)
            rows = associate(tr, B, ids, cfg.min_iou, pred_boxes)
        else:
            rows = associate(tr, B, ids, cfg.min_iou)
            turned, depth_ratio = tr.last_box, None  # the depth ratios of the continued only
        old = rows >= 0
        every_old = all_true(old)
        r_old = rows if every_old else rows[old]
        any_old = r_old.size > 0
        S_old = tr.state[:, r_old]  # (a copy) the continued tracks' states, rows as ROW_*
        dt_old = t - S_old[ROW_LAST_T]
        grad_v_old = S_old[ROW_GRAD_VAR] + cfg.process.gradient_rad**2 * dt_old  # predict
        if cfg.adapt_box_noise and any_old and pred_boxes is not None:
            self._learn_box_noise(B[old] - pred_boxes[r_old], r_old, t)
        log_pi = None  # the heading prior of every target (else per target)
        if cfg.yaw_memory and any_old:
            mix = 1.0 - np.exp(-dt_old / cfg.yaw_memory_s)
            carried = (1.0 - mix[:, None]) * np.exp(S_old[ROW_LOG_W:].T) + mix[:, None] * np.exp(
                self._log_yaw_prior
            )
            log_pi = np.broadcast_to(self._log_yaw_prior[None, :], e.shape).copy()
            log_pi[old] = np.log(np.maximum(carried, 1e-300))
        if cfg.gradient_feedback:  # each target's gradient so far, predicted to now
            grad_m = np.zeros(n)
            grad_v = np.full(n, np.inf)
            grad_o = np.zeros(n)
            if any_old:
                grad_m[old] = S_old[ROW_GRAD_MEAN]
                grad_v[old] = grad_v_old
                grad_o[old] = S_old[ROW_GRAD_OTHER]
            a_m, a_v = _shrink_to_prior(grad_m, grad_v + grad_o, cfg.gradient_sigma_rad)
            alpha: FloatArray | float = a_m[:, None]
            alpha_var: FloatArray | float = a_v[:, None]
        else:  # the prior, the same for every target
            alpha, alpha_var = 0.0, cfg.gradient_sigma_rad**2

        # --- ground-contact cue and fusion ---------------------------------------------------
        v_frame = cam.c_y - f * math.tan(theta_f)
        if cfg.use_ground_contact:
            cos2 = math.cos(theta_f) ** 2
            v_target = cam.c_y - f * np.tan(theta_f + alpha) if cfg.gradient_feedback else v_frame
            row_white = sigma_px**2 + (f * jitter_rad / cos2) ** 2
            row_other = (f / cos2) ** 2 * (alpha_var + calib.sigma_delta**2)
            gc = cues.ground_contact_log_cue(
                bottom, v_target, f, h, e, row_white, row_other, calib.sigma_height, G[_P_SD_E]
            )
            if cuts is not None and any_true(cuts[2]):
                if cfg.censor_border_cuts:
                    bounds.append((gc.mean, gc.var, cuts[2][:, None]))
                gc = _inflate(gc, cuts[2][:, None], cfg.truncation_factor**2)
        if cfg.occlusion_aware and cfg.use_ground_contact and n > 1:
            # a size cue that says too far may show only part of a vehicle hidden behind a
            # nearer one (censored): which sides nearer boxes may cut, then the outlier test
            gate = cfg.occlusion_gate_sigma
            cut_w, cut_o = cues.hidden_sides(B, gate * sigma_px)
            if any_true(cut_o):
                r_h_other = r_h_other + cues.occlusion_log_var(
                    cues.unexplained_excess(
                        y_h, (c_h * ls_h) ** 2 + r_h_white + r_h_other, gc.mean, gc.var, gate
                    ),
                    cut_o[:, None],
                )
            if cfg.use_width and any_true(cut_w):
                r_w_other = r_w_other + cues.occlusion_log_var(
                    cues.unexplained_excess(
                        y_w, (share_w * ls_w) ** 2 + r_w_white + r_w_other, gc.mean, gc.var, gate
                    ),
                    cut_w[:, None],
                )
        # a class mixes body styles: a vehicle is typical (the prior's σ) or, less often, of
        # atypical height (σ × atypical_height_factor); both are hypotheses next to the heading
        n_modes = len(self._height_modes)
        size_modes = [
            cues.fuse_size_cues(
                y_h,
                r_h_white,
                r_h_other,
                c_h,
                y_w,
                r_w_white,
                r_w_other,
                share_w,
                ls_h if k == 1.0 else k * ls_h,
                ls_w,
                G[_P_CORR],
            )
            for k in self._height_modes
        ]
        size = size_modes[0] if n_modes == 1 else _concat_cues(size_modes)
        e_all = np.tile(e, n_modes) if n_modes > 1 else e
        if cfg.use_ground_contact:
            fused = cues.fuse_log_cues(size, gc if n_modes == 1 else _concat_cues([gc] * n_modes))
        else:
            fused = size
        for bound, bound_var, rows_cut in bounds:
            if n_modes > 1:
                bound, bound_var = np.tile(bound, n_modes), np.tile(bound_var, n_modes)
            fused = cues.censor_upper(fused, bound, bound_var, rows_cut)
        log_prior_all = (
            self._log_prior_rows(n) if log_pi is None else np.tile(log_pi, n_modes) + self._log_mode
        )
        meas, w_all = cues.collapse_hypotheses(fused, log_prior_all + fused.loglik)
        size_c = cues.mix_hypotheses(size, w_all)
        e_mean = np.add.reduce(w_all * e_all, axis=1)
        w = w_all.reshape(n, n_modes, -1).sum(axis=1) if n_modes > 1 else w_all  # headings

        # --- distance filter --------------------------------------------------------------------
        # state rows (ℓ, r, P_ℓℓ, P_ℓr, P_rr) of every target
        filt: FloatArray | None = None
        continued = np.zeros(n, dtype=bool)
        if cfg.motion_model and any_old:
            prior = S_old[ROW_FILTER]
            ratio = (
                depth_ratio[r_old]
                if depth_ratio is not None
                else depth_ratios(S_old[ROW_LAST_BOX], f, cam.c_x, cam.c_y, S_old[ROW_ROT], R_now)
            )
            prior[0] += np.log(np.maximum(ratio, 0.1))
            pred = kf.cv_predict_rows(prior, dt_old, cfg.process.accel_mps2)
            m_old, v_old, w_old = (
                (meas.mean, meas.var, meas.var_white)
                if every_old
                else (meas.mean[old], meas.var[old], meas.var_white[old])
            )
            upd, _ = kf.cv_update_rows(pred, m_old, w_old)
            dev = m_old - pred[0]
            same = dev * dev <= (pred[2] + v_old) * cfg.gate_sigma**2
            if every_old and all_true(same):  # every target continues its track
                filt = upd
                continued[:] = True
            else:
                filt = self._new_filter_rows(meas)
                idx = np.flatnonzero(old)
                filt[:, idx[same]] = upd[:, same]
                continued[idx[same]] = True
                rows[idx[~same]] = -1  # another vehicle took this track's id or place: afresh
        if filt is None:
            filt = self._new_filter_rows(meas)
        var_other = meas.var - meas.var_white  # ≥ 0: mix_hypotheses caps the white part
        dist, sigma = kf.distance_moments_rows(filt, var_other)
        if any_true(continued):
            speed, speed_sd, ttc, ttc_sd = kf.motion_moments_rows(filt)
            if not all_true(continued):
                speed, speed_sd, ttc, ttc_sd = (
                    np.where(continued, a, np.nan) for a in (speed, speed_sd, ttc, ttc_sd)
                )
        else:
            speed = speed_sd = ttc = ttc_sd = _filled(n, np.nan)

        # --- continuous target gradient from Δy and the size distance ----------------------
        z_size = np.exp(size_c.mean)
        delta_y = (B[:, 1] + B[:, 3]) * 0.5 - v_frame
        flat = cues.expected_centre_offset_px(z_size, f, h, pri[:, 0], e_mean)
        a_obs = np.arctan((flat - delta_y) * (1.0 / f))  # cues.target_gradient, flat once
        gain2 = flat * flat * (1.0 / (f * f))
        a_white = gain2 * size_c.var_white + (sigma_px**2 + (f * jitter_rad) ** 2) / f**2
        z_h_sd = pri[:, 3] * 0.5 / z_size
        a_other = gain2 * (size_c.var - size_c.var_white) + z_h_sd * z_h_sd
        g_mean, g_var = kf.random_walk_update(
            *_gradient_prior(rows, old, every_old, S_old[ROW_GRAD_MEAN], grad_v_old),
            0.0,
            0.0,
            a_obs,
            a_white,
        )
        alpha_out, alpha_out_var = _shrink_to_prior(g_mean, g_var + a_other, cfg.gradient_sigma_rad)

        belief: FloatArray | None = None
        if cfg.yaw_memory:  # the heading belief a track carries (only read with yaw_memory)
            belief = log_prior_all + cfg.yaw_evidence_weight * fused.loglik  # tempered: frames
            if n_modes > 1:  # correlate
                belief = np.logaddexp.reduce(belief.reshape(n, n_modes, -1), axis=1)
            belief = belief - np.logaddexp.reduce(belief, axis=1, keepdims=True)
        uid = (
            self._store(
                rows,
                ids,
                filt,
                belief,
                g_mean,
                g_var,
                a_other,
                B,
                t,
                R_now,
                turned if box_motion else None,
            )
            if cfg.tracking
            else self._new_uids(n)
        )
        if cfg.self_calibrate:
            usable = pri[:, 7] <= SELFCAL_MAX_LOG_SIGMA
            if cuts is not None:
                usable &= ~cuts[1] & ~cuts[2]
            theta_cfg = theta_f - calib.delta
            v_cfg = cam.c_y - f * math.tan(theta_cfg)
            near = np.where(usable, z_size - e_mean, np.nan)
            self.selfcal.update(uid, B[:, 3], _filled(n, v_cfg), _filled(n, theta_cfg), near)
        gc_plain = cues.ground_contact_cue(B[:, 3], v_frame, f, h, e_mean)
        return {
            "distance": dist,
            "sigma_m": sigma,
            "distance_nearest_face_m": dist - e_mean,
            "speed_mps": speed,
            "speed_sigma_mps": speed_sd,
            "ttc_s": ttc,
            "ttc_sigma_s": ttc_sd,
            "target_gradient_rad": alpha_out,
            "target_gradient_sigma_rad": np.sqrt(alpha_out_var),
            "yaw_rad": self._yaw[w.argmax(axis=1)],
            "distance_size_m": z_size,
            "distance_ground_contact_m": gc_plain,
            "track_uid": uid.astype(float),
            "theta_adj": theta_f + alpha_out,
            "delta_y": delta_y,
            "v": cam.c_y - f * np.tan(theta_f + alpha_out),
        }

    def _new_filter_rows(self, meas: cues.LogCue) -> FloatArray:
        """Filter state rows of tracks that start at this frame's measurement (its white part)
        with zero rate."""
        filt = np.zeros((5, meas.mean.shape[0]))
        filt[0] = meas.mean
        filt[2] = meas.var_white
        filt[4] = self.config.rate_sigma_per_s**2
        return filt

    def _new_uids(self, k: int) -> NDArray[np.int64]:
        uid = np.arange(self._next_uid, self._next_uid + k)
        self._next_uid += k
        return uid

    # -- state handling ---------------------------------------------------------------------

    def _store(
        self,
        rows: NDArray[np.int64],
        ext_ids: NDArray[np.int64],
        filt: FloatArray,
        log_w: FloatArray | None,
        g_mean: FloatArray,
        g_var: FloatArray,
        g_other: FloatArray,
        boxes: FloatArray,
        t: float,
        R_now: NDArray[np.float64] | None,
        turned: FloatArray | None,
    ) -> NDArray[np.int64]:
        """Write the updated states back; returns the track uid of every target.

        ``filt`` holds the distance filter's rows (:data:`ROW_FILTER`) of every target.
        ``log_w`` (the heading belief) is None when it is not kept: tracks then carry the prior.
        ``turned`` (the tracks' last boxes turned with the camera) is None when the box motion
        is not needed (only id-less tracks and the box-noise estimate use it). A new track that
        carries a box track id replaces any live track with that id (its vehicle failed the
        gate); a second box with an id already continued in this frame gets an id-less track.
        """
        tr = self.tracks
        n = rows.shape[0]
        cont = rows >= 0
        every = all_true(cont)
        r = rows if every else rows[cont]
        R = np.eye(3) if R_now is None else np.asarray(R_now, dtype=float)
        if every:
            uid = tr.uid[r]
        else:
            uid = np.empty(n, np.int64)
            uid[cont] = tr.uid[r]
        if r.size:

            def pick(a: np.ndarray) -> np.ndarray:
                return a if every else a[..., cont]

            S = tr.state[:, r]
            b = pick(boxes.T)
            S[ROW_FILTER] = pick(filt)
            S[ROW_GRAD_MEAN] = pick(g_mean)
            S[ROW_GRAD_VAR] = pick(g_var)
            S[ROW_GRAD_OTHER] = pick(g_other)
            if turned is not None:  # the box motion (else not needed: see _estimate_boxes)
                S[ROW_BOX_VEL] = (b - turned[r].T) / np.maximum(t - S[ROW_LAST_T], 1e-6)
            S[ROW_PREV_T] = S[ROW_LAST_T]
            S[ROW_LAST_T] = t
            S[ROW_LAST_BOX] = b
            S[ROW_ROT] = R.reshape(9, 1)
            S[ROW_N_OBS] += 1.0
            if log_w is not None:
                S[ROW_LOG_W:] = pick(log_w.T)
            tr.state[:, r] = S
        if every:
            return uid
        new = ~cont
        k = int(np.count_nonzero(new))
        new_uid = self._new_uids(k)
        uid[new] = new_uid
        ext = ext_ids[new].copy()
        taken = set(tr.ext_id[r].tolist())  # ids continued in this frame
        seen: set[int] = set()
        for i, e in enumerate(ext.tolist()):
            if e >= 0 and (e in taken or e in seen):
                ext[i] = -1
            seen.add(e)
        log_w_new = (
            np.broadcast_to(self._log_yaw_prior, (k, self._yaw.size))
            if log_w is None
            else log_w[new]
        )
        add = TrackArrays.start(
            new_uid,
            ext,
            filt[:, new],
            log_w_new,
            g_mean[new],
            g_var[new],
            g_other[new],
            t,
            boxes[new],
            R,
        )
        claimed = ext[ext >= 0]
        if claimed.size and len(tr):
            replaced = (tr.ext_id[:, None] == claimed[None, :]).any(axis=1)
            if any_true(replaced):
                tr = tr.keep(~replaced)
        self.tracks = tr.concat(add)
        return uid

    def _learn_box_noise(self, miss: FloatArray, rows: NDArray[np.int64], t: float) -> None:
        """Pool the misses of the constant-velocity box predictions of tracks updated at an even
        pace (``miss`` = box − predicted box, pixels): a second difference, variance 6σ²."""
        tr = self.tracks
        dt1 = t - tr.last_t[rows]
        dt0 = tr.last_t[rows] - tr.prev_t[rows]
        even = (
            np.isfinite(dt0)
            & (np.abs(dt1 - dt0) <= 0.2 * dt0)
            & np.all(np.isfinite(tr.box_vel[rows]), axis=1)
        )
        if not np.any(even):
            return
        d2 = miss[even]
        cap = 4.0 * math.sqrt(6.0) * self.box_sigma_px  # an id switch or a jump is not noise
        self._d2_sum += float(np.sum(np.minimum(d2 * d2, cap * cap)))
        self._d2_count += int(d2.size)

    def _drop_stale(self, t: float) -> None:
        tr = self.tracks
        age = self.config.max_age_s + 1e-9
        if len(tr) and t - np.minimum.reduce(tr.last_t) > age:  # the oldest is stale
            self.tracks = tr.keep(t - tr.last_t <= age)

    # -- calibration and image extent -------------------------------------------------------

    def _calibration_in_use(self) -> _CalibInUse:
        cfg = self.config
        if cfg.self_calibrate:
            cov = self.selfcal.covariance
            return _CalibInUse(
                self.selfcal.horizon_offset_rad,
                math.sqrt(cov[0, 0]),
                self.selfcal.height_m,
                math.sqrt(cov[1, 1]),
            )
        return self._fixed_calib

    def _truncation(self, boxes: FloatArray) -> tuple[NDArray[np.bool_], ...] | None:
        """Boxes touching the image border: (left or right, top, bottom) flags, or None when
        no box touches it.

        The image size is the camera's when known; otherwise the largest right/bottom edge seen
        so far (these boxes included) stands for the border once it lies beyond twice the
        principal point.
        """
        cam = self.camera
        if self._image_size_known:
            right, bottom = float(cam.image_width or 0) - 1.0, float(cam.image_height or 0) - 1.0
        else:
            seen_right, seen_bottom = np.maximum.reduce(boxes[:, 2:4], axis=0).tolist()
            self._max_right = max(self._max_right, seen_right)
            self._max_bottom = max(self._max_bottom, seen_bottom)
            right = (
                cam.image_width - 1.0
                if cam.image_width
                else (self._max_right if self._max_right >= 2 * cam.c_x else math.inf)
            )
            bottom = (
                cam.image_height - 1.0
                if cam.image_height
                else (self._max_bottom if self._max_bottom >= 2 * cam.c_y else math.inf)
            )
        if self._border_high[2] != right - 0.5 or self._border_high[3] != bottom - 0.5:
            self._border_high = np.array([math.inf, math.inf, right - 0.5, bottom - 0.5])
        cut = (boxes <= _BORDER_LOW) | (boxes >= self._border_high)
        if not any_true(cut):
            return None
        return cut[:, 0] | cut[:, 2], cut[:, 1], cut[:, 3]


_BORDER_LOW = np.array([0.5, 0.5, -math.inf, -math.inf])
"""A box edge at or below these (left, top) touches the image's left or top border."""

_OUTPUT_KEYS = ("distance", "theta_adj", "v", "delta_y", *EXTRA_COLUMNS)


_ABSENT: dict[tuple[str, ...], list[str]] = {}


def _scatter(
    values: dict[str, FloatArray], keys: tuple[str, ...], rows: NDArray[np.intp] | None, n: int
) -> dict[str, FloatArray]:
    """Per-box outputs of length ``n``: ``values`` (of the boxes ``rows``; all boxes when None)
    placed in NaN-filled columns; keys without values stay NaN."""
    if rows is None:
        have = tuple(values)
        missing = _ABSENT.get(have)
        if missing is None:
            missing = _ABSENT[have] = [k for k in keys if k not in values]
    else:
        missing = list(keys)
    nan = np.empty((len(missing), n))
    nan.fill(np.nan)
    out = dict(zip(missing, nan, strict=True))
    if rows is None:
        out.update(values)
    else:
        for k, v in values.items():
            out[k][rows] = v
    return out


class _ClassTable:
    """Class priors and their per-heading constants, one row per class name seen so far.

    The priors and the heading grid are fixed for an estimator, so each frame only gathers
    rows (``scalars``: H, W, L, σH, σW, σL, corr_hw, σH/H, σW/W, σL/L; ``planes``:
    ``(_N_PLANES, rows, K)`` per-hypothesis constants, see :data:`_P_E`) instead of recomputing
    them. Rows are gathered along the second axis, so that each plane of a frame is
    contiguous.
    """

    def __init__(self, priors: dict[str, DimensionPrior] | None, yaw_rad: FloatArray) -> None:
        self._priors = priors
        self._yaw = yaw_rad
        self._index: dict[object, int] = {}
        self._rows: list[tuple[float, ...]] = []
        self._build()

    def rows(self, classes: NDArray[np.object_]) -> NDArray[np.intp]:
        """Row of each class name (new names are added)."""
        index = self._index
        try:
            return np.array([index[c] for c in classes], dtype=np.intp)
        except KeyError:
            for c in classes:
                if c not in index:
                    index[c] = len(self._rows)
                    self._rows.append(prior_row(resolve_prior(c, self._priors)))
            self._build()
            return np.array([index[c] for c in classes], dtype=np.intp)

    def _build(self) -> None:
        a = np.asarray(self._rows, dtype=float).reshape(-1, 7)
        H, W, L, sH, sW, sL, corr = (a[:, k : k + 1] for k in range(7))
        psi = self._yaw[None, :]
        self.scalars = np.concatenate([a, sH / H, sW / W, sL / L], axis=1)
        e = cues.depth_half_extent(psi, W, L)
        var_e = 0.25 * ((np.abs(np.cos(psi)) * sL) ** 2 + (np.abs(np.sin(psi)) * sW) ** 2)
        planes = {
            _P_E: e,
            _P_VAR_E: var_e,
            _P_SD_E: np.sqrt(var_e),
            _P_E_MIN: e + _MIN_NEAR_M,  # the nearest face at least _MIN_NEAR_M away
            _P_H: H,
            _P_LS_H: sH / H,
            _P_LS_W: sW / W,
            _P_LS_L: sL / L,
            _P_CORR: corr,
            _P_HWC: 0.5 * W * np.cos(psi),
            _P_HWS: 0.5 * W * np.sin(psi),
            _P_HLC: 0.5 * L * np.cos(psi),
            _P_HLS: 0.5 * L * np.sin(psi),
        }
        self.planes = np.stack([np.broadcast_to(planes[k], e.shape) for k in range(_N_PLANES)])


(
    _P_E,
    _P_VAR_E,
    _P_SD_E,
    _P_E_MIN,
    _P_H,
    _P_LS_H,
    _P_LS_W,
    _P_LS_L,
    _P_CORR,
    _P_HWC,
    _P_HWS,
    _P_HLC,
    _P_HLS,
) = range(13)
_N_PLANES = 13
"""Planes of :attr:`_ClassTable.planes`: per class and heading hypothesis, the footprint's
half depth extent e (m), its variance and 1σ, the smallest centre distance accepted, the
class's H, σH/H, σW/W, σL/L and H–W correlation (repeated over the hypotheses), then
``W cos ψ/2``, ``W sin ψ/2``, ``L cos ψ/2``, ``L sin ψ/2`` (the width cue's terms, m)."""


@dataclass(frozen=True)
class _CalibInUse:
    delta: float
    sigma_delta: float
    height: float
    sigma_height: float


def _gradient_prior(
    rows: NDArray[np.int64],
    old: NDArray[np.bool_],
    every_old: bool,
    mean_old: FloatArray,
    var_old: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Mean and variance (rad, rad²) of each target's road gradient before this frame: its
    track's random walk predicted to now (``mean_old``, ``var_old``: of the targets ``old``
    that were associated with a track), or (0, 10⁶) for a target that starts a track (``rows``
    < 0, after the gate)."""
    kept = rows[old] >= 0 if not every_old else rows >= 0
    if every_old and all_true(kept):
        return mean_old, np.minimum(var_old, 1e6)
    mean, var = np.zeros(rows.shape), np.full(rows.shape, 1e6)
    idx = np.flatnonzero(old)[kept]
    mean[idx] = mean_old[kept]
    var[idx] = np.minimum(var_old[kept], 1e6)
    return mean, var


def _filled(n: int, value: float) -> FloatArray:
    """``np.full(n, value)``, cheaper for the few targets of a frame."""
    out = np.empty(n)
    out.fill(value)
    return out


_OBJECT_COLUMNS: dict[str, NDArray[np.object_]] = {}


def _object_column(value: str, n: int) -> NDArray[np.object_]:
    """A new object array of ``n`` copies of ``value`` (copied from a cached template)."""
    tmpl = _OBJECT_COLUMNS.get(value)
    if tmpl is None or tmpl.shape[0] < n:
        tmpl = _OBJECT_COLUMNS[value] = np.full(max(n, 64), value, dtype=object)
    return tmpl[:n].copy()


def _shrink_to_prior(
    mean: FloatArray, var: FloatArray, prior_sigma: float
) -> tuple[FloatArray, FloatArray]:
    """Combine an estimate (mean, var; var may be inf) with a zero-mean prior of spread
    ``prior_sigma``: the posterior mean and variance."""
    s2 = prior_sigma * prior_sigma
    finite = np.isfinite(var)
    if all_true(finite):
        return mean * s2 / (s2 + var), s2 * var / (s2 + var)
    v = np.where(finite, var, 1.0)
    return (np.where(finite, mean * s2 / (s2 + v), 0.0), np.where(finite, s2 * v / (s2 + v), s2))


def _concat_cues(parts: list[cues.LogCue]) -> cues.LogCue:
    """Log cues side by side along the hypothesis axis."""
    return cues.LogCue(
        *(
            np.concatenate([getattr(p, k) for p in parts], axis=-1)
            for k in ("mean", "var", "var_white", "loglik")
        )
    )


def _inflate(cue: cues.LogCue, mask: NDArray[np.bool_], factor: float) -> cues.LogCue:
    """The cue with its variances multiplied by ``factor`` where ``mask``."""
    return cues.LogCue(
        cue.mean,
        np.where(mask, cue.var * factor, cue.var),
        np.where(mask, cue.var_white * factor, cue.var_white),
        cue.loglik,
    )


class OursSelfCalibratingEstimator(OursEstimator):
    """``ours`` that also estimates the camera's mount angle θ0 and height online
    (``self_calibrate=True``): for a rough calibration."""

    name: ClassVar[str] = "ours-selfcal"

    def __init__(self, camera: Camera, config: OursConfig | None = None, **overrides: Any) -> None:
        if config is None:
            overrides.setdefault("self_calibrate", True)
        super().__init__(camera, config, **overrides)
