"""The frame size the built-in visual odometry works at, and the checks of its input frames.

Dashcam frames (1920×1080 and more) carry more pixels than the rotation needs: the corner
search and the image statistics grow with the pixel count while the tracks stay as few. Frames
wider than ``max_width_px`` are therefore scaled down (equally in both axes) before tracking,
the camera, the masked boxes and the track positions scaled to match; narrower frames (KITTI's
1242 px) are used as they are, bit for bit.

Pixel convention: pixel centres at integer coordinates, so that a point ``u`` of the full frame
is at ``s·(u + 0.5) − 0.5`` in a frame scaled by ``s`` (what ``cv2.resize`` does).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.core.errors import DataMismatchError

FloatArray = NDArray[np.float64]

LINEAR_MIN_SCALE = 0.5
"""Frames scaled by more than this are interpolated bilinearly, by less (or by exactly a half)
area-averaged (:meth:`WorkingSize.image`)."""


def check_gray_frame(image_gray: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """``image_gray`` as an ``H×W`` uint8 array, or :class:`DataMismatchError`."""
    image = np.asarray(image_gray)
    if image.ndim != 2 or image.dtype != np.uint8:
        raise DataMismatchError(
            f"visual odometry needs grey H×W uint8 frames, got shape {image.shape} "
            f"and dtype {image.dtype}"
        )
    return image


def check_principal_point(camera: Camera, width: int, height: int) -> None:
    """Fail when the camera's principal point lies outside a ``width×height`` frame."""
    if not (0 < camera.c_x < width and 0 < camera.c_y < height):
        raise DataMismatchError(
            f"the camera's principal point ({camera.c_x:.1f}, {camera.c_y:.1f}) px lies "
            f"outside the {width}×{height} frames: calibration and frames do not match"
        )


@dataclass(frozen=True)
class WorkingSize:
    """How full frames map to the frames the odometry tracks in.

    Attributes:
        full_size: ``(width, height)`` of the input frames, pixels.
        size: ``(width, height)`` of the working frames, pixels (``full_size`` when unscaled).
        camera: the camera of the working frames (focal length and principal point scaled).
    """

    full_size: tuple[int, int]
    size: tuple[int, int]
    camera: Camera

    @classmethod
    def choose(
        cls, camera: Camera, width: int, height: int, max_width_px: int | None
    ) -> WorkingSize:
        """The working size of ``width×height`` frames of ``camera``: scaled to
        ``max_width_px`` wide when wider (None: never scaled)."""
        if max_width_px is None or width <= max_width_px:
            return cls((width, height), (width, height), camera)
        work_w = int(max_width_px)
        work_h = max(1, round(height * work_w / width))
        sx, sy = work_w / width, work_h / height
        scaled = replace(
            camera,
            f=camera.f * sx,
            c_x=sx * (camera.c_x + 0.5) - 0.5,
            c_y=sy * (camera.c_y + 0.5) - 0.5,
            image_width=work_w,
            image_height=work_h,
        )
        return cls((width, height), (work_w, work_h), scaled)

    @property
    def scaled(self) -> bool:
        """True when the working frames are smaller than the input frames."""
        return self.size != self.full_size

    def _scale(self) -> FloatArray:
        return np.array(self.size, dtype=np.float64) / np.array(self.full_size, dtype=np.float64)

    def image(self, image: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """A full grey frame at the working size (contiguous; the same pixels when unscaled).

        Scales above :data:`LINEAR_MIN_SCALE` interpolate bilinearly: OpenCV's area averaging
        at a fractional scale costs 9 ms per 1920×1080 frame (against 1 ms), and on the shared
        KITTI excerpts scaled to 1920 px wide the rotations are as accurate either way
        (``benchmarks/realtime.py --part widths``). Smaller scales average areas.
        """
        if not self.scaled:
            return np.ascontiguousarray(image)
        linear = self._scale()[0] > LINEAR_MIN_SCALE
        interpolation = cv2.INTER_LINEAR if linear else cv2.INTER_AREA
        return np.asarray(cv2.resize(image, self.size, interpolation=interpolation))

    def boxes(self, boxes: FloatArray) -> FloatArray:
        """``(M, 4)`` boxes (left, top, right, bottom) from full to working pixels."""
        if not self.scaled or len(boxes) == 0:
            return boxes
        s = np.tile(self._scale(), 2)
        return s * (boxes + 0.5) - 0.5

    def to_full(self, pts: NDArray[np.float32]) -> NDArray[np.float32]:
        """``(N, 2)`` working-frame pixels as full-frame pixels."""
        if not self.scaled:
            return pts.copy()
        return ((pts + 0.5) / self._scale() - 0.5).astype(np.float32)
