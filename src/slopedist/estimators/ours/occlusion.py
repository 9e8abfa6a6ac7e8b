"""Occlusion by nearer targets for ``ours``: which box sides a nearer box may hide, and the
extra variance of a size cue that says farther than the ground contact beyond its noise.

Pure, vectorised functions (no state). Boxes are (left, top, right, bottom) in pixels, image rows
growing downwards; cues are log distances ``ℓ = log(Z / 1 m)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.core.rectangles import contains_edges, meets_segment
from slopedist.io.detections.boxes import overlapping_pairs

FloatArray = NDArray[np.float64]


def hidden_sides(
    boxes: ArrayLike, tol_px: float = 1.5
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Whether each box's width and height may be cut short by a nearer box.

    Box ``j`` is nearer than box ``i`` when its bottom is lower in the image (``b_j > b_i``:
    on a common road a nearer vehicle touches the ground lower). An edge of ``i`` that lies on
    a nearer box that overlaps it (or touches it, within ``tol_px``) may be where ``i``'s
    vehicle disappears behind the nearer one rather than where it ends: a box drawn around what
    is visible (an image detector's, a LiDAR cluster's) is then narrower or shorter than the
    vehicle. (A box drawn around the whole vehicle, as labels and LiDAR detectors' 3D boxes are,
    is not cut, but cannot be told apart from the box alone.)

    Args:
        boxes: ``(N, 4)`` (left, top, right, bottom), pixels.
        tol_px: how close an edge must come to a nearer box to count as on it, pixels.

    Returns:
        ``(width_cut, height_cut)``: ``(N,)`` flags, a left or right edge (resp. top or bottom
        edge) on a nearer box.
    """
    b = np.asarray(boxes, dtype=float).reshape(-1, 4)
    lo = b[:, :2] - tol_px  # each box's extent (columns, rows), widened by tol
    hi = b[:, 2:] + tol_px
    if b.shape[0] <= _DENSE_MAX_BOXES or not np.isfinite(b).all() or tol_px < 0:
        return _hidden_sides_dense(b, lo, hi)
    if b.shape[0] <= _PAIRS_MAX_BOXES:
        return _hidden_sides_pairs(b, lo, hi)
    return _hidden_sides_sweep(b, lo, hi)


_DENSE_MAX_BOXES = 48
"""Up to this many boxes every pair is tested at once (cheaper than sorting for a few)."""

_PAIRS_MAX_BOXES = 400
"""Up to this many boxes the overlapping pairs are listed and tested; beyond, where a crowded
image has too many of them, the sweep answers per box."""


