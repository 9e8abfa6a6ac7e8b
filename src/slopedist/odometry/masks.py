"""Vehicle boxes as masks of the built-in visual odometry: features are not taken inside them.

Boxes are ``(M, 4)`` arrays ``(left, top, right, bottom)`` in full-resolution pixels.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.core.errors import DataMismatchError

FloatArray = NDArray[np.float64]


def check_boxes(mask_boxes: ArrayLike | None) -> FloatArray:
    """The ``(M, 4)`` mask boxes (left, top, right, bottom) pixels, without the rows that are
    not finite (a NaN or infinite box, flagged ``non_finite_box`` by the estimators, masks
    nothing).

    Raises:
        DataMismatchError: not an ``(N, 4)`` array.
    """
    if mask_boxes is None:
        return np.empty((0, 4))
    boxes = np.asarray(mask_boxes, dtype=float)
    if boxes.size == 0:
        return np.empty((0, 4))
    if boxes.ndim != 2 or boxes.shape[1] != 4:
        raise DataMismatchError(
            f"mask_boxes must be (N, 4) (left, top, right, bottom) pixels, got {boxes.shape}"
        )
    return boxes[np.isfinite(boxes).all(axis=1)]


def grown_boxes(boxes: FloatArray, margin_px: float) -> FloatArray:
    """``(M, 4)`` boxes (left, top, right, bottom) grown by ``margin_px`` on every side."""
    return boxes + np.array([-margin_px, -margin_px, margin_px, margin_px])


def inside_boxes(pts: NDArray[np.float32], boxes: FloatArray) -> NDArray[np.bool_]:
    """``(N,)`` True for points inside any of the ``(M, 4)`` boxes (left, top, right, bottom)."""
    if len(boxes) == 0 or len(pts) == 0:
        return np.zeros(len(pts), dtype=bool)
    x = pts[:, 0:1]
    y = pts[:, 1:2]
    inside = (x >= boxes[:, 0]) & (x <= boxes[:, 2]) & (y >= boxes[:, 1]) & (y <= boxes[:, 3])
    return np.asarray(inside.any(axis=1))


def half_size_corner_mask(
    shape: tuple[int, ...],
    tracks_px: NDArray[np.float32],
    boxes: FloatArray,
    radius: int,
    border: int,
) -> NDArray[np.uint8]:
    """Where new corners may be detected on the half-resolution copy of a frame (``shape``
    its shape): 255, except 0 within ``radius`` (half-resolution pixels) of a track
    (``tracks_px``: ``(N, 2)`` full-resolution pixels), within ``border`` of the edge and inside
    the ``(M, 4)`` boxes (full-resolution pixels)."""
    mask: NDArray[np.uint8]
    if len(tracks_px):
        occupied = np.zeros(shape, dtype=np.uint8)
        xy = np.clip((tracks_px * 0.5).astype(np.intp), 0, [shape[1] - 1, shape[0] - 1])
        occupied[xy[:, 1], xy[:, 0]] = 255
        kernel = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
        mask = np.asarray(cv2.bitwise_not(cv2.dilate(occupied, kernel)))
    else:
        mask = np.full(shape, 255, dtype=np.uint8)
    mask[:border] = 0
    mask[-border:] = 0
    mask[:, :border] = 0
    mask[:, -border:] = 0
    for left, top, right, bottom in boxes * 0.5:
        mask[
            max(int(top), 0) : max(math.ceil(bottom) + 1, 0),
            max(int(left), 0) : max(math.ceil(right) + 1, 0),
        ] = 0
    return mask
