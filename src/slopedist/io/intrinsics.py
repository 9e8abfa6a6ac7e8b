"""Camera intrinsics with lens distortion, and the mapping of boxes into an ideal pinhole.

The estimators use a square-pixel pinhole (:class:`~slopedist.core.camera.Camera`, one focal
length).
:class:`Intrinsics` is turned into the *ideal* camera ``f = fy``, ``(c_x, c_y)`` unchanged, and
box corners are mapped into it: ``u' = c_x + fy·x_n``, ``v' = c_y + fy·y_n`` where
``(x_n, y_n)`` is the undistorted normalised image point (``cv2.undistortPoints`` with ``P`` =
the ideal K). This removes lens distortion and honours ``fx ≠ fy`` (non-square pixels, or video
resized with another aspect ratio). Only boxes (and feature points) are mapped, never whole
images, which keeps it fast: each box edge is mapped at its midpoint (see
:meth:`Intrinsics.rectify_boxes`). Frames shown in overlays stay the distorted originals.

Distortion coefficients are OpenCV's order ``k1, k2, p1, p2[, k3[, k4, k5, k6[, s1…s4[, τx,
τy]]]]`` (ROS ``plumb_bob``/``rational_polynomial``), or ``k1…k4`` of the fisheye model (ROS
``equidistant``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.core.camera import KITTI_CAMERA_HEIGHT_M, Camera
from slopedist.core.errors import ConfigurationError
from slopedist.io.detections.boxes import FRAME_BOX_COLUMN, BoxTable, frame_pixel_boxes
from slopedist.io.detections.onnx_detector import DetectionTiming, Detector

DISTORTION_COUNTS = (0, 4, 5, 8, 12, 14)
"""Lengths OpenCV accepts for (non-fisheye) distortion coefficients."""

UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
"""Iterations of the undistortion: OpenCV's default (5) leaves pixels of error under strong
barrel distortion; 50 reach 1e-6 px."""

K_LAST_ROW_TOLERANCE = 1e-6
"""How far each value of K's last row may be from ``0 0 1`` (float round-off of a written file);
any other last row (a transposed K has ``cx cy 1``) is refused, never ignored."""

MAX_ROUND_TRIP_PX = 0.01
"""A mapped point must distort back to within this many pixels of the input point."""

MAX_LENS_SCALE = 8.0
"""Largest factor by which a (non-fisheye) lens model may move a point of the image's edge
away from or towards the principal point when mapped into the ideal camera. Real lenses stay
well within it (strong barrel distortion, k1 = −0.35, moves the edge of a 90° view by less than
1.5×); a coefficient typed a thousand times too large moves it by orders of magnitude, and the
boxes with it."""


@dataclass(frozen=True)
class Intrinsics:
    """A calibrated camera: pinhole ``K`` plus lens distortion.

    Attributes:
        K: 3×3 intrinsic matrix, pixels (``fx``, ``fy``, ``cx``, ``cy``; skew ignored).
        dist: distortion coefficients (OpenCV order, see the module docstring); empty = none.
        fisheye: the coefficients are the fisheye model's ``k1…k4``.
        image_size: ``(width, height)`` in pixels, if known.
    """

    K: NDArray[np.float64]
    dist: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    fisheye: bool = False
    image_size: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        try:
            K = np.asarray(self.K, dtype=float)
            dist = np.asarray(self.dist, dtype=float).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise ConfigurationError(
                f"camera matrix and distortion must be numbers: {exc}"
            ) from None
        if self.image_size is not None and not (
            len(self.image_size) == 2
            and all(
                isinstance(v, (int, np.integer)) and not isinstance(v, bool) and 0 < v <= 1_000_000
                for v in self.image_size
            )
        ):
            raise ConfigurationError(
                f"image size must be (width, height) in 1..1000000 px, got {self.image_size!r}"
            )
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise ConfigurationError(f"camera matrix must be 3×3 and finite, got {K.tolist()}")
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ConfigurationError(f"focal lengths must be > 0 pixels, got {K[0, 0]}, {K[1, 1]}")
        if np.any(np.abs(K[2] - (0.0, 0.0, 1.0)) > K_LAST_ROW_TOLERANCE):
            raise ConfigurationError(
                f"the camera matrix's last row must be 0 0 1, got {K[2].tolist()} "
                "(a transposed K, e.g. MATLAB's IntrinsicMatrix?)"
            )
        counts = (0, 4) if self.fisheye else DISTORTION_COUNTS
        if dist.size not in counts or not np.all(np.isfinite(dist)):
            raise ConfigurationError(
                f"expected {' or '.join(map(str, counts))} finite distortion coefficients, "
                f"got {dist.tolist()}"
            )
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "dist", dist)

    @classmethod
    def from_values(
        cls,
        fx: float,
        fy: float,
        cx: float,
        cy: float,
        dist: ArrayLike = (),
        image_size: tuple[int, int] | None = None,
    ) -> Intrinsics:
        """Intrinsics from explicit values (pixels; ``image_size`` = width, height), e.g.
        ``--fx --fy --cx --cy --image-size``."""
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        return cls(K, np.asarray(dist, dtype=float), image_size=image_size)

    def with_image_size(self, image_size: tuple[int, int] | None) -> Intrinsics:
        """These intrinsics for images of ``image_size`` (width, height; pixels); unchanged
        when None.

        Raises:
            ConfigurationError: the intrinsics state another size.
        """
        if image_size is None or self.image_size == tuple(image_size):
            return self
        width, height = (int(v) for v in image_size)
        if self.image_size is not None:
            raise ConfigurationError(
                f"the calibration is for {self.image_size[0]}×{self.image_size[1]} px images, "
                f"not {width}×{height} px as given"
            )
        return replace(self, image_size=(width, height))

    def check_camera(self) -> None:
        """Refuse a camera no lens and sensor make: its ideal camera's focal length or principal
        point out of range (:class:`~slopedist.core.camera.Camera`), or a lens model that moves the
        image's edges absurdly (:meth:`check_lens_scale`).

        Raises:
            ConfigurationError: naming what is implausible.
        """
        self.camera()
        self.check_lens_scale()

    def check_lens_scale(self) -> None:
        """Refuse a (non-fisheye) lens model that moves the midpoints of the image's edges by
        more than :data:`MAX_LENS_SCALE` radially (the image twice the principal point when its
        size is unknown; points the model cannot map are left to the boxes' own
        ``non_finite_box`` state).

        Raises:
            ConfigurationError: naming the point, where it goes and the factor.
        """
        if self.fisheye or self.is_ideal:
            return
        cx, cy = self.K[0, 2], self.K[1, 2]
        width, height = self.image_size or (2 * cx + 1, 2 * cy + 1)
        edges = np.array([[0.0, cy], [width - 1.0, cy], [cx, 0.0], [cx, height - 1.0]])
        mapped = self.rectify_points(edges)
        centre = np.array([cx, cy])
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.linalg.norm(mapped - centre, axis=1) / np.linalg.norm(edges - centre, axis=1)
        for point, to, k in zip(edges, mapped, scale):
            if np.isfinite(k) and not 1 / MAX_LENS_SCALE <= k <= MAX_LENS_SCALE:
                raise ConfigurationError(
                    f"the distortion coefficients {self.dist.tolist()} move the image's edge "
                    f"point ({point[0]:g}, {point[1]:g}) px to ({to[0]:.4g}, {to[1]:.4g}) px, "
                    f"{k:.3g}× its distance from the principal point: not a lens (a "
                    "coefficient in other units?)"
                )

    @property
    def ideal_K(self) -> NDArray[np.float64]:
        """K of the ideal camera boxes are mapped to: ``f = fy``, same principal point."""
        fy, cx, cy = self.K[1, 1], self.K[0, 2], self.K[1, 2]
        return np.array([[fy, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

    @property
    def is_ideal(self) -> bool:
        """True when no mapping is needed (no distortion, square pixels, no skew)."""
        return not np.any(self.dist != 0) and self.K[0, 0] == self.K[1, 1] and self.K[0, 1] == 0

    def camera(
        self, height_m: float = KITTI_CAMERA_HEIGHT_M, mount_angle_rad: float = 0.0
    ) -> Camera:
        """The ideal square-pixel :class:`Camera` (mount in metres and radians)."""
        K = self.ideal_K
        cam = Camera(float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), height_m, mount_angle_rad)
        return cam if self.image_size is None else cam.with_image_size(*self.image_size)

    def rectify_points(self, points: ArrayLike) -> NDArray[np.float64]:
        """``(N, 2)`` pixel points (u, v) of the real camera → pixels of the ideal camera.

        A point the undistortion cannot invert (near the image corners of a strongly distorted
        lens the model folds over, and the iteration lands elsewhere) is NaN: the mapped point
        is checked by distorting it again, and rejected when it misses by more than
        :data:`MAX_ROUND_TRIP_PX`.
        """
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 1, 2)
        if self.is_ideal or pts.shape[0] == 0:
            return pts.reshape(-1, 2).copy()
        ideal = self.ideal_K
        undistort: Any = cv2.fisheye.undistortPoints if self.fisheye else cv2.undistortPoints
        out = undistort(pts, self.K, self.dist, R=np.eye(3), P=ideal, criteria=UNDISTORT_CRITERIA)
        mapped = np.asarray(out, dtype=np.float64).reshape(-1, 2)
        normalised = (mapped - ideal[:2, 2]) / ideal[1, 1]
        miss = np.linalg.norm(self.distort_normalised(normalised) - pts.reshape(-1, 2), axis=1)
        mapped[~(miss <= MAX_ROUND_TRIP_PX)] = np.nan
        return mapped

    def distort_normalised(self, points: ArrayLike) -> NDArray[np.float64]:
        """``(N, 2)`` normalised image points (x/z, y/z) → pixels of the real camera."""
        xy = np.asarray(points, dtype=np.float64).reshape(-1, 1, 2)
        if self.fisheye:
            out = cv2.fisheye.distortPoints(xy, self.K, self.dist)
        else:
            xyz = np.concatenate([xy, np.ones((xy.shape[0], 1, 1))], axis=2)
            zero = np.zeros(3)
            out, _ = cv2.projectPoints(xyz, zero, zero, self.K, self.dist)
        return np.asarray(out, dtype=np.float64).reshape(-1, 2)

    def rectify_boxes(self, boxes: ArrayLike) -> NDArray[np.float64]:
        """``(N, 4)`` boxes (left, top, right, bottom; pixels) → boxes in the ideal camera.

        Each edge is mapped at its midpoint: bottom and top at the box's centre column, left and
        right at its centre row (the bottom centre is where the estimators take the ground
        contact). Distortion bends the object's outline, so which point of an edge touches the
        object is unknown; the midpoint is exact for a target straight ahead and, for strong
        barrel distortion (k1 = −0.35), keeps flat-road distances within 1 % for targets
        10–40 m ahead up to one lane to the side (1.1 % at 8 m; the extent of the mapped
        outline would be off by up to 5 %).
        """
        b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        if self.is_ideal or b.shape[0] == 0:
            return b.copy()
        u_mid, v_mid = (b[:, 0] + b[:, 2]) / 2, (b[:, 1] + b[:, 3]) / 2
        edges = np.stack(
            [
                np.c_[b[:, 0], v_mid],
                np.c_[u_mid, b[:, 1]],
                np.c_[b[:, 2], v_mid],
                np.c_[u_mid, b[:, 3]],
            ],
            axis=1,
        )
        mapped = self.rectify_points(edges.reshape(-1, 2)).reshape(-1, 4, 2)
        return np.c_[mapped[:, 0, 0], mapped[:, 1, 1], mapped[:, 2, 0], mapped[:, 3, 1]]

    def rectify_table(self, table: BoxTable) -> BoxTable:
        """A copy of ``table`` with :meth:`rectify_boxes` applied; the boxes as they were, in
        the frame's pixels, are kept in the extra column :data:`FRAME_BOX_COLUMN`
        (:func:`in_frame_pixels`)."""
        if self.is_ideal:
            return table
        extra = dict(table.extra)
        extra.setdefault(FRAME_BOX_COLUMN, table.boxes.copy())
        return BoxTable(
            table.frame,
            self.rectify_boxes(table.boxes),
            table.track_id,
            table.score,
            table.cls,
            extra,
        )


def in_frame_pixels(table: BoxTable) -> BoxTable:
    """``table`` with its boxes in the frame's own pixels: the boxes
    :meth:`Intrinsics.rectify_table` mapped into the ideal camera back as they were (column
    :data:`FRAME_BOX_COLUMN`), else ``table`` itself (its boxes were never mapped)."""
    if FRAME_BOX_COLUMN not in table.extra:
        return table
    boxes = frame_pixel_boxes(table)
    return BoxTable(table.frame, boxes, table.track_id, table.score, table.cls, table.extra)


class RectifiedDetector:
    """A :class:`~slopedist.io.detections.onnx_detector.Detector` whose boxes are mapped into the
    ideal camera of ``intrinsics`` (:meth:`Intrinsics.rectify_table`); the mapping is counted in
    its post-processing time."""

    def __init__(self, detector: Detector, intrinsics: Intrinsics) -> None:
        self.detector, self.intrinsics = detector, intrinsics
        self.model_path = getattr(detector, "model_path", None)
        self.last_timing = DetectionTiming()

    def detect(self, image_bgr: NDArray[np.uint8], frame: int = 0) -> BoxTable:
        """The wrapped detector's boxes, in the ideal camera."""
        table = self.detector.detect(image_bgr, frame)
        t0 = time.perf_counter()
        mapped = self.intrinsics.rectify_table(table)
        t = self.detector.last_timing
        self.last_timing = replace(t, postprocess_s=t.postprocess_s + time.perf_counter() - t0)
        return mapped
