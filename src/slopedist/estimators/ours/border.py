"""Which boxes of ``ours`` are cut by the image border (their vehicle may extend beyond it).

Image coordinates in pixels: columns grow to the right, rows downwards; a box is (left, top,
right, bottom). The test is :func:`slopedist.detections.boxes.border_cuts`, the one behind the
``cut`` column of every method, so the cues ``ours`` censors are the edges that column names.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from slopedist.camera import Camera
from slopedist.detections.boxes import border_cuts
from slopedist.estimators.base import image_size
from slopedist.estimators.ours.fusion import any_true
from slopedist.estimators.ours.records import BorderCuts

FloatArray = NDArray[np.float64]


class ImageBorder:
    """The image border as the camera or, without its image size, the boxes reveal it.

    The image size is the camera's when known; otherwise the largest right/bottom edge seen
    so far (the current boxes included) stands for the last column/row once it lies beyond
    twice the principal point (before that, no box is cut on that side). :meth:`reset`
    forgets what was seen (new sequence).
    """

    def __init__(self, camera: Camera) -> None:
        self._camera = camera
        self.known_size = image_size(camera)
        """The camera's image ``(width, height)`` in pixels, or None when unknown."""
        self.reset()

    def reset(self) -> None:
        self._max_right = -math.inf
        self._max_bottom = -math.inf

    def cut_edges(self, boxes: FloatArray) -> NDArray[np.bool_]:
        """``(n, 4)`` flags: is the (left, top, right, bottom) edge of each box ``(n, 4)`` cut?"""
        return border_cuts(boxes, self.known_size or self._seen_size(boxes))

    def cuts(self, boxes: FloatArray) -> BorderCuts | None:
        """Boxes ``(n, 4)`` cut by the border: (left or right, top, bottom) flags, or None
        when no box is."""
        cut = self.cut_edges(boxes)
        if not any_true(cut):
            return None
        return BorderCuts(cut[:, 0] | cut[:, 2], cut[:, 1], cut[:, 3])

    def _seen_size(self, boxes: FloatArray) -> tuple[float, float]:
        """The image size as far as the boxes show it (inf while unknown)."""
        cam = self._camera
        seen_right, seen_bottom = np.maximum.reduce(boxes[:, 2:4], axis=0).tolist()
        self._max_right = max(self._max_right, seen_right)
        self._max_bottom = max(self._max_bottom, seen_bottom)
        right = self._max_right if self._max_right >= 2 * cam.c_x else math.inf
        bottom = self._max_bottom if self._max_bottom >= 2 * cam.c_y else math.inf
        return right + 1.0, bottom + 1.0
