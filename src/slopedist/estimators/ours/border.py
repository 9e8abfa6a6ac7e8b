"""Which boxes of ``ours`` touch the image border (their vehicle may extend beyond it).

Image coordinates in pixels: columns grow to the right, rows downwards; a box is (left, top,
right, bottom).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from slopedist.camera import Camera
from slopedist.estimators.ours.fusion import any_true
from slopedist.estimators.ours.records import BorderCuts

FloatArray = NDArray[np.float64]

_BORDER_LOW = np.array([0.5, 0.5, -math.inf, -math.inf])
"""A box edge at or below these (left, top) touches the image's left or top border."""


class ImageBorder:
    """The image border as the boxes of a sequence reveal it.

    The image size is the camera's when known; otherwise the largest right/bottom edge seen
    so far (the current boxes included) stands for the border once it lies beyond twice the
    principal point. :meth:`reset` forgets what was seen (new sequence).
    """

    def __init__(self, camera: Camera) -> None:
        self._camera = camera
        self._known_extent = (
            (float(camera.image_width) - 1.0, float(camera.image_height) - 1.0)
            if camera.image_width and camera.image_height
            else None
        )
        self.reset()

    def reset(self) -> None:
        self._max_right = -math.inf
        self._max_bottom = -math.inf
        self._high = np.full(4, math.inf)  # box edges at or beyond touch the border

    def cuts(self, boxes: FloatArray) -> BorderCuts | None:
        """Boxes ``(n, 4)`` touching the border: (left or right, top, bottom) flags, or None
        when no box touches it."""
        right, bottom = self._known_extent or self._seen_extent(boxes)
        if self._high[2] != right - 0.5 or self._high[3] != bottom - 0.5:
            self._high = np.array([math.inf, math.inf, right - 0.5, bottom - 0.5])
        cut = (boxes <= _BORDER_LOW) | (boxes >= self._high)
        if not any_true(cut):
            return None
        return BorderCuts(cut[:, 0] | cut[:, 2], cut[:, 1], cut[:, 3])

    def _seen_extent(self, boxes: FloatArray) -> tuple[float, float]:
        """The last column and row of the image as far as the boxes show it (inf while
        unknown)."""
        cam = self._camera
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
        return right, bottom
