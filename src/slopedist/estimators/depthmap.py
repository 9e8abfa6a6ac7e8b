"""The depth-map baseline: the distance of a target is a depth map's value at its 2D box.

This is the protocol the paper uses for DORN and Monodepth2: the depth at the centre pixel of
the target's box. Options:

Sampling (:class:`DepthSample`):
    ``centre``: the single pixel nearest to the box centre ``((l+r)/2, (t+b)/2)`` (the paper);
    ``window``: median of the valid pixels of a ``window_px × window_px`` square around it,
    cut to the box (robust to holes and noise, and usable on sparse LiDAR maps; a window wider
    than the box never reaches the road or the cars beside it);
    ``lower``: median of the valid pixels of the box's lower part: the bottom
    ``lower_fraction`` of its rows and the central half of its columns (the vehicle's rear
    and wheels, away from the background seen beside and above it).
    Pixels of value NaN, ±inf or ≤ 0 are "no value", and so are metric depths (scaling
    ``none``) outside the plausible range [0.1, 1000] m (:func:`slopedist.io.depth.base.
    plausible_depth`); no valid pixel → reason ``no_depth``, never a clamped number.

Median scaling (:class:`DepthScaling`) for scale-less monocular models, per frame, as in the
depth-evaluation literature (Monodepth2 scales each image by ``median(truth)/median(pred)``):
    ``none``: depths are used as they are (metric models, LiDAR, files in metres);
    ``contact``: scale ``s = median(d_contact) / median(d_raw)`` over the frame's targets that
    have both, where ``d_contact = f·h/(u − c_y − f·tan θ0)`` is the flat-ground distance of
    eq. 1 with the camera at rest (needs only the camera height; no ground truth);
    ``truth``: ``s = median(g) / median(d_raw)`` with ``g`` the supplied ground-truth distance
    of each target, read from the box column ``truth_column`` (default ``gt_distance_m``,
    metres, NaN = unknown). This is an oracle protocol, for comparison with published numbers.
    A frame without any reference pair reuses the last frame's scale; before the first scale of
    a sequence, targets are missing with reason ``no_scale``.

Plausibility: a depth below ``min_depth_m`` (default 0.1 m) or above 1000 m after scaling is
reason ``no_depth`` (a 1e-30 network output is not a distance of 0.001 m); a depth is never
capped (evaluations cap every method's estimates alike, at 80 m for the KITTI protocol).

Scale check (scaling ``none``): metric depth maps must agree with the flat-ground distance of
eq. 1 where it is reliable — boxes whose contact distance is
:data:`SCALE_CHECK_RANGE_M` (3–12 m: there a 4° slope between the car and the target moves it
by at most a factor 2) and whose bottom the image border does not cut. Once
:data:`SCALE_CHECK_COUNT` such targets of a sequence have a depth, the median ratio of depth to
contact distance must lie within a factor :data:`SCALE_CHECK_FACTOR` of 1; otherwise the run
stops with an error (the maps are not in metres: a 16-bit PNG in millimetres read as KITTI's
metres × 256 is 3.9× too far, and every target would be ``ok`` at that distance).

Border: the depth at the box centre is still a pixel of the vehicle when the box is cut by the
image border (the visible part is what the box covers), so a cut box keeps status ``ok`` with
its ``cut`` flag; boxes wholly outside the image or degenerate are ``missing`` before sampling.

Extra output columns: ``depth_raw_m`` (sampled depth before scaling) and ``depth_scale``.
"""

from __future__ import annotations

import math
from enum import Enum
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from slopedist.core import geometry as geo
from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError, DataMismatchError
from slopedist.estimators.base import (
    Estimator,
    FrameEstimates,
    FrameInput,
    MissingReason,
    ReferencePoint,
    image_size,
    unusable_box_reasons,
)
from slopedist.io.depth.base import MAX_PLAUSIBLE_DEPTH_M, MIN_PLAUSIBLE_DEPTH_M, plausible_depth
from slopedist.io.detections.boxes import EDGES, border_cuts

DEFAULT_MIN_DEPTH_M = MIN_PLAUSIBLE_DEPTH_M
SCALE_CHECK_RANGE_M = (3.0, 12.0)
"""Flat-ground contact distances (m) at which a metric depth map's scale is checked."""

SCALE_CHECK_COUNT = 5
"""Targets in that range a sequence needs before its depth maps' scale is judged."""

SCALE_CHECK_FACTOR = 2.5
"""Largest accepted median ratio (either way) of a metric depth to the contact distance."""

TRUTH_COLUMN = "gt_distance_m"
"""Box column read by the ``truth`` scaling: ground-truth distance per target, metres."""


class DepthSample(str, Enum):
    """Which pixels of the box give its depth (see the module docstring)."""

    CENTRE = "centre"
    WINDOW = "window"
    LOWER = "lower"


