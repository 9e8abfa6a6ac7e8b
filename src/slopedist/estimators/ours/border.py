"""Which boxes of ``ours`` are cut by the image border (their vehicle may extend beyond it).

Image coordinates in pixels: columns grow to the right, rows downwards; a box is (left, top,
right, bottom). The test is :func:`slopedist.io.detections.boxes.border_cuts`, the one behind the
``cut`` column of every method, so the cues ``ours`` censors are the edges that column names.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.estimators.base import (
    EstimateStatus,
    FrameEstimates,
    MissingReason,
    image_size,
)
from slopedist.estimators.ours.records import BorderCuts
from slopedist.io.detections.boxes import border_cuts

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
        """``(n, 4)`` flags: is the (left, top, right, bottom) edge of each box ``(n, 4)`` cut?
        (:func:`~slopedist.io.detections.boxes.border_cuts`)"""
        return border_cuts(boxes, self.known_size or self._seen_size(boxes))

    def _seen_size(self, boxes: FloatArray) -> tuple[float, float]:
        """The image size as far as the boxes show it (inf while unknown)."""
        cam = self._camera
        seen_right, seen_bottom = np.maximum.reduce(boxes[:, 2:4], axis=0).tolist()
        self._max_right = max(self._max_right, seen_right)
        self._max_bottom = max(self._max_bottom, seen_bottom)
        right = self._max_right if self._max_right >= 2 * cam.c_x else math.inf
        bottom = self._max_bottom if self._max_bottom >= 2 * cam.c_y else math.inf
        return right + 1.0, bottom + 1.0


def border_cuts_of(cut: NDArray[np.bool_]) -> BorderCuts | None:
    """The (left or right, top, bottom) flags of boxes whose edges ``cut`` ``(n, 4)``
    (:meth:`ImageBorder.cut_edges`) the border cuts, or None when no box is cut."""
    if not cut.any():
        return None
    return BorderCuts(cut[:, 0] | cut[:, 2], cut[:, 1], cut[:, 3])


def settle_border_cuts(
    est: FrameEstimates, cut: NDArray[np.bool_], use_width: bool, use_ground_contact: bool
) -> None:
    """The states of the boxes cut by the image border (``cut``: ``(n, 4)`` left, top, right,
    bottom, the ``cut`` column's test, :func:`~slopedist.io.detections.boxes.border_cuts`): a box
    keeps ``ok`` while one of its cues is uncut (the height: neither top nor bottom cut; the
    width: no side cut; the ground contact: no bottom cut); otherwise it is an ``upper_bound``,
    reason ``cut_bottom``, whose distance is the least of the cut contact and width cues (each
    says at least the true distance: the lowest visible row lies above the contact row, the
    visible width is less than the vehicle's)."""
    if not cut.any():
        return
    side = cut[:, 0] | cut[:, 2]
    top, bottom = cut[:, 1], cut[:, 3]
    uncut = ~top & ~bottom  # the height cue
    if use_width:
        uncut |= ~side
    if use_ground_contact:
        uncut |= ~bottom
    bounded = ~uncut & (est.status == EstimateStatus.OK.value)
    if not bounded.any():
        return
    contact = np.where(bottom, est.extra["distance_ground_contact_m"], np.inf)
    width = np.where(side, est.extra["distance_width_m"], np.inf)
    bound = np.fmin(contact, width)  # NaN where a cue is missing: the other
    est.distance_m[bounded] = bound[bounded]
    est.set_state(bounded, EstimateStatus.UPPER_BOUND, MissingReason.CUT_BOTTOM)
