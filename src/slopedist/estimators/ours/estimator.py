"""``ours``: size and ground-contact cues fused per target, tracked over time, self-calibrating.

For every box and every heading hypothesis ψ the estimator computes

1. the **height cue** (:func:`~slopedist.estimators.ours.cues.height_cue`): distance from the box
   height and the class's height prior, exact for a 3D box (roof and footprint in perspective);
2. the **width cue** (:func:`~slopedist.estimators.ours.cues.width_cue`): distance from the box
   width, the class's width and length and ψ — a car seen at an angle shows its side, so the
   heading is a hypothesis, weighted by how well it reconciles width and height and by a prior
   that most traffic is aligned with the road;
3. the **ground-contact cue**: eq. 1 with the vanishing line of the ego gradient θ (eq. 4–5), as
   the paper, plus the target's own continuous road gradient α,

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
from slopedist.errors import ConfigurationError
from slopedist.estimators.base import (
    Estimator,
    FrameEstimates,
    FrameInput,
    ReferencePoint,
    unusable_box_reasons,
)
from slopedist.estimators.ours import cues
from slopedist.estimators.ours import filter as kf
from slopedist.estimators.ours.priors import (
    DimensionPrior,
    YawPrior,
    priors_for,
    yaw_grid,
    yaw_prior_weights,
)
from slopedist.estimators.ours.selfcal import Calibration, SelfCalConfig, SelfCalibrator
from slopedist.estimators.ours.tracking import (
    TrackArrays,
    associate,
    predicted_boxes,
    relative_rotations,
)

FloatArray = NDArray[np.float64]

EXTRA_COLUMNS = (
    "sigma_m", "distance_nearest_face_m", "speed_mps", "speed_sigma_mps", "ttc_s", "ttc_sigma_s",
    "target_gradient_rad", "target_gradient_sigma_rad", "yaw_rad", "distance_size_m",
    "distance_ground_contact_m", "track_uid", "calib_mount_angle_rad",
    "calib_mount_angle_sigma_rad", "calib_height_m", "calib_height_sigma_m",
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
    """Options of ``ours``. Defaults are physical priors, not fitted on evaluation data.

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
            ``adapt_box_noise``).
        adapt_box_noise: estimate the box-edge noise online from the second differences of the
            tracks' box edges (10 Hz tracks are smooth, so what is left is detector noise).
        theta_sigma_rad: per-frame jitter of the ego gradient's vanishing line.
        no_rotation_theta_sigma_rad: the same when the frame has no rotation (θ of a camera at
            rest is used then).
        gradient_sigma_rad: prior spread of a target's road gradient relative to the ego's.
        height_sigma_m: camera-height uncertainty when not self-calibrating.
        mount_sigma_rad: mount-angle uncertainty when not self-calibrating.
        rate_sigma_per_s: prior spread of the relative rate Ż/Z of a new track.
        yaw_prior: heading prior.
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
        truncation_factor: noise multiplier of a cue whose box edge touches the image border.
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
    box_sigma_px: float = 0.5
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
    priors: dict[str, DimensionPrior] | None = None
    selfcal: SelfCalConfig = field(default_factory=SelfCalConfig)

    def __post_init__(self) -> None:
        for name in ("box_sigma_px", "theta_sigma_rad", "no_rotation_theta_sigma_rad",
                     "gradient_sigma_rad", "height_sigma_m", "mount_sigma_rad",
                     "rate_sigma_per_s", "yaw_memory_s", "max_age_s", "gate_sigma",
                     "truncation_factor", "yaw_evidence_weight"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ConfigurationError(f"ours option {name} must be a finite number > 0, "
                                         f"got {value!r}")
        if not 0.0 <= self.min_iou <= 1.0:
            raise ConfigurationError(f"ours option min_iou must be in [0, 1], got {self.min_iou}")

    @property
    def tracking(self) -> bool:
        """Whether any state is carried from frame to frame (so boxes must be associated)."""
        return (self.motion_model or self.yaw_memory or self.gradient_feedback
                or self.adapt_box_noise)


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
                    f"(known: {', '.join(sorted(known))})")
            config = dataclasses.replace(config, **overrides)
        self.config = config
        grid = yaw_grid() if config.yaw_hypotheses else np.zeros(1)
        self._yaw = grid
        self._log_yaw_prior = np.log(yaw_prior_weights(grid, config.yaw_prior)) if grid.size > 1 \
            else np.zeros(1)
        self.selfcal = SelfCalibrator(camera.f, camera.mount_angle_rad, camera.height_m,
                                      config.selfcal)
        self._theta_rest = float(geo.ego_road_gradient(np.eye(3), np.eye(3),
                                                       camera.mount_angle_rad))
        self.reset()

    def reset(self) -> None:
        """Forget all tracks and the self-calibration (new sequence)."""
        self.tracks = TrackArrays.empty(self._yaw.size)
        self.selfcal.reset()
        self._next_uid = 0
        self._max_right = -math.inf
        self._max_bottom = -math.inf
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
        reasons = unusable_box_reasons(frame, needs_rotation=False)
        theta_in = float(frame.theta_rad)
        out = {k: np.full(n, np.nan) for k in ("distance", "theta_adj", "v", *EXTRA_COLUMNS)}
        calib = self._calibration_in_use()
        theta_ok = math.isfinite(theta_in)
        theta_f = (theta_in if theta_ok else self._theta_rest) + calib.delta
        jitter = (self.config.theta_sigma_rad if theta_ok
                  else self.config.no_rotation_theta_sigma_rad)
        good = np.flatnonzero(reasons == "")
        self._drop_stale(frame.timestamp_s)  # before association: the same whether or not the
        self._update_image_extent(boxes[good])  # caller also passes the frames with no boxes
        if good.size:
            for key, value in self._estimate_boxes(frame, good, theta_f, jitter, calib).items():
                out[key][good] = value
        if self.config.self_calibrate:
            cal = self.selfcal.calibration()
            out["calib_mount_angle_rad"][good] = cal.mount_angle_rad
            out["calib_mount_angle_sigma_rad"][good] = cal.mount_angle_sigma_rad
            out["calib_height_m"][good] = cal.height_m
            out["calib_height_sigma_m"][good] = cal.height_sigma_m
        v_frame = geo.vanishing_line_row(theta_f, self.camera.f, self.camera.c_y)
        delta_y = geo.target_offset_px(geo.box_centre_row(boxes), v_frame)
        return FrameEstimates(
            theta_rad=np.full(n, theta_in),
            theta_adj_rad=out["theta_adj"],
            delta_y_px=np.where(reasons == "", delta_y, np.nan),
            v_px=out["v"],
            distance_m=out["distance"],
            reason=reasons,
            reference=np.full(n, ReferencePoint.CENTRE.value, dtype=object),
            extra={k: out[k] for k in EXTRA_COLUMNS},
        )

    def _estimate_boxes(self, frame: FrameInput, good: NDArray[np.intp], theta_f: float,
                        jitter_rad: float, calib: _CalibInUse) -> dict[str, FloatArray]:
        """All outputs for the usable boxes ``good`` of ``frame`` (and the state updates)."""
        cfg = self.config
        cam = self.camera
        f = cam.f
        t = frame.timestamp_s
        B = frame.boxes.boxes[good]
        pri = priors_for(frame.boxes.cls[good], cfg.priors)
        n = B.shape[0]
        psi = self._yaw[None, :]
        H, W, L = pri.height_m[:, None], pri.width_m[:, None], pri.length_m[:, None]
        h = calib.height
        trunc_lr, trunc_top, trunc_bottom = self._truncation(B)
        infl = cfg.truncation_factor ** 2
        cos2 = math.cos(theta_f) ** 2
        sigma_px = self.box_sigma_px

        # --- size cues per (target, heading hypothesis) -----------------------------------
        e = cues.depth_half_extent(psi, W, L)
        var_e = 0.25 * ((np.abs(np.cos(psi)) * pri.length_sigma_m[:, None]) ** 2
                        + (np.abs(np.sin(psi)) * pri.width_sigma_m[:, None]) ** 2)
        z_h, dz_dD, dz_dH, dz_de, dz_dh = cues.height_cue(B[:, 1:2], B[:, 3:4], f, h, H, e)
        y_h = np.log(z_h)
        c_h = dz_dH * H / z_h
        r_h_white = 2.0 * (dz_dD * sigma_px / z_h) ** 2
        r_h_other = (dz_de ** 2 * var_e + (dz_dh * calib.sigma_height) ** 2) / z_h ** 2
        cut_h = (trunc_top | trunc_bottom)[:, None]
        r_h_white = np.where(cut_h, r_h_white * infl, r_h_white)
        r_h_other = np.where(cut_h, r_h_other * infl, r_h_other)
        if cfg.use_width:
            z_w, dz_dcol, share_w = cues.width_cue(B[:, 0:1], B[:, 2:3], f, cam.c_x, psi, W, L,
                                                   z_h, iterations=1)
            z_w = np.maximum(z_w, e + _MIN_NEAR_M)
            y_w = np.log(z_w)
            r_w_white = (dz_dcol * sigma_px / z_w) ** 2
            r_w_other = ((1.0 - share_w) * pri.log_sigma_l[:, None]) ** 2
            r_w_white = np.where(trunc_lr[:, None], r_w_white * infl, r_w_white)
        else:
            y_w = r_w_white = r_w_other = share_w = np.full(e.shape, np.nan)
        # a class mixes body styles: a vehicle is typical (the prior's σ) or, less often, of
        # atypical height (σ × atypical_height_factor); both are hypotheses next to the heading
        modes = [(1.0, 1.0 - cfg.atypical_height_weight)]
        if cfg.atypical_height_weight > 0:
            modes.append((cfg.atypical_height_factor, cfg.atypical_height_weight))
        size = _concat_cues([cues.fuse_size_cues(
            y_h, r_h_white, r_h_other, c_h, y_w, r_w_white, r_w_other, share_w,
            k * pri.log_sigma_h[:, None], pri.log_sigma_w[:, None], pri.corr_hw[:, None])
            for k, _ in modes])
        n_modes = len(modes)
        log_mode = np.repeat(np.log([p for _, p in modes]), e.shape[1])
        e_all = np.tile(e, n_modes)

        # --- what the tracks carry --------------------------------------------------------
        R_now = frame.R_world_cam
        tr = self.tracks
        R_rel = relative_rotations(tr.R_last, R_now)
        pred_boxes, turned = predicted_boxes(tr, t, R_rel, f, cam.c_x, cam.c_y)
        rows = (associate(tr, B, frame.boxes.track_id[good], cfg.min_iou, pred_boxes)
                if cfg.tracking else np.full(n, -1, np.int64))
        old = rows >= 0
        r_old = rows[old]
        if cfg.adapt_box_noise and r_old.size:
            self._learn_box_noise(B[old] - pred_boxes[r_old], r_old, t)
        dt = np.where(old, t - self.tracks.last_t[np.maximum(rows, 0)] if len(self.tracks)
                      else 0.0, 0.0)
        log_pi = np.broadcast_to(self._log_yaw_prior, e.shape).copy()
        if cfg.yaw_memory and r_old.size:
            mix = 1.0 - np.exp(-dt[old] / cfg.yaw_memory_s)
            belief = ((1.0 - mix[:, None]) * np.exp(self.tracks.log_w[r_old])
                      + mix[:, None] * np.exp(self._log_yaw_prior))
            log_pi[old] = np.log(np.maximum(belief, 1e-300))
        grad_m = np.zeros(n)
        grad_v = np.full(n, np.inf)
        grad_o = np.zeros(n)
        if r_old.size:
            tr = self.tracks
            grad_m[old] = tr.grad_mean[r_old]
            grad_v[old] = tr.grad_var[r_old] + cfg.process.gradient_rad ** 2 * dt[old]  # predict
            grad_o[old] = tr.grad_var_other[r_old]
        if cfg.gradient_feedback:
            alpha, alpha_var = _shrink_to_prior(grad_m, grad_v + grad_o, cfg.gradient_sigma_rad)
        else:
            alpha, alpha_var = np.zeros(n), np.full(n, cfg.gradient_sigma_rad ** 2)

        # --- ground-contact cue and fusion ---------------------------------------------------
        v_frame = cam.c_y - f * math.tan(theta_f)
        if cfg.use_ground_contact:
            v_target = cam.c_y - f * np.tan(theta_f + alpha)
            row_white = sigma_px ** 2 + (f * jitter_rad / cos2) ** 2
            row_other = (f / cos2) ** 2 * (alpha_var + calib.sigma_delta ** 2)
            gc = cues.ground_contact_log_cue(B[:, 3:4], v_target[:, None], f, h, e_all,
                                             row_white, row_other[:, None], calib.sigma_height,
                                             np.sqrt(np.tile(var_e, n_modes)))
            gc = _inflate(gc, trunc_bottom[:, None], infl)
            fused = cues.fuse_log_cues(size, gc)
        else:
            fused = size
        log_prior_all = np.tile(log_pi, n_modes) + log_mode
        meas, w_all = cues.collapse_hypotheses(fused, log_prior_all + fused.loglik)
        size_c, _ = cues.collapse_hypotheses(size, np.log(np.maximum(w_all, 1e-300)))
        e_mean = np.sum(w_all * e_all, axis=1)
        w = w_all.reshape(n, n_modes, -1).sum(axis=1)  # heading weights

        # --- distance filter --------------------------------------------------------------------
        x = np.stack([meas.mean, np.zeros(n)], axis=1)
        P = np.zeros((n, 2, 2))
        P[:, 0, 0] = meas.var_white
        P[:, 1, 1] = cfg.rate_sigma_per_s ** 2
        continued = np.zeros(n, dtype=bool)
        if cfg.motion_model and r_old.size:
            x_old = self.tracks.x[r_old].copy()
            x_old[:, kf.IDX_LOG_Z] += _turned_depth_log_ratio(
                self.tracks.last_box[r_old], R_rel[r_old], f, cam.c_x, cam.c_y)
            xp, Pp = kf.cv_predict(x_old, self.tracks.P[r_old], dt[old], cfg.process.accel_mps2)
            xu, Pu, _ = kf.cv_update(xp, Pp, meas.mean[old], meas.var_white[old])
            same = ((meas.mean[old] - xp[:, 0]) ** 2
                    <= cfg.gate_sigma ** 2 * (Pp[:, 0, 0] + meas.var[old]))
            idx = np.flatnonzero(old)[same]
            x[idx], P[idx] = xu[same], Pu[same]
            continued[idx] = True
            gone = np.flatnonzero(old)[~same]
            rows[gone] = -1  # another vehicle took this track's id or place: start afresh
        var_other = np.maximum(meas.var - meas.var_white, 0.0)
        dist, sigma = kf.distance_moments(x, P, var_other)
        speed, speed_sd = kf.speed_moments(x, P)
        ttc, ttc_sd = kf.ttc_moments(x, P)

        # --- continuous target gradient from Δy and the size distance ----------------------
        z_size = np.exp(size_c.mean)
        delta_y = geo.box_centre_row(B) - v_frame
        a_obs = cues.target_gradient(delta_y, z_size, f, h, pri.height_m, e_mean)
        flat = cues.expected_centre_offset_px(z_size, f, h, pri.height_m, e_mean)
        a_white = ((flat / f) ** 2 * size_c.var_white
                   + (sigma_px ** 2 + (f * jitter_rad) ** 2) / f ** 2)
        a_other = ((flat / f) ** 2 * np.maximum(size_c.var - size_c.var_white, 0.0)
                   + (0.5 * pri.height_sigma_m / z_size) ** 2)
        fresh = rows < 0
        g_mean, g_var = kf.random_walk_update(  # grad_v is already predicted to now
            np.where(fresh, 0.0, grad_m), np.where(fresh, 1e6, np.minimum(grad_v, 1e6)), 0.0,
            0.0, a_obs, a_white)
        alpha_out, alpha_out_var = _shrink_to_prior(g_mean, g_var + a_other,
                                                    cfg.gradient_sigma_rad)

        belief = log_prior_all + cfg.yaw_evidence_weight * fused.loglik  # tempered: frames
        belief = np.logaddexp.reduce(belief.reshape(n, n_modes, -1), axis=1)  # correlate
        belief -= np.logaddexp.reduce(belief, axis=1, keepdims=True)
        uid = self._store(rows, frame.boxes.track_id[good], x, P, belief, g_mean, g_var, a_other,
                          B, t, R_now, turned)
        if cfg.self_calibrate:
            usable = (pri.log_sigma_h <= SELFCAL_MAX_LOG_SIGMA) & ~trunc_top & ~trunc_bottom
            theta_cfg = theta_f - calib.delta
            v_cfg = cam.c_y - f * math.tan(theta_cfg)
            near = np.where(usable, z_size - e_mean, np.nan)
            self.selfcal.update(uid, B[:, 3], np.full(n, v_cfg), np.full(n, theta_cfg), near)
        moving = continued & cfg.motion_model
        gc_plain = cues.ground_contact_cue(B[:, 3], v_frame, f, h, e_mean)
        return {
            "distance": dist, "sigma_m": sigma, "distance_nearest_face_m": dist - e_mean,
            "speed_mps": np.where(moving, speed, np.nan),
            "speed_sigma_mps": np.where(moving, speed_sd, np.nan),
            "ttc_s": np.where(moving, ttc, np.nan), "ttc_sigma_s": np.where(moving, ttc_sd, np.nan),
            "target_gradient_rad": alpha_out,
            "target_gradient_sigma_rad": np.sqrt(alpha_out_var),
            "yaw_rad": self._yaw[np.argmax(w, axis=1)],
            "distance_size_m": z_size,
            "distance_ground_contact_m": gc_plain,
            "track_uid": uid.astype(float),
            "theta_adj": theta_f + alpha_out,
            "v": cam.c_y - f * np.tan(theta_f + alpha_out),
        }

    # -- state handling ---------------------------------------------------------------------

    def _store(self, rows: NDArray[np.int64], ext_ids: NDArray[np.int64], x: FloatArray,
               P: FloatArray, log_w: FloatArray, g_mean: FloatArray, g_var: FloatArray,
               g_other: FloatArray, boxes: FloatArray, t: float,
               R_now: NDArray[np.float64] | None, turned: FloatArray) -> NDArray[np.int64]:
        """Write the updated states back; returns the track uid of every target.

        A new track that carries a box track id replaces any live track with that id (its
        vehicle failed the gate); a second box with an id already continued in this frame gets
        an id-less track.
        """
        tr = self.tracks
        n = rows.shape[0]
        uid = np.empty(n, np.int64)
        cont = rows >= 0
        r = rows[cont]
        if r.size:
            tr.x[r], tr.P[r], tr.log_w[r] = x[cont], P[cont], log_w[cont]
            tr.grad_mean[r], tr.grad_var[r], tr.grad_var_other[r] = (
                g_mean[cont], g_var[cont], g_other[cont])
            dt = np.maximum(t - tr.last_t[r], 1e-6)
            tr.box_vel[r] = (boxes[cont] - turned[r]) / dt[:, None]
            tr.prev_t[r] = tr.last_t[r]
            tr.last_t[r], tr.last_box[r] = t, boxes[cont]
            tr.R_last[r] = np.eye(3) if R_now is None else R_now
            tr.n_obs[r] += 1
            uid[cont] = tr.uid[r]
        new = ~cont
        k = int(new.sum())
        if k:
            new_uid = np.arange(self._next_uid, self._next_uid + k)
            self._next_uid += k
            uid[new] = new_uid
            if self.config.tracking:
                ext = ext_ids[new].copy()
                ext[np.isin(ext, tr.ext_id[r])] = -1
                _, first = np.unique(ext, return_index=True)
                dup = np.ones(k, dtype=bool)
                dup[first] = False
                ext[dup] = -1
                replaced = np.isin(tr.ext_id, ext[ext >= 0])
                add = TrackArrays(new_uid, ext, x[new], P[new], log_w[new], g_mean[new],
                                  g_var[new], g_other[new], np.full(k, t), boxes[new],
                                  np.full(k, np.nan), np.full((k, 4), np.nan),
                                  np.broadcast_to(np.eye(3) if R_now is None else R_now,
                                                  (k, 3, 3)).copy(),
                                  np.ones(k, np.int64))
                self.tracks = tr.keep(~replaced).concat(add)
        return uid

    def _learn_box_noise(self, miss: FloatArray, rows: NDArray[np.int64], t: float) -> None:
        """Pool the misses of the constant-velocity box predictions of tracks updated at an even
        pace (``miss`` = box − predicted box, pixels): a second difference, variance 6σ²."""
        tr = self.tracks
        dt1 = t - tr.last_t[rows]
        dt0 = tr.last_t[rows] - tr.prev_t[rows]
        even = np.isfinite(dt0) & (np.abs(dt1 - dt0) <= 0.2 * dt0) & np.all(
            np.isfinite(tr.box_vel[rows]), axis=1)
        if not np.any(even):
            return
        d2 = miss[even]
        cap = 4.0 * math.sqrt(6.0) * self.box_sigma_px  # an id switch or a jump is not noise
        self._d2_sum += float(np.sum(np.minimum(d2 * d2, cap * cap)))
        self._d2_count += int(d2.size)

    def _drop_stale(self, t: float) -> None:
        tr = self.tracks
        if len(tr):
            self.tracks = tr.keep(t - tr.last_t <= self.config.max_age_s + 1e-9)

    # -- calibration and image extent -------------------------------------------------------

    def _calibration_in_use(self) -> _CalibInUse:
        cfg = self.config
        if cfg.self_calibrate:
            cov = self.selfcal.covariance
            return _CalibInUse(self.selfcal.horizon_offset_rad, math.sqrt(cov[0, 0]),
                               self.selfcal.height_m, math.sqrt(cov[1, 1]))
        return _CalibInUse(0.0, cfg.mount_sigma_rad, self.camera.height_m, cfg.height_sigma_m)

    def _update_image_extent(self, boxes: FloatArray) -> None:
        if boxes.size:
            self._max_right = max(self._max_right, float(boxes[:, 2].max()))
            self._max_bottom = max(self._max_bottom, float(boxes[:, 3].max()))

    def _truncation(self, boxes: FloatArray) -> tuple[NDArray[np.bool_], ...]:
        """Boxes touching the image border: (left or right, top, bottom) flags.

        The image size is the camera's when known; otherwise the largest right/bottom edge seen
        so far stands for the border once it lies beyond twice the principal point.
        """
        cam = self.camera
        right = (cam.image_width - 1.0 if cam.image_width
                 else (self._max_right if self._max_right >= 2 * cam.c_x else math.inf))
        bottom = (cam.image_height - 1.0 if cam.image_height
                  else (self._max_bottom if self._max_bottom >= 2 * cam.c_y else math.inf))
        lr = (boxes[:, 0] <= 0.5) | (boxes[:, 2] >= right - 0.5)
        return lr, boxes[:, 1] <= 0.5, boxes[:, 3] >= bottom - 0.5