class DepthScaling(str, Enum):
    """Per-frame median scaling of scale-less depth (see the module docstring)."""

    NONE = "none"
    CONTACT = "contact"
    TRUTH = "truth"


def _median_valid(patch: NDArray[np.floating], metric: bool) -> float:
    """Median of the valid pixels: finite and > 0, and plausible metres when ``metric``."""
    with np.errstate(invalid="ignore"):
        valid = plausible_depth(patch) if metric else np.isfinite(patch) & (patch > 0)
    values = patch[valid]
    return float(np.median(values)) if values.size else math.nan


def sample_box_depth(
    depth_m: NDArray[np.floating],
    boxes: NDArray[np.float64],
    sample: DepthSample = DepthSample.CENTRE,
    window_px: int = 5,
    lower_fraction: float = 1.0 / 3.0,
    metric: bool = True,
) -> NDArray[np.float64]:
    """Depth of every box ``(left, top, right, bottom)`` sampled from ``depth_m``.

    Pixel ``(row i, column j)`` is centred on image coordinates ``(y = i, x = j)``. Boxes that
    reach past the image are clipped to it, and a ``window`` to the pixels whose centres lie in
    the box (never fewer than the centre pixel); NaN where no valid pixel is sampled. ``metric``:
    the map is in metres, and values outside the plausible range are no value; otherwise
    (scale-less maps) only non-finite and non-positive values are.
    """
    d = np.asarray(depth_m)
    h, w = d.shape
    out = np.full(len(boxes), np.nan)
    for k, (left, top, right, bottom) in enumerate(np.asarray(boxes, dtype=float)):
        if sample is DepthSample.LOWER:
            r0 = math.floor(bottom - lower_fraction * (bottom - top) + 0.5)
            r1 = math.floor(bottom + 0.5) + 1
            quarter = 0.25 * (right - left)
            c0 = math.floor(left + quarter + 0.5)
            c1 = math.floor(right - quarter + 0.5) + 1
        else:
            row = math.floor(0.5 * (top + bottom) + 0.5)
            col = math.floor(0.5 * (left + right) + 0.5)
            half = window_px // 2 if sample is DepthSample.WINDOW else 0
            r0 = min(max(row - half, math.ceil(top)), row)
            r1 = max(min(row + half, math.floor(bottom)), row) + 1
            c0 = min(max(col - half, math.ceil(left)), col)
            c1 = max(min(col + half, math.floor(right)), col) + 1
        r0, r1, c0, c1 = max(r0, 0), min(r1, h), max(c0, 0), min(c1, w)
        if r0 < r1 and c0 < c1:
            out[k] = _median_valid(d[r0:r1, c0:c1], metric)
    return out


