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
   from the constant-angular-velocity prediction (:mod:`slopedist.odometry.twoview`): a
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
restarts). Before the first origin the state is ``NOT_INITIALISED``. An exposure jump (a tunnel, a
flash, auto-exposure) is tracked through by mapping the new frame's grey levels to the previous
frame's mean and spread (:func:`match_exposure`) before Lucas–Kanade, which assumes constant
brightness; for the same reason, of two consecutive frames of clearly different sharpness (a jolt,
motion blur) the sharper is blurred to match (:func:`blur_to_energy`), and a frame far blurrier
than the last good one (:data:`MAX_BLUR_RATIO`) is ``LOST`` and bridged.

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
from numpy.typing import ArrayLike, NDArray

from slopedist.camera import Camera
from slopedist.errors import ConfigurationError, DataMismatchError
from slopedist.odometry import twoview as tv
from slopedist.odometry.affine_refine import refine_affine
from slopedist.odometry.base import LOOKBACK_S, TIME_EPS_S, OdometryResult, OdometryState

FloatArray = NDArray[np.float64]

USAC_MAX_ITERATIONS = 300
"""Iteration cap of OpenCV's USAC essential-matrix search (the fallback of a failed local fit)."""

MAX_WARM_START_DEG = 15.0
"""A previous translation direction warm-starts a fit only within this angle of the chord."""