@dataclass(frozen=True)
class _CalibInUse:
    delta: float
    sigma_delta: float
    height: float
    sigma_height: float


def _shrink_to_prior(mean: FloatArray, var: FloatArray, prior_sigma: float
                     ) -> tuple[FloatArray, FloatArray]:
    """Combine an estimate (mean, var; var may be inf) with a zero-mean prior of spread
    ``prior_sigma``: the posterior mean and variance."""
    s2 = prior_sigma * prior_sigma
    finite = np.isfinite(var)
    v = np.where(finite, var, 1.0)
    return (np.where(finite, mean * s2 / (s2 + v), 0.0),
            np.where(finite, s2 * v / (s2 + v), s2))


def _turned_depth_log_ratio(boxes: FloatArray, R_rel: FloatArray, f: float, c_x: float,
                            c_y: float) -> FloatArray:
    """log(Z_new/Z_old) of points seen at the boxes' centres when the camera turns by ``R_rel``
    (the ego's own rotation changes every target's depth, most for targets off to the side)."""
    ray = np.stack([(0.5 * (boxes[:, 0] + boxes[:, 2]) - c_x) / f,
                    (0.5 * (boxes[:, 1] + boxes[:, 3]) - c_y) / f, np.ones(len(boxes))], axis=1)
    z_new = np.einsum("tj,tj->t", R_rel[:, 2, :], ray)
    return np.log(np.maximum(z_new, 0.1))


def _concat_cues(parts: list[cues.LogCue]) -> cues.LogCue:
    """Log cues side by side along the hypothesis axis."""
    return cues.LogCue(*(np.concatenate([getattr(p, k) for p in parts], axis=-1)
                         for k in ("mean", "var", "var_white", "loglik")))


def _inflate(cue: cues.LogCue, mask: NDArray[np.bool_], factor: float) -> cues.LogCue:
    """The cue with its variances multiplied by ``factor`` where ``mask``."""
    return cues.LogCue(cue.mean, np.where(mask, cue.var * factor, cue.var),
                       np.where(mask, cue.var_white * factor, cue.var_white), cue.loglik)


class OursSelfCalibratingEstimator(OursEstimator):
    """``ours`` that also estimates the camera's mount angle θ0 and height online
    (``self_calibrate=True``): for a rough calibration."""

    name: ClassVar[str] = "ours-selfcal"

    def __init__(self, camera: Camera, config: OursConfig | None = None, **overrides: Any) -> None:
        if config is None:
            overrides.setdefault("self_calibrate", True)
        super().__init__(camera, config, **overrides)