class DepthMapEstimator(Estimator):
    """Depth-map baseline: depth at the target's box (the paper's DORN/Monodepth2 protocol).

    Args:
        camera: the camera (used for the image size check and the ``contact`` scaling).
        sample: :class:`DepthSample` (or its name).
        window_px: side of the ``window`` square, pixels (odd; ≥ 1).
        lower_fraction: share of the box height used by ``lower`` (0 < x ≤ 1).
        scaling: :class:`DepthScaling` (or its name).
        min_depth_m: smallest plausible depth after scaling, metres (smaller: ``no_depth``).
        truth_column: box column holding ground-truth distances for ``truth`` scaling.
    """

    name: ClassVar[str] = "depthmap"
    handles_border_cuts: ClassVar[bool] = True
    needs_rotation: ClassVar[bool] = False
    needs_depth: ClassVar[bool] = True

    def __init__(
        self,
        camera: Camera,
        sample: DepthSample | str = DepthSample.CENTRE,
        window_px: int = 5,
        lower_fraction: float = 1.0 / 3.0,
        scaling: DepthScaling | str = DepthScaling.NONE,
        min_depth_m: float = DEFAULT_MIN_DEPTH_M,
        truth_column: str = TRUTH_COLUMN,
    ) -> None:
        super().__init__(camera)
        try:
            self.sample = DepthSample(sample)
            self.scaling = DepthScaling(scaling)
        except ValueError as exc:
            raise ConfigurationError(f"depthmap: {exc}") from None
        if window_px < 1 or window_px % 2 == 0:
            raise ConfigurationError(
                f"depthmap: window must be an odd number ≥ 1 of pixels, got {window_px}"
            )
        if not 0 < lower_fraction <= 1:
            raise ConfigurationError(
                f"depthmap: lower fraction must be in (0, 1], got {lower_fraction}"
            )
        self.window_px = int(window_px)
        self.lower_fraction = float(lower_fraction)
        self.min_depth_m = float(min_depth_m)
        self.truth_column = truth_column
        self._last_scale = math.nan
        self._check_log_ratios: list[float] | None = []

    def reset(self) -> None:
        self._last_scale = math.nan
        self._check_log_ratios = []

    def _check_metric_scale(self, frame: FrameInput, raw: NDArray[np.float64]) -> None:
        """The scale check of the module docstring (pooled until judged, then off).

        Raises:
            DataMismatchError: the depth maps' median ratio to the contact distance is beyond
                :data:`SCALE_CHECK_FACTOR`.
        """
        pool = self._check_log_ratios
        if pool is None:
            return
        contact = self._reference(frame)
        cuts = border_cuts(frame.boxes.boxes, image_size(self.camera))
        cut_bottom = cuts[:, EDGES.index("bottom")]
        low, high = SCALE_CHECK_RANGE_M
        with np.errstate(invalid="ignore"):
            use = np.isfinite(raw) & (raw > 0) & (contact >= low) & (contact <= high)
        use &= ~cut_bottom
        pool.extend(np.log(raw[use] / contact[use]).tolist())
        if len(pool) < SCALE_CHECK_COUNT:
            return
        ratio = math.exp(float(np.median(pool)))
        self._check_log_ratios = None
        if not 1.0 / SCALE_CHECK_FACTOR <= ratio <= SCALE_CHECK_FACTOR:
            raise DataMismatchError(
                f"frame {frame.frame_index}: the depth maps say {ratio:.2f} times the flat-road "
                f"distance of the {len(pool)} targets {low:g}–{high:g} m ahead (median): they "
                "are not metres (a 16-bit PNG must be KITTI's metres × 256; millimetres read "
                "3.9 times too far), or the camera height is wrong; give metric maps, or a "
                "scaling (--depth-scaling contact) for a scale-less model"
            )

    def _reference(self, frame: FrameInput) -> NDArray[np.float64]:
        boxes = frame.boxes.boxes
        if self.scaling is DepthScaling.TRUTH:
            if self.truth_column not in frame.boxes.extra:
                raise ConfigurationError(
                    f"depthmap scaling 'truth' needs a ground-truth distance column "
                    f"'{self.truth_column}' (metres) in the boxes of frame {frame.frame_index}"
                )
            return np.asarray(frame.boxes.extra[self.truth_column], dtype=float)
        theta_rest = geo.rest_gradient(self.camera.mount_angle_rad)
        v = geo.vanishing_line_row(theta_rest, self.camera.f, self.camera.c_y)
        return geo.ground_contact_distance(
            self.camera.f, self.camera.height_m, geo.box_bottom_row(boxes), v
        )

    def estimate(self, frame: FrameInput) -> FrameEstimates:
        boxes = frame.boxes.boxes
        n = len(boxes)
        reasons = unusable_box_reasons(frame, False, self.camera)
        raw = np.full(n, np.nan)
        if frame.depth_m is not None:
            cam = self.camera
            if (
                cam.image_width is not None
                and cam.image_height is not None
                and (frame.depth_m.shape != (cam.image_height, cam.image_width))
            ):
                raise DataMismatchError(
                    f"frame {frame.frame_index}: depth map is {frame.depth_m.shape[1]}×"
                    f"{frame.depth_m.shape[0]} pixels, the camera's image "
                    f"{cam.image_width}×{cam.image_height}"
                )
            ok = reasons == ""
            raw[ok] = sample_box_depth(
                frame.depth_m,
                boxes[ok],
                self.sample,
                self.window_px,
                self.lower_fraction,
                metric=self.scaling is DepthScaling.NONE,
            )
        reasons[(reasons == "") & ~np.isfinite(raw)] = MissingReason.NO_DEPTH.value
        if self.scaling is DepthScaling.NONE and n:
            self._check_metric_scale(frame, raw)
        scale = 1.0
        if self.scaling is not DepthScaling.NONE and n:
            ref = self._reference(frame)
            pair = (reasons == "") & np.isfinite(ref) & (ref > 0)
            if pair.any():
                self._last_scale = float(np.median(ref[pair]) / np.median(raw[pair]))
            scale = self._last_scale
            if not math.isfinite(scale):
                reasons[reasons == ""] = MissingReason.NO_SCALE.value
        d = raw * scale
        with np.errstate(invalid="ignore"):
            implausible = ~((d >= self.min_depth_m) & (d <= MAX_PLAUSIBLE_DEPTH_M))
        reasons[(reasons == "") & implausible] = MissingReason.NO_DEPTH.value
        d = np.where(reasons == "", d, np.nan)
        theta = np.full(n, frame.theta_rad, dtype=float)
        nan = np.full(n, np.nan)
        return FrameEstimates(
            theta_rad=theta,
            theta_adj_rad=theta.copy(),
            delta_y_px=nan,
            v_px=nan.copy(),
            distance_m=d,
            reason=reasons,
            reference=np.full(n, ReferencePoint.BOX_CENTRE_PIXEL.value, dtype=object),
            extra={"depth_raw_m": raw, "depth_scale": np.full(n, scale, dtype=float)},
        )