def _hidden_sides_pairs(
    b: FloatArray, lo: FloatArray, hi: FloatArray
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """:func:`hidden_sides` over the list of the pairs of boxes ``b[i]`` and widened boxes
    ``(lo, hi)[j]`` that overlap (:func:`overlapping_pairs`: ``O(n log n)`` plus their number),
    with ``j`` nearer."""
    i, j = overlapping_pairs(b, np.concatenate([lo, hi], axis=1))
    nearer = b[j, 3] > b[i, 3]
    i, j = i[nearer], j[nearer]
    cut = np.zeros((b.shape[0], 2), dtype=bool)
    if not i.size:
        return cut[:, 0], cut[:, 1]
    lo_j, hi_j = lo[j], hi[j]
    bi = b[i]
    on = (
        ((bi[:, :2] >= lo_j) & (bi[:, :2] <= hi_j))  # left / top edge of i on j
        | ((bi[:, 2:] >= lo_j) & (bi[:, 2:] <= hi_j))
    )  # right / bottom edge of i on j
    cut[i[on[:, 0]], 0] = True
    cut[i[on[:, 1]], 1] = True
    return cut[:, 0], cut[:, 1]


def _hidden_sides_dense(
    b: FloatArray, lo: FloatArray, hi: FloatArray
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """:func:`hidden_sides` with every pair tested at once as ``(i, j, axis)`` arrays
    (:func:`_cuts_by`)."""
    cut = np.logical_or.reduce(_cuts_by(b[:, None], lo[None], hi[None], b[None, :, 3]), axis=1)
    return cut[:, 0], cut[:, 1]


def _cuts_by(
    b_i: FloatArray, lo_j: FloatArray, hi_j: FloatArray, bottom_j: FloatArray
) -> NDArray[np.bool_]:
    """Whether the widened box ``(lo_j, hi_j)`` with the bottom row ``bottom_j`` cuts the width
    and the height (last axis) of box ``b_i``, broadcast over the leading axes: ``b_i``
    overlaps it, ``j`` is nearer (its bottom lower) and an edge of ``i`` lies within ``j``'s
    widened extent (columns: a side, rows: top or bottom)."""
    b_lo, b_hi = b_i[..., :2], b_i[..., 2:]
    reach = np.minimum(b_hi, hi_j) > np.maximum(b_lo, lo_j)
    near = reach[..., 0] & reach[..., 1] & (bottom_j > b_i[..., 3])
    on = ((b_lo >= lo_j) & (b_lo <= hi_j)) | ((b_hi >= lo_j) & (b_hi <= hi_j))
    return on & near[..., None]


def _hidden_sides_sweep(
    b: FloatArray, lo: FloatArray, hi: FloatArray
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """:func:`hidden_sides` for many finite boxes (widened by a ``tol_px ≥ 0``), with the
    answers of :func:`_hidden_sides_dense`: a cut is looked for among each box's neighbours
    in column order first (:func:`_witnessed_cuts`; in a crowded image nearly every box is cut
    by one of them), and the sweep (:func:`_swept_cuts`) decides the boxes left."""
    width_cut, height_cut = _witnessed_cuts(b, lo, hi)
    left = np.flatnonzero(~(width_cut & height_cut))
    width_swept, height_swept = _swept_cuts(b, lo, hi, left)
    width_cut[left] |= width_swept
    height_cut[left] |= height_swept
    return width_cut, height_cut


_WITNESS_NEIGHBOURS = 16
"""How many neighbours on each side, in the order of the left edges, :func:`_witnessed_cuts`
tests a box against at most."""


def _witnessed_cuts(
    b: FloatArray, lo: FloatArray, hi: FloatArray
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """The cuts of :func:`hidden_sides` that a box's neighbours in the order of the left edges
    give (:func:`_cuts_by`), a subset of them: the neighbours on both sides one step further
    at a time, for the boxes not yet cut on both axes, up to :data:`_WITNESS_NEIGHBOURS`."""
    n = b.shape[0]
    order = np.argsort(b[:, 0], kind="stable")
    place = np.empty(n, dtype=np.intp)
    place[order] = np.arange(n)
    cut = np.zeros((n, 2), dtype=bool)
    todo = np.arange(n)
    for d in range(1, _WITNESS_NEIGHBOURS + 1):
        for step in (d, -d):
            at = place[todo] + step
            inside = (at >= 0) & (at < n)
            i, j = todo[inside], order[at[inside]]
            cut[i] |= _cuts_by(b[i], lo[j], hi[j], b[j, 3])
        todo = todo[~cut[todo].all(axis=1)]
        if not todo.size:
            break
    return cut[:, 0], cut[:, 1]


def _swept_cuts(
    b: FloatArray, lo: FloatArray, hi: FloatArray, which: NDArray[np.intp]
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """The cuts of :func:`hidden_sides` of the boxes ``b[which]`` by all of ``b``, in
    ``O(n log² n)`` whatever the number of overlapping pairs.

    A nearer box ``j`` reaches box ``i`` when ``i``'s bottom row lies between the widened top of
    ``j`` and ``j``'s own bottom (``lo_j < b_i < b_j``: nearer, and the rows overlap) and the
    columns overlap. Then ``i``'s height may be cut (its bottom edge lies on ``j``), and its
    width when its left edge (``lo_j ≤ l_i < hi_j``) or its right edge (``lo_j < r_i ≤ hi_j``)
    lies within ``j``'s columns: queries of the points ``(l_i, b_i)``, ``(r_i, b_i)`` and of the
    bottom edge ``(l_i, r_i) × {b_i}`` against the rectangles ``(lo_j, hi_j) × (lo_j, b_j)``.
    """
    rect_x = (lo[:, 0], hi[:, 0])
    rect_y = (lo[:, 1], b[:, 3])
    q = b[which]
    bottom = q[:, 3]
    proper = (q[:, 2] > q[:, 0]) & (q[:, 3] > q[:, 1])
    left_on, right_on = contains_edges(rect_x, rect_y, q[:, 0], q[:, 2], bottom)
    height_cut = meets_segment(rect_x, rect_y, (q[:, 0], q[:, 2]), bottom, start_held=left_on)
    return proper & (left_on | right_on), proper & height_cut


def unexplained_excess(
    y_cue: ArrayLike,
    var_cue: ArrayLike,
    y_ref: ArrayLike,
    var_ref: ArrayLike,
    gate_sigma: float = 3.0,
) -> FloatArray:
    """How far a log-distance cue says farther than a reference beyond their own noise:
    ``max(y_cue − y_ref, 0)² − gate_sigma²·(var_cue + var_ref)`` (log², > 0 only for an
    outlier on the far side; NaN where either is missing)."""
    excess = np.maximum(np.asarray(y_cue) - np.asarray(y_ref), 0.0)
    return np.asarray(
        excess * excess - gate_sigma * gate_sigma * (np.asarray(var_cue) + np.asarray(var_ref))
    )


def occlusion_log_var(unexplained: ArrayLike, cut: ArrayLike) -> FloatArray:
    """Extra variance of a log-distance size cue whose dimension may be cut short by a nearer
    vehicle (:func:`hidden_sides`).

    Hiding part of a dimension only shrinks a box drawn around what is visible, which makes the
    cue's distance too large; so for a dimension that may be cut the cue is a censored
    measurement: what it says beyond an independent reference (the ground contact) may be
    hiding, by any amount. An excess the two cues' own noise explains, or a cue that says nearer
    than the reference (hiding cannot explain that), leaves the cue alone; beyond it the
    unexplained excess (:func:`unexplained_excess`) is taken as the cue's extra error variance.
    No parameter besides the outlier test's.

    Args:
        unexplained: :func:`unexplained_excess` of the cue against the reference (log²).
        cut: whether the cue's dimension may be cut short, broadcastable to ``unexplained``.
    """
    u = np.asarray(unexplained)
    return np.asarray(np.where(np.asarray(cut) & (u > 0.0), u, 0.0))
