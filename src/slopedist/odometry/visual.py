"""Built-in monocular visual odometry on OpenCV, tuned for the rotation over the look-back.

The ego gradient (DESIGN.md eq. 2–4) needs only ``ΔR_prevᵀ ΔR_curr``, the camera rotation between
the current frame and the frame one look-back (1 s) earlier. So instead of chaining frame-to-frame
rotations (whose errors add up over the ten steps of a second), each frame's rotation is estimated
*directly* against its look-back frame, from KLT tracks kept alive through that second:

1. Tracks: corners (Shi–Tomasi, detected on a half-resolution copy, away from existing tracks and
   from ``mask_boxes``) are followed frame to frame with pyramidal Lucas–Kanade, started from a
   constant-velocity prediction, each position then refined by an affine fit of the patch
   (:mod:`~slopedist.odometry.affine_refine`: the road near the camera stretches and shears from
   frame to frame, which biases the translational fit along the flow). Tracks that fail, leave
   the image, enter a masked box or are outliers of a fit are dropped; new corners refill the
   image.
2. Rotation: the correspondences between the look-back frame ``L`` and the current frame ``t``
   (tracks alive in both) give the relative pose by iteratively reweighted least squares started
   from the constant-angular-velocity prediction (:mod:`~slopedist.odometry.visual_fit` on
   :mod:`slopedist.odometry.twoview`): a
   rotation-only model when there is no parallax (standing car, only far points), else the
   5-degree-of-freedom essential matrix on the Sampson distance. OpenCV's USAC essential-matrix
   solver is the fallback when the local fit does not explain most tracks.
3. Output: ``R_world_cam(t) = R_world_cam(L) · R_Ltᵀ``, so a consumer that looks back to ``L``
   (same rule as :func:`~slopedist.odometry.base.lookback_indices`) gets the direct estimate
   exactly; chaining happens only in steps of one look-back. When too few tracks survive from
   ``L`` (a sharp turn), the oldest later frame with enough tracks bridges the gap.

States: the first frame with enough corners is the origin (identity, ``OK``); a frame whose
rotation cannot be estimated is ``LOST`` (tracking then continues from the last good frame, which
bridges dropped or blurred frames); when no good frame has been seen for ``max_bridge_s`` the
next frame with enough corners starts a new *segment* (its rotation continues from the last good
one, which assumes no rotation during the gap; :attr:`BuiltinVisualOdometry.segment` counts the
restarts). Before the first origin the state is ``NOT_INITIALISED``. An exposure jump (a tunnel,
a flash, auto-exposure) or a change of sharpness (a jolt, motion blur) is tracked through by
matching the frames' grey levels and sharpness (:mod:`~slopedist.odometry.image_stats`) before
Lucas–Kanade, which assumes both constant; a frame far blurrier than the last good one
(:data:`~slopedist.odometry.image_stats.MAX_BLUR_RATIO`) is ``LOST`` and bridged.

Frames wider than ``max_width_px`` are tracked scaled down (:mod:`.working_size`).
Memory is bounded: the tracks (``max_features``) and one look-back of frame records.

Convention: camera frame x right, y down, z forward; pixels, seconds, radians;
``R_world_cam`` camera-to-world relative to the origin frame.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.core.errors import DataMismatchError
from slopedist.odometry import image_stats
from slopedist.odometry import twoview as tv
from slopedist.odometry.affine_refine import refine_affine
from slopedist.odometry.base import TIME_EPS_S, OdometryResult, OdometryState
from slopedist.odometry.masks import (
    check_boxes,
    grown_boxes,
    half_size_corner_mask,
    inside_boxes,
)
from slopedist.odometry.point_map import PointNormaliser
from slopedist.odometry.visual_config import FitInfo, VisualOdometryConfig
from slopedist.odometry.visual_fit import TwoViewFitting
from slopedist.odometry.working_size import WorkingSize, check_gray_frame, check_principal_point

FloatArray = NDArray[np.float64]

MIN_FRAME_PX = 2
"""Frames (at the working size) narrower or lower than this have no half-size copy to find
corners in: they are never tracked (``not_initialised``)."""


@dataclass(frozen=True)
class _FrameRecord:
    """A good frame: its time, rotation and the tracks alive in it (ids sorted, pixels)."""

    timestamp_s: float
    R_world_cam: FloatArray
    ids: NDArray[np.int64]
    pts: NDArray[np.float32]


_Estimate = tuple[FloatArray, tv.TwoViewFit, NDArray[np.int64], _FrameRecord]
"""A rotation estimate: ``R_world_cam``, the fit, the track ids fitted, the reference frame."""


class BuiltinVisualOdometry(TwoViewFitting):
    """Rotation-only visual odometry from grey frames (see the module docstring).

    Example::

        vo = BuiltinVisualOdometry(camera)
        for t, image in frames:
            result = vo.process(image, t, mask_boxes=boxes_of_moving_vehicles)
            if result.state is OdometryState.OK:
                use(result.R_world_cam)
    """

    def __init__(self, camera: Camera, config: VisualOdometryConfig | None = None) -> None:
        self.camera = camera
        self.config = config or VisualOdometryConfig()
        self.normalise = PointNormaliser(camera.K)  # full-frame pixels → ideal camera
        self._f = camera.f  # focal length of the working frames (pixels), set by _set_work
        theta0 = camera.mount_angle_rad
        self._heading = np.array([0.0, -math.sin(theta0), math.cos(theta0)])
        c = self.config
        self._klt_criteria = (
            cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS,
            c.klt_iterations,
            0.01,
        )
        self.reset()

    # ------------------------------------------------------------------ public interface
    @property
    def segment(self) -> int:
        """Number of restarts after a loss; rotations of different segments are unrelated."""
        return self._segment

    @property
    def tracks(self) -> NDArray[np.float32]:
        """Full-frame pixel positions ``(N, 2)`` of the tracks alive in the last good frame."""
        return self._pts.copy() if self._work is None else self._work.to_full(self._pts)

    @property
    def history_frames(self) -> int:
        """Frame records kept for the look-back (bounded by one look-back of frames)."""
        return len(self._history)

    def reset(self) -> None:
        """Forget everything; the next frame may start a new sequence (timestamps restart)."""
        self._history: deque[_FrameRecord] = deque(maxlen=self.config.max_history_frames)
        self._prev_image: NDArray[np.uint8] | None = None
        self._prev_energy = 0.0  # gradient energy of the previous image
        self._prev_stats = (0.0, 0.0)  # grey-level mean and standard deviation of it
        # the last current frame converted to float32, reused when it is the next previous one
        self._float_source: NDArray[np.uint8] | None = None
        self._float_image = np.empty((0, 0), dtype=np.float32)
        self._ids = np.empty(0, dtype=np.int64)
        self._pts = np.empty((0, 2), dtype=np.float32)
        self._vel = np.empty((0, 2), dtype=np.float32)  # pixels per second
        self._next_id = 0
        self._omega = np.zeros(3)  # angular velocity, rotation vector per second (camera frame)
        self._moving = False  # True once a velocity prediction exists
        self._cov = np.zeros((3, 3))  # covariance of the last rotation w.r.t. its look-back
        self._t_last: dict[str, FloatArray] = {}  # last translation direction per fit kind
        self._usac_budget = 1  # global searches left for the current frame
        self._last_timestamp: float | None = None
        self._last_R: FloatArray | None = None
        self._segment = 0
        self.last_fit: FitInfo | None = None
        self._work: WorkingSize | None = None
        self._size_source = "the first frame"
        if self.camera.image_width is not None and self.camera.image_height is not None:
            self._set_work(self.camera.image_width, self.camera.image_height)
            self._size_source = "the camera calibration"

    def process(
        self,
        image_gray: NDArray[np.uint8],
        timestamp_s: float,
        mask_boxes: NDArray[np.float64] | None = None,
    ) -> OdometryResult:
        """Process the next frame.

        Args:
            image_gray: grey frame ``(H, W)`` uint8, the size of the camera's images.
            timestamp_s: seconds, strictly increasing from frame to frame.
            mask_boxes: ``(N, 4)`` boxes (left, top, right, bottom) in pixels of moving objects;
                no feature inside them is detected or used.

        Raises:
            DataMismatchError: a timestamp that does not increase, an image that is not grey
                uint8 or whose size differs from the camera's / the earlier frames'.
        """
        image = self._check_image(image_gray)
        t = self._check_timestamp(timestamp_s)
        assert self._work is not None
        boxes = self._work.boxes(check_boxes(mask_boxes))
        if min(image.shape) < MIN_FRAME_PX:  # every frame has this size: never initialised
            return OdometryResult(None, OdometryState.NOT_INITIALISED, 0, self._segment)
        if not self._history:
            return self._start(image, t, boxes)
        if t - self._history[-1].timestamp_s > self.config.max_bridge_s:
            return self._start(image, t, boxes)
        try:
            return self._track(image, t, boxes)
        except np.linalg.LinAlgError:  # a degenerate fit: this frame has no rotation
            return OdometryResult(None, OdometryState.LOST, 0, self._segment)

    # ------------------------------------------------------------------ input checks
    def _check_image(self, image_gray: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """The frame at the working size (:mod:`~slopedist.odometry.working_size`)."""
        image = check_gray_frame(image_gray)
        height, width = image.shape
        if self._work is None:
            check_principal_point(self.camera, width, height)
            self._set_work(width, height)
        assert self._work is not None
        if (width, height) != self._work.full_size:
            raise DataMismatchError(
                f"frame size {width}×{height} px differs from the "
                f"{'×'.join(map(str, self._work.full_size))} px of {self._size_source}"
            )
        return self._work.image(image)

    def _set_work(self, width: int, height: int) -> None:
        """Fix the full and working frame sizes and the working camera's intrinsics."""
        self._work = WorkingSize.choose(self.camera, width, height, self.config.max_width_px)
        self._f = self._work.camera.f

    def _check_timestamp(self, timestamp_s: float) -> float:
        t = float(timestamp_s)
        if not math.isfinite(t):
            raise DataMismatchError(f"frame timestamp must be finite, got {timestamp_s}")
        if self._last_timestamp is not None and t <= self._last_timestamp:
            raise DataMismatchError(
                f"frame timestamp {t} s does not follow the previous frame's "
                f"{self._last_timestamp} s (timestamps must increase)"
            )
        self._last_timestamp = t
        return t

    # ------------------------------------------------------------------ origin / restart
    def _start(self, image: NDArray[np.uint8], t: float, boxes: FloatArray) -> OdometryResult:
        """Make this frame the origin of a (new) segment if it has enough corners."""
        self._ids = np.empty(0, dtype=np.int64)
        self._pts = np.empty((0, 2), dtype=np.float32)
        self._vel = np.empty((0, 2), dtype=np.float32)
        small = image_stats.half_size(image)
        self._add_features(image, boxes, small)
        if len(self._ids) < self.config.min_inliers:
            state = OdometryState.NOT_INITIALISED if self._last_R is None else OdometryState.LOST
            return OdometryResult(None, state, 0, self._segment)
        if self._last_R is None:
            R = np.eye(3)
        else:  # restart after a loss: continue from the last known rotation
            R = self._last_R
            self._segment += 1
        self._history.clear()
        self._cov = np.zeros((3, 3))
        self._omega = np.zeros(3)
        self._moving = False
        self._commit(
            image,
            t,
            R,
            image_stats.gradient_energy(image, small=small),
            image_stats.grey_stats(image),
        )
        return OdometryResult(R.copy(), OdometryState.OK, 0, self._segment)

    # ------------------------------------------------------------------ tracking
    def _track(self, image: NDArray[np.uint8], t: float, boxes: FloatArray) -> OdometryResult:
        prev = self._history[-1]
        dt = t - prev.timestamp_s
        assert self._prev_image is not None
        if len(self._pts) == 0:
            return OdometryResult(None, OdometryState.LOST, 0, self._segment)
        self._usac_budget = 1
        small = image_stats.half_size(image)  # also where new corners are detected
        energy = image_stats.gradient_energy(image, small=small)
        if self._prev_energy > image_stats.MAX_BLUR_RATIO * energy:
            # so blurred that its rotation would be poor: bridge it from the last sharp frame
            return OdometryResult(None, OdometryState.LOST, 0, self._segment)
        # Lucas–Kanade assumes constant brightness: after an exposure jump (a tunnel,
        # auto-exposure, a flash) track into this frame with its grey levels mapped to the
        # previous frame's mean and spread; the raw frame is kept for the next step
        stats = image_stats.grey_stats(image)  # serve again as the next previous frame's
        jumped = image_stats.match_exposure(
            image,
            self._prev_image,
            image_stats.EXPOSURE_JUMP_LEVELS,
            image_stats=stats,
            reference_stats=self._prev_stats,
        )
        current = image if jumped is None else jumped
        # Lucas–Kanade also needs both frames equally sharp: when one is clearly blurrier (a
        # jolt, motion blur), blur the other to match (a symmetric blur moves no feature)
        previous = self._prev_image
        if energy > image_stats.SHARPNESS_RATIO * self._prev_energy:
            current = image_stats.blur_to_energy(current, self._prev_energy)
        elif self._prev_energy > image_stats.SHARPNESS_RATIO * energy:
            previous = image_stats.blur_to_energy(previous, energy)
        keep, pts, estimate = self._attempt(previous, current, boxes, t, dt)
        if estimate is None and jumped is None:
            # a smaller exposure change can still break the tracks: retry matched
            matched = image_stats.match_exposure(
                current,
                previous,
                image_stats.MIN_EXPOSURE_CHANGE,
                image_stats=stats if current is image else None,
                reference_stats=self._prev_stats if previous is self._prev_image else None,
            )
            if matched is not None:
                keep, pts, estimate = self._attempt(previous, matched, boxes, t, dt)
        if estimate is None:
            return OdometryResult(None, OdometryState.LOST, 0, self._segment)
        ids = self._ids[keep]
        vel = (pts - self._pts[keep]) / dt
        R_world_cam, cov, good, fit = self._verify(prev, keep, pts, estimate)
        ids, pts, vel = ids[good], pts[good], vel[good]
        self._cov = cov
        self._omega = tv.so3_log(prev.R_world_cam.T @ R_world_cam) / dt
        self._moving = True
        self._ids, self._pts, self._vel = ids, pts.astype(np.float32), vel.astype(np.float32)
        self._add_features(image, boxes, small)
        self._commit(image, t, R_world_cam, energy, stats)
        return OdometryResult(R_world_cam.copy(), OdometryState.OK, fit.n_inliers, self._segment)

    def _verify(
        self,
        prev: _FrameRecord,
        keep: NDArray[np.bool_],
        pts: NDArray[np.float32],
        estimate: _Estimate,
    ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_], tv.TwoViewFit]:
        """Check the fitted rotation frame to frame (tracks ``self._pts[keep]`` → ``pts``):
        the rotation (fused with the chained one when the fit reached further back), its
        covariance, the tracks kept (no outlier to either fit) and the fit."""
        c = self.config
        R_world_cam, fit, fit_ids, ref = estimate
        cov = tv.rotation_covariance(fit.information, R_world_cam.T @ ref.R_world_cam)
        good = ~np.isin(
            self._ids[keep], fit_ids[fit.residuals_px > c.outlier_px], assume_unique=True
        )
        # frame to frame: drop outliers among the young tracks too, and (when the direct fit
        # reached further back and the fusion is on) fuse the chained rotation
        direct_info = self.last_fit
        f2f = None
        if ref is not prev and c.fuse_frame_to_frame:
            f2f = self._fit(self._pts[keep], pts, R_world_cam.T @ prev.R_world_cam, "f2f")
            self.last_fit = direct_info
        if f2f is not None:
            good &= f2f.residuals_px <= c.outlier_px
            vote = prev.R_world_cam @ f2f.R.T
            step_cov = np.linalg.inv(f2f.information) + c.frame_to_frame_floor_rad**2 * np.eye(3)
            cov_vote = f2f.R @ (step_cov + self._cov) @ f2f.R.T
            R_world_cam, cov = tv.fuse_rotations(R_world_cam, cov, vote, cov_vote)
        else:
            x_prev = self.normalise(self._full(self._pts[keep]))
            x_cur = self.normalise(self._full(pts))
            r_f2f = tv.epipolar_residuals_px(
                R_world_cam.T @ prev.R_world_cam,
                x_prev,
                x_cur,
                self._f,
                c.inlier_threshold_px,
            )
            good &= r_f2f <= c.outlier_px
        return R_world_cam, cov, good, fit

    def _attempt(
        self,
        previous: NDArray[np.uint8],
        image: NDArray[np.uint8],
        boxes: FloatArray,
        t: float,
        dt: float,
    ) -> tuple[NDArray[np.bool_], NDArray[np.float32], _Estimate | None]:
        """Track from ``previous`` (the last good frame) into ``image`` from the velocity
        prediction (or, with no velocity yet, the global shift) and estimate the rotation; after
        a failed prediction (a jolt, a long gap) retry once from the global shift. Returns the
        kept-track mask, their positions and the estimate (None when both attempts fail)."""
        if self._moving:
            guess = self._pts + self._vel * dt
        else:  # no motion known yet (first step of a segment): global shift of the image
            guess = self._pts + image_stats.global_shift(previous, image)
        keep, pts = self._follow(previous, image, guess, boxes)
        estimate = self._estimate(self._ids[keep], pts, t)
        if estimate is None and self._moving:
            keep, pts = self._follow(
                previous, image, self._pts + image_stats.global_shift(previous, image), boxes
            )
            estimate = self._estimate(self._ids[keep], pts, t)
        return keep, pts, estimate

    def _follow(
        self,
        previous: NDArray[np.uint8],
        image: NDArray[np.uint8],
        guess: NDArray[np.floating],
        boxes: FloatArray,
    ) -> tuple[NDArray[np.bool_], NDArray[np.float32]]:
        """Track the current points into ``image`` by pyramidal Lucas–Kanade from ``guess``.

        Returns the mask of the points kept (tracked, similar patch, inside the image, outside
        the masked boxes) and their new positions.
        """
        c = self.config
        assert self._work is not None
        p1, status, err = cv2.calcOpticalFlowPyrLK(
            previous,
            image,
            self._pts.reshape(-1, 1, 2),
            np.asarray(guess, dtype=np.float32).reshape(-1, 1, 2),
            winSize=(c.klt_window_px, c.klt_window_px),
            maxLevel=c.klt_levels,
            criteria=self._klt_criteria,
            flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
        )
        p1 = np.asarray(p1, dtype=np.float32).reshape(-1, 2)
        tracked = (status.ravel() == 1) & (err.ravel() < c.klt_max_error)
        if c.affine_refinement:  # the patch's stretch and shear (the road near the camera)
            # not where the window reaches into a masked box: one rigid surface per window
            near = inside_boxes(p1, grown_boxes(boxes, 0.5 * c.klt_window_px + 1.0))
            refine = tracked & ~near
            prev_f = self._float_image if previous is self._float_source else None
            if prev_f is None or previous is image:
                prev_f = previous.astype(np.float32)
            cur_f = image.astype(np.float32)
            self._float_source, self._float_image = image, cur_f  # the next step's previous
            p1[refine] = refine_affine(prev_f, cur_f, self._pts[refine], p1[refine])[0]
        width, height = self._work.size
        margin = 0.5 * c.klt_window_px
        keep = (
            tracked
            & (p1[:, 0] >= margin)
            & (p1[:, 0] < width - margin)
            & (p1[:, 1] >= margin)
            & (p1[:, 1] < height - margin)
            & ~inside_boxes(p1, boxes)
        )
        return keep, p1[keep]

    def _lookback_position(self, t: float) -> int:
        """Index in the history of the look-back frame of time ``t`` (0 without enough history)."""
        cutoff = t - self.config.lookback_s + TIME_EPS_S
        k = 0
        for i, rec in enumerate(self._history):
            if rec.timestamp_s <= cutoff:
                k = i
            else:
                break
        return k

    def _estimate(
        self, ids: NDArray[np.int64], pts: NDArray[np.float32], t: float
    ) -> _Estimate | None:
        """Rotation of the current frame against its look-back frame (or the oldest usable)."""
        c = self.config
        self.last_fit = None
        if len(ids) < c.min_inliers:
            return None
        prev = self._history[-1]
        R_pred = prev.R_world_cam @ tv.so3_exp(self._omega * (t - prev.timestamp_s))
        newest = len(self._history) - 1
        candidates: list[int] = []
        for k in range(self._lookback_position(t), newest + 1):
            if np.count_nonzero(np.isin(self._history[k].ids, ids, assume_unique=True)) >= (
                c.min_inliers
            ):
                candidates.append(k)  # the oldest usable frame: the look-back if possible
                break
        if newest not in candidates:
            candidates.append(newest)  # fallback: the previous frame has the most tracks
        for k in candidates:
            ref = self._history[k]
            common, i_ref, i_cur = np.intersect1d(
                ref.ids, ids, assume_unique=True, return_indices=True
            )
            if len(common) < c.min_inliers:
                continue
            fit = self._fit(ref.pts[i_ref], pts[i_cur], R_pred.T @ ref.R_world_cam)
            if self.last_fit is not None:
                self.last_fit = replace(self.last_fit, interval_s=t - ref.timestamp_s)
            if fit is not None:
                return ref.R_world_cam @ fit.R.T, fit, common, ref
        return None

    # ------------------------------------------------------------------ bookkeeping
    def _commit(
        self,
        image: NDArray[np.uint8],
        t: float,
        R_world_cam: FloatArray,
        energy: float,
        stats: tuple[float, float],
    ) -> None:
        """Record a good frame; ``energy`` (:func:`gradient_energy`) and ``stats``
        (:func:`grey_stats`) are the image's, kept for the next frame's comparisons."""
        self._history.append(_FrameRecord(t, R_world_cam, self._ids.copy(), self._pts.copy()))
        cutoff = t - self.config.lookback_s + TIME_EPS_S
        while len(self._history) > 1 and self._history[1].timestamp_s <= cutoff:
            self._history.popleft()
        self._prev_image = image
        self._prev_energy = energy
        self._prev_stats = stats
        self._last_R = R_world_cam

    def _add_features(
        self, image: NDArray[np.uint8], boxes: FloatArray, small: NDArray[np.uint8]
    ) -> None:
        """Detect corners on ``small``, the half-resolution copy of ``image``
        (:func:`~slopedist.odometry.image_stats.half_size`), away from tracks and masked boxes."""
        c = self.config
        wanted = c.max_features - len(self._ids)
        if wanted < max(8, c.max_features // 10):
            return
        radius = max(1, round(0.5 * c.min_feature_distance_px))
        border = max(2, math.ceil(0.25 * c.klt_window_px) + 1)
        mask = half_size_corner_mask(small.shape, self._pts, boxes, radius, border)
        corners = cv2.goodFeaturesToTrack(
            small, wanted, c.corner_quality, radius, mask=mask, blockSize=3
        )
        if corners is None or len(corners) == 0:
            return
        new = corners.reshape(-1, 2).astype(np.float32) * 2.0 + 0.5
        n = len(new)
        new_ids = np.arange(self._next_id, self._next_id + n, dtype=np.int64)
        self._next_id += n
        vel0 = (np.median(self._vel, axis=0) if len(self._vel) else np.zeros(2)).astype(np.float32)
        self._ids = np.concatenate([self._ids, new_ids])
        self._pts = np.concatenate([self._pts, new])
        self._vel = np.concatenate([self._vel, np.tile(vel0, (n, 1))])