@dataclass(frozen=True)
class VisualOdometryConfig:
    """Parameters of :class:`BuiltinVisualOdometry` (pixels are full-resolution pixels).

    Attributes:
        lookback_s: interval over which rotations are estimated directly, seconds; use the same
            look-back as the gradient (1 s).
        max_features: number of tracks kept alive.
        min_feature_distance_px: minimum distance between tracks, pixels.
        corner_quality: Shi–Tomasi quality level relative to the best corner of the frame.
        klt_window_px: side of the Lucas–Kanade window, pixels.
        klt_levels: pyramid levels above the full-resolution image.
        klt_iterations: maximum Lucas–Kanade iterations per level.
        klt_max_error: tracks whose mean absolute patch difference (grey levels) exceeds this
            are dropped.
        inlier_threshold_px: inlier threshold and robust-loss scale of the fits, pixels.
        outlier_px: tracks with a larger residual in a fit are dropped, pixels.
        min_inliers: fewer inliers than this make a frame ``LOST``.
        min_inlier_ratio: fits explaining a smaller fraction of the tracks are retried with
            OpenCV's USAC solver and, failing that, rejected.
        static_parallax_px: when the rotation-only model explains the tracks with a median
            residual below this (pixels), it is used instead of the essential matrix.
        max_bridge_s: after this long without a good frame, tracking restarts (new segment).
        max_history_frames: hard cap on the frame records kept for the look-back.
        fuse_frame_to_frame: when the direct fit reaches further back than the previous frame,
            fuse it with the rotation chained from the previous frame's (information-weighted:
            the chain helps where the direct fit is weak, e.g. yaw against a sideways
            translation with few tracks).
        frame_to_frame_floor_rad: standard deviation added per axis to every frame-to-frame
            step of the chain, radians: a fit between consecutive frames has systematic errors
            its residuals do not show (on the rendered hills about 0.005–0.01° per step, in
            pitch and roll, the same sign from step to step), which add up over the ten steps of
            a look-back; without this floor the fusion trusts the chain most where it is
            biased.
        affine_refinement: refine every Lucas–Kanade position with an affine fit of the patch
            (:mod:`~slopedist.odometry.affine_refine`; its stretch and shear bias the
            translational fit on the road near the camera).
    """

    lookback_s: float = LOOKBACK_S
    max_features: int = 250
    min_feature_distance_px: float = 12.0
    corner_quality: float = 0.01
    klt_window_px: int = 11
    klt_levels: int = 3
    klt_iterations: int = 12
    klt_max_error: float = 40.0
    inlier_threshold_px: float = 1.0
    outlier_px: float = 3.0
    min_inliers: int = 20
    min_inlier_ratio: float = 0.5
    static_parallax_px: float = 0.7
    max_bridge_s: float = 0.5
    max_history_frames: int = 256
    fuse_frame_to_frame: bool = True
    frame_to_frame_floor_rad: float = math.radians(0.02)
    affine_refinement: bool = True

    def __post_init__(self) -> None:
        positive = (
            "lookback_s",
            "min_feature_distance_px",
            "corner_quality",
            "klt_max_error",
            "inlier_threshold_px",
            "outlier_px",
            "static_parallax_px",
            "max_bridge_s",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigurationError(f"visual odometry {name} must be > 0, got {value}")
        if self.max_features < self.min_inliers or self.min_inliers < 8:
            raise ConfigurationError(
                "visual odometry needs 8 ≤ min_inliers ≤ max_features, got "
                f"min_inliers={self.min_inliers}, max_features={self.max_features}"
            )
        if self.klt_window_px < 5 or self.klt_levels < 0 or self.klt_iterations < 1:
            raise ConfigurationError("klt_window_px ≥ 5, klt_levels ≥ 0, klt_iterations ≥ 1")
        if not 0 < self.min_inlier_ratio <= 1:
            raise ConfigurationError("min_inlier_ratio must lie in (0, 1]")
        if self.max_history_frames < 2:
            raise ConfigurationError("max_history_frames must be ≥ 2")
        if not (
            math.isfinite(self.frame_to_frame_floor_rad) and self.frame_to_frame_floor_rad >= 0
        ):
            raise ConfigurationError(
                "visual odometry frame_to_frame_floor_rad must be ≥ 0, got "
                f"{self.frame_to_frame_floor_rad}"
            )


@dataclass(frozen=True)
class FitInfo:
    """Diagnostics of the last rotation fit.

    Attributes:
        interval_s: time between the reference frame and the current one, seconds (the
            look-back when the tracks allow it).
        correspondences: tracks common to both frames.
        inliers: inliers of the fit.
        model: ``"rotation"`` (no parallax) or ``"essential"``.
        usac: True when the local fit failed and OpenCV's USAC solver was used.
    """

    interval_s: float
    correspondences: int
    inliers: int
    model: str
    usac: bool


@dataclass(frozen=True)
class _FrameRecord:
    """A good frame: its time, rotation and the tracks alive in it (ids sorted, pixels)."""

    timestamp_s: float
    R_world_cam: FloatArray
    ids: NDArray[np.int64]
    pts: NDArray[np.float32]


class BuiltinVisualOdometry:
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
        self._K = camera.K
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
        """Pixel positions ``(N, 2)`` of the tracks alive in the last good frame (a copy)."""
        return self._pts.copy()

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
        if self.camera.image_width is not None and self.camera.image_height is not None:
            self._size: tuple[int, int] | None = (self.camera.image_width, self.camera.image_height)
            self._size_source = "the camera calibration"
        else:
            self._size = None
            self._size_source = ""

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
        boxes = _check_boxes(mask_boxes)
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
        image = np.asarray(image_gray)
        if image.ndim != 2 or image.dtype != np.uint8:
            raise DataMismatchError(
                f"visual odometry needs grey H×W uint8 frames, got shape {image.shape} "
                f"and dtype {image.dtype}"
            )
        height, width = image.shape
        if self._size is None:
            if not (0 < self.camera.c_x < width and 0 < self.camera.c_y < height):
                raise DataMismatchError(
                    f"the camera's principal point ({self.camera.c_x:.1f}, "
                    f"{self.camera.c_y:.1f}) px lies outside the {width}×{height} frames: "
                    "calibration and frames do not match"
                )
            self._size = (width, height)
            self._size_source = "the first frame"
        elif (width, height) != self._size:
            raise DataMismatchError(
                f"frame size {width}×{height} px differs from the {self._size[0]}×"
                f"{self._size[1]} px of {self._size_source}"
            )
        return np.ascontiguousarray(image)

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
        small = _half_size(image)
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
        self._commit(image, t, R, gradient_energy(image, small=small), grey_stats(image))
        return OdometryResult(R.copy(), OdometryState.OK, 0, self._segment)

    # ------------------------------------------------------------------ tracking
    def _track(self, image: NDArray[np.uint8], t: float, boxes: FloatArray) -> OdometryResult:
        prev = self._history[-1]
        dt = t - prev.timestamp_s
        c = self.config
        assert self._prev_image is not None
        if len(self._pts) == 0:
            return OdometryResult(None, OdometryState.LOST, 0, self._segment)
        self._usac_budget = 1
        small = _half_size(image)  # also where new corners are detected
        energy = gradient_energy(image, small=small)
        if self._prev_energy > MAX_BLUR_RATIO * energy:
            # so blurred that its rotation would be poor: bridge it from the last sharp frame
            return OdometryResult(None, OdometryState.LOST, 0, self._segment)
        # Lucas–Kanade assumes constant brightness: after an exposure jump (a tunnel,
        # auto-exposure, a flash) track into this frame with its grey levels mapped to the
        # previous frame's mean and spread; the raw frame is kept for the next step
        stats = grey_stats(image)  # this frame's statistics serve again as the next previous
        jumped = match_exposure(
            image,
            self._prev_image,
            EXPOSURE_JUMP_LEVELS,
            image_stats=stats,
            reference_stats=self._prev_stats,
        )
        current = image if jumped is None else jumped
        # Lucas–Kanade also needs both frames equally sharp: when one is clearly blurrier (a
        # jolt, motion blur), blur the other to match (a symmetric blur moves no feature)
        previous = self._prev_image
        if energy > SHARPNESS_RATIO * self._prev_energy:
            current = blur_to_energy(current, self._prev_energy)
        elif self._prev_energy > SHARPNESS_RATIO * energy:
            previous = blur_to_energy(previous, energy)
        keep, pts, estimate = self._attempt(previous, current, boxes, t, dt)
        if estimate is None and jumped is None:
            # a smaller exposure change can still break the tracks: retry matched
            matched = match_exposure(
                current,
                previous,
                MIN_EXPOSURE_CHANGE,
                image_stats=stats if current is image else None,
                reference_stats=self._prev_stats if previous is self._prev_image else None,
            )
            if matched is not None:
                keep, pts, estimate = self._attempt(previous, matched, boxes, t, dt)
        if estimate is None:
            return OdometryResult(None, OdometryState.LOST, 0, self._segment)
        ids = self._ids[keep]
        vel = (pts - self._pts[keep]) / dt
        R_world_cam, fit, fit_ids, ref = estimate
        cov = _rotation_covariance(fit.information, R_world_cam.T @ ref.R_world_cam)
        good = ~np.isin(ids, fit_ids[fit.residuals_px > c.outlier_px], assume_unique=True)
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
            R_world_cam, cov = _fuse(R_world_cam, cov, vote, cov_vote)
        else:
            x_prev = tv.normalise_pixels(self._pts[keep], self._K)
            x_cur = tv.normalise_pixels(pts, self._K)
            r_f2f = tv.epipolar_residuals_px(
                R_world_cam.T @ prev.R_world_cam,
                x_prev,
                x_cur,
                self.camera.f,
                c.inlier_threshold_px,
            )
            good &= r_f2f <= c.outlier_px
        ids, pts, vel = ids[good], pts[good], vel[good]
        self._cov = cov
        self._omega = tv.so3_log(prev.R_world_cam.T @ R_world_cam) / dt
        self._moving = True
        self._ids, self._pts, self._vel = ids, pts.astype(np.float32), vel.astype(np.float32)
        self._add_features(image, boxes, small)
        self._commit(image, t, R_world_cam, energy, stats)
        return OdometryResult(R_world_cam.copy(), OdometryState.OK, fit.n_inliers, self._segment)

    def _attempt(
        self,
        previous: NDArray[np.uint8],
        image: NDArray[np.uint8],
        boxes: FloatArray,
        t: float,
        dt: float,
    ) -> tuple[
        NDArray[np.bool_],
        NDArray[np.float32],
        tuple[FloatArray, tv.TwoViewFit, NDArray[np.int64], _FrameRecord] | None,
    ]:
        """Track from ``previous`` (the last good frame) into ``image`` from the velocity
        prediction (or, with no velocity yet, the global shift) and estimate the rotation; after
        a failed prediction (a jolt, a long gap) retry once from the global shift. Returns the
        kept-track mask, their positions and the estimate (None when both attempts fail)."""
        if self._moving:
            guess = self._pts + self._vel * dt
        else:  # no motion known yet (first step of a segment): global shift of the image
            guess = self._pts + _global_shift(previous, image)
        keep, pts = self._follow(previous, image, guess, boxes)
        estimate = self._estimate(self._ids[keep], pts, t)
        if estimate is None and self._moving:
            keep, pts = self._follow(
                previous, image, self._pts + _global_shift(previous, image), boxes
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
        assert self._size is not None
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
            near = _inside_boxes(p1, _grown(boxes, 0.5 * c.klt_window_px + 1.0))
            refine = tracked & ~near
            prev_f = self._float_image if previous is self._float_source else None
            if prev_f is None or previous is image:
                prev_f = previous.astype(np.float32)
            cur_f = image.astype(np.float32)
            self._float_source, self._float_image = image, cur_f  # the next step's previous
            p1[refine] = refine_affine(prev_f, cur_f, self._pts[refine], p1[refine])[0]
        width, height = self._size
        margin = 0.5 * c.klt_window_px
        keep = (
            tracked
            & (p1[:, 0] >= margin)
            & (p1[:, 0] < width - margin)
            & (p1[:, 1] >= margin)
            & (p1[:, 1] < height - margin)
            & ~_inside_boxes(p1, boxes)
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
    ) -> tuple[FloatArray, tv.TwoViewFit, NDArray[np.int64], _FrameRecord] | None:
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

    def _fit(
        self,
        uv_ref: NDArray[np.float32],
        uv_cur: NDArray[np.float32],
        R_init: FloatArray,
        kind: str = "direct",
    ) -> tv.TwoViewFit | None:
        """Relative pose reference → current (``X_cur = R X_ref + t``) or None if unreliable.

        ``kind`` ("direct" or "f2f") selects which earlier translation warm-starts the fit.
        """
        c = self.config
        f = self.camera.f
        x1 = tv.normalise_pixels(uv_ref, self._K)
        x2 = tv.normalise_pixels(uv_cur, self._K)
        n = len(x1)
        rot = tv.fit_rotation_only(x1, x2, f, c.inlier_threshold_px, R_init=R_init)
        if rot.n_inliers >= max(c.min_inliers, c.min_inlier_ratio * n) and (
            float(np.median(rot.residuals_px)) < c.static_parallax_px
        ):
            self.last_fit = FitInfo(0.0, n, rot.n_inliers, "rotation", False)
            return rot
        fit = self._refine(x1, x2, R_init, self._t_last.get(kind))
        usac = False
        if fit.n_inliers < c.min_inlier_ratio * n:  # poor prediction: start from the rotation
            other = self._refine(x1, x2, rot.R)
            fit = other if other.n_inliers > fit.n_inliers else fit
        if fit.n_inliers < c.min_inlier_ratio * n and self._usac_budget > 0:
            self._usac_budget -= 1  # at most one global search per frame (bounded time)
            global_fit = self._fit_usac(uv_ref, uv_cur, x1, x2)
            if global_fit is not None and global_fit.n_inliers > fit.n_inliers:
                fit = global_fit
            usac = True
        self.last_fit = FitInfo(0.0, n, fit.n_inliers, "essential", usac)
        if fit.n_inliers < max(c.min_inliers, c.min_inlier_ratio * n):
            return None
        self._t_last[kind] = fit.t
        return fit

    def _fit_usac(
        self,
        uv_ref: NDArray[np.float32],
        uv_cur: NDArray[np.float32],
        x1: FloatArray,
        x2: FloatArray,
    ) -> tv.TwoViewFit | None:
        """Global fallback: USAC essential matrix + cheirality, then the local refinement."""
        c = self.config
        E, mask = cv2.findEssentialMat(
            uv_ref,
            uv_cur,
            self._K,
            cv2.USAC_DEFAULT,
            0.999,
            c.inlier_threshold_px,
            USAC_MAX_ITERATIONS,
        )
        if E is None or E.shape != (3, 3):
            return None
        _, R, _, _ = cv2.recoverPose(E, uv_ref, uv_cur, self._K, mask=mask)
        return self._refine(x1, x2, np.asarray(R, dtype=np.float64))

    def _refine(
        self, x1: FloatArray, x2: FloatArray, R_init: FloatArray, t_last: FloatArray | None = None
    ) -> tv.TwoViewFit:
        """Essential-matrix refinement from ``R_init``.

        The translation starts along the chord of the car's arc (the heading turned by half the
        rotation), or from ``t_last`` (the previous fit of this kind) when that agrees with the
        chord within ``MAX_WARM_START_DEG``.
        """
        c = self.config
        t_init = tv.so3_exp(0.5 * tv.so3_log(R_init)) @ self._heading
        if t_last is not None and abs(float(t_last @ t_init)) > math.cos(
            math.radians(MAX_WARM_START_DEG)
        ):
            t_init = t_last if t_last @ t_init > 0 else -t_last
        return tv.fit_relative_pose(
            x1, x2, self.camera.f, R_init, t_init, threshold_px=c.inlier_threshold_px
        )

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
        (:func:`_half_size`), away from tracks and masked boxes."""
        c = self.config
        wanted = c.max_features - len(self._ids)
        if wanted < max(8, c.max_features // 10):
            return
        radius = max(1, round(0.5 * c.min_feature_distance_px))
        if len(self._pts):  # 0 within ``radius`` of a track, 255 elsewhere
            occupied = np.zeros(small.shape, dtype=np.uint8)
            xy = np.clip(
                (self._pts * 0.5).astype(np.intp), 0, [small.shape[1] - 1, small.shape[0] - 1]
            )
            occupied[xy[:, 1], xy[:, 0]] = 255
            kernel = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
            mask = np.asarray(cv2.bitwise_not(cv2.dilate(occupied, kernel)))
        else:
            mask = np.full(small.shape, 255, dtype=np.uint8)
        border = max(2, math.ceil(0.25 * c.klt_window_px) + 1)
        mask[:border] = 0
        mask[-border:] = 0
        mask[:, :border] = 0
        mask[:, -border:] = 0
        for left, top, right, bottom in boxes * 0.5:
            mask[
                max(int(top), 0) : max(math.ceil(bottom) + 1, 0),
                max(int(left), 0) : max(math.ceil(right) + 1, 0),
            ] = 0
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


def _rotation_covariance(information: FloatArray, Q: FloatArray) -> FloatArray:
    """Covariance (rad²) of ``R_world_cam`` from a fit's information on ``R_rel = Q``.

    ``R_world_cam = R_ref · R_relᵀ``; a right perturbation ``R_rel·exp(ω)`` is the perturbation
    ``R_world_cam·exp(−Q ω)`` of the output, hence ``Σ = Q Λ⁻¹ Qᵀ``.
    """
    return np.asarray(Q @ np.linalg.inv(information + 1e-12 * np.eye(3)) @ Q.T)


def _fuse(
    R_a: FloatArray, cov_a: FloatArray, R_b: FloatArray, cov_b: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Information-weighted mean of two rotations with covariances of right perturbations."""
    info_a = np.linalg.inv(cov_a + 1e-14 * np.eye(3))
    info_b = np.linalg.inv(cov_b + 1e-14 * np.eye(3))
    info = info_a + info_b
    phi = np.asarray(np.linalg.solve(info, info_b @ tv.so3_log(R_a.T @ R_b)), dtype=np.float64)
    return np.asarray(R_a @ tv.so3_exp(phi)), np.asarray(np.linalg.inv(info))


def _half_size(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Half-resolution copy (2×2 block means; an odd last row/column is dropped)."""
    h, w = image.shape
    even = image[: h - h % 2, : w - w % 2]
    return np.asarray(cv2.resize(even, (w // 2, h // 2), interpolation=cv2.INTER_AREA))


MIN_EXPOSURE_STD = 2.0
"""Frames whose grey-level standard deviation is below this (blank, black) are not rescaled."""
EXPOSURE_JUMP_LEVELS = 16.0
"""Frames whose exposure match (:func:`match_exposure`) moves some grey level by this much are
tracked matched from the start. Between KITTI frames, changes of the scene alone move the
mean by up to ~7 levels and the spread by up to ~7 %, which maps some level by at most ~15."""
MIN_EXPOSURE_CHANGE = 3.0
"""After a failed frame, an exposure match that moves no grey level by this much (levels) is
not worth a retry."""


def grey_stats(image: NDArray[np.uint8]) -> tuple[float, float]:
    """Mean and standard deviation of a frame's grey levels."""
    mean, std = (float(v) for v in np.ravel(cv2.meanStdDev(image)))
    return mean, std


def match_exposure(
    image: NDArray[np.uint8],
    reference: NDArray[np.uint8],
    min_change: float,
    image_stats: tuple[float, float] | None = None,
    reference_stats: tuple[float, float] | None = None,
) -> NDArray[np.uint8] | None:
    """``image`` with its grey levels mapped affinely to the mean and standard deviation of
    ``reference`` (a global gain and offset, as an exposure or gain change of the camera makes).

    ``image_stats``, ``reference_stats``: the frames' :func:`grey_stats` when already known.
    Returns None when either frame is nearly uniform (nothing to match) or when the mapping
    would change no grey level by ``min_change`` (grey levels) or more.
    """
    mean_i, std_i = grey_stats(image) if image_stats is None else image_stats
    mean_r, std_r = grey_stats(reference) if reference_stats is None else reference_stats
    if std_i < MIN_EXPOSURE_STD or std_r < MIN_EXPOSURE_STD:
        return None
    gain = std_r / std_i
    levels = np.arange(256, dtype=np.float64)
    mapped = np.clip(np.rint(mean_r + gain * (levels - mean_i)), 0, 255)
    if np.max(np.abs(mapped - levels)) < min_change:
        return None
    return np.asarray(cv2.LUT(image, mapped.astype(np.uint8)))


SHARPNESS_RATIO = 1.5
"""When one of two consecutive frames has this many times the other's gradient energy, the
sharper one is blurred to match before tracking. Between the shared KITTI frames the ratio
stays below 1.23; a Gaussian blur of 1.3–1.4 px reaches 1.5."""
MAX_BLUR_RATIO = 8.0
"""A frame with less than 1/this of the previous good frame's gradient energy (a Gaussian blur
of about 4 px on KITTI frames) is ``LOST``, and the next sharp frame is tracked from the last
sharp one: on the sharp turn with three frames blurred by 10 px that gives θ 0.09° RMS, against
0.15° when they are tracked."""
BLUR_SIGMAS_PX = (0.7, 1.0, 1.4, 2.0, 2.8, 4.0, 5.6, 8.0)
"""Gaussian blurs tried by :func:`blur_to_energy`, pixels."""


def gradient_energy(image: NDArray[np.uint8], small: NDArray[np.uint8] | None = None) -> float:
    """Sharpness of a frame: the mean squared Sobel gradient of its half-size copy divided by
    its grey-level variance (per pixel², independent of the exposure's gain and offset);
    comparable between frames of the same scene. ``small``: the half-size copy
    (:func:`_half_size`) when already made."""
    if small is None:
        small = _half_size(image)
    square_sum = 0.0
    for dx, dy in ((1, 0), (0, 1)):  # E[g²] = std² + mean², per axis (OpenCV, int16 Sobel)
        mean, std = cv2.meanStdDev(cv2.Sobel(small, cv2.CV_16S, dx, dy, ksize=3))
        square_sum += float(std[0, 0]) ** 2 + float(mean[0, 0]) ** 2
    grey_std = float(cv2.meanStdDev(small)[1][0, 0])
    return square_sum / max(grey_std**2, 1.0)


def blur_to_energy(image: NDArray[np.uint8], target: float) -> NDArray[np.uint8]:
    """``image`` blurred (Gaussian, one of :data:`BLUR_SIGMAS_PX`) so that its
    :func:`gradient_energy` comes closest to ``target`` (that of a blurrier frame of the same
    scene)."""
    best: tuple[float, NDArray[np.uint8]] = (math.inf, image)
    for sigma in BLUR_SIGMAS_PX:
        blurred: NDArray[np.uint8] = np.asarray(
            cv2.GaussianBlur(image, (0, 0), sigma), dtype=np.uint8
        )
        gap = abs(math.log(max(gradient_energy(blurred), 1e-9) / max(target, 1e-9)))
        if gap >= best[0]:
            break  # the energy falls with sigma: past the closest one
        best = (gap, blurred)
    return best[1]


def _global_shift(image_a: NDArray[np.uint8], image_b: NDArray[np.uint8]) -> FloatArray:
    """Dominant image shift a → b in pixels ``(2,)`` by phase correlation at quarter size."""
    h, w = image_a.shape
    size = (max(w // 4, 8), max(h // 4, 8))
    a = cv2.resize(image_a, size, interpolation=cv2.INTER_AREA).astype(np.float32)
    b = cv2.resize(image_b, size, interpolation=cv2.INTER_AREA).astype(np.float32)
    (dx, dy), response = cv2.phaseCorrelate(a, b)
    if not (math.isfinite(dx) and math.isfinite(dy)) or response < 0.05:
        return np.zeros(2)
    return np.array([dx * w / size[0], dy * h / size[1]])


def _check_boxes(mask_boxes: ArrayLike | None) -> FloatArray:
    if mask_boxes is None:
        return np.empty((0, 4))
    boxes = np.asarray(mask_boxes, dtype=float)
    if boxes.size == 0:
        return np.empty((0, 4))
    if boxes.ndim != 2 or boxes.shape[1] != 4:
        raise DataMismatchError(
            f"mask_boxes must be (N, 4) (left, top, right, bottom) pixels, got {boxes.shape}"
        )
    return boxes


def _grown(boxes: FloatArray, margin_px: float) -> FloatArray:
    """``(M, 4)`` boxes (left, top, right, bottom) grown by ``margin_px`` on every side."""
    return boxes + np.array([-margin_px, -margin_px, margin_px, margin_px])


def _inside_boxes(pts: NDArray[np.float32], boxes: FloatArray) -> NDArray[np.bool_]:
    """``(N,)`` True for points inside any of the ``(M, 4)`` boxes (left, top, right, bottom)."""
    if len(boxes) == 0 or len(pts) == 0:
        return np.zeros(len(pts), dtype=bool)
    x = pts[:, 0:1]
    y = pts[:, 1:2]
    inside = (x >= boxes[:, 0]) & (x <= boxes[:, 2]) & (y >= boxes[:, 1]) & (y <= boxes[:, 3])
    return np.asarray(inside.any(axis=1))
