"""Which box of a frame continues which track of ``ours``, and where the tracks' boxes go.

Boxes that carry a track id (``>= 0``) continue the track with that id; boxes without one are
matched to the id-less tracks by 2D IoU with the tracks' predicted boxes (greedy, best pair
first). A track's box is predicted by turning its last box with the camera's own rotation
(:func:`turn_boxes`) and moving it on at its image velocity (:func:`moved_boxes`).

Image coordinates in pixels (a box is left, top, right, bottom); times in seconds; rotations
camera-to-world.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from slopedist.estimators.ours.tracks import Tracks
from slopedist.io.detections.boxes import iou_matrix, pair_iou, proper_box_rows

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def associate(
    tracks: Tracks,
    boxes: FloatArray,
    track_ids: IntArray,
    min_iou: float = 0.3,
    predicted: FloatArray | None = None,
) -> IntArray:
    """Row of ``tracks`` each box continues, or −1 for a new track.

    Boxes with an id ``>= 0`` follow the live track with that id (a second box with the same id
    in one frame starts a new track); the others are matched by IoU to the live id-less tracks'
    ``predicted`` boxes ``(T, 4)`` (default: their last boxes), greedily, best pair first.
    """
    n = boxes.shape[0]
    if len(tracks) == 0 or n == 0:
        return np.full(n, -1, np.int64)
    ids = track_ids.tolist()
    by_id = tracks.row_of_box_track_id()
    rows = np.array([by_id.get(i, -1) if i >= 0 else -1 for i in ids], dtype=np.int64)
    if len(set(ids)) < n:  # a second box with an id already taken starts a new track
        seen: set[int] = set()
        for k, i in enumerate(ids):
            if i >= 0 and i in seen:
                rows[k] = -1
            seen.add(i)
    has_id = track_ids >= 0
    if has_id.all():
        return rows
    free_boxes = np.flatnonzero(~has_id)
    free_tracks = np.flatnonzero(tracks.box_track_id < 0)  # id-less tracks are never taken by an id
    if free_boxes.size and free_tracks.size:
        ref = tracks.last_box_px.T if predicted is None else predicted
        b, t = greedy_iou_matches(boxes[free_boxes], ref[free_tracks], min_iou)
        rows[free_boxes[b]] = free_tracks[t]
    return rows


def greedy_iou_matches(
    boxes: FloatArray, tracks: FloatArray, min_iou: float
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Pairs ``(box, track)`` of boxes ``(N, 4)`` and tracks' boxes ``(T, 4)`` matched one to
    one by IoU ≥ ``min_iou``, greedily: best pair first, equal IoUs in row-major order.

    Many boxes are matched in stages of falling IoU (:data:`_IOU_STAGES`, then ``min_iou``):
    greedy matching takes the pairs in order of falling IoU, so every pair above a stage's level
    is decided before any below it, and the next stage needs only the boxes and tracks left
    over. At each stage a box is compared with its :data:`GATE_TRACKS` nearest tracks left
    over (:func:`nearest_tracks`). Where no box has more tracks than that within its reach at
    ``min_iou`` (every realistic image), these are the matches of one greedy pass over all
    pairs. In a crowd of near-duplicate boxes (hundreds on top of each other) the gate bounds
    the work per box, and a box whose nearest tracks all went to better pairs may start a new
    track where the full matching would have given it a farther one.
    """
    n, m = boxes.shape[0], tracks.shape[0]
    levels = [min_iou]
    if n * m > _DENSE_MAX_PAIRS:
        levels = [level for level in _IOU_STAGES if level > min_iou] + levels
    free_b, free_t = np.arange(n), np.arange(m)
    matched_b, matched_t = [free_b[:0]], [free_t[:0]]
    for level in levels:
        bi, ti, iou = _iou_candidates(boxes[free_b], tracks[free_t], level)
        b, t = _greedy(bi, ti, iou)
        matched_b.append(free_b[b])
        matched_t.append(free_t[t])
        free_b, free_t = np.delete(free_b, b), np.delete(free_t, t)
        if not (free_b.size and free_t.size):
            break
    return np.concatenate(matched_b), np.concatenate(matched_t)


_IOU_STAGES = (0.9, 0.7, 0.5)
"""IoU levels, falling, at which :func:`greedy_iou_matches` of many boxes is cut into stages."""


def _greedy(
    bi: NDArray[np.intp], ti: NDArray[np.intp], iou: FloatArray
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Greedy one-to-one matching of the candidate pairs ``(bi, ti)`` (row-major) by falling
    ``iou``, equal values in the order given: the matched pairs' indices."""
    order = np.argsort(-iou, kind="stable")
    taken_b: set[int] = set()
    taken_t: set[int] = set()
    pairs: list[tuple[int, int]] = []
    for b, t in zip(bi[order].tolist(), ti[order].tolist(), strict=True):
        if b not in taken_b and t not in taken_t:
            taken_b.add(b)
            taken_t.add(t)
            pairs.append((b, t))
    matched = np.array(pairs, dtype=np.intp).reshape(-1, 2)
    return matched[:, 0], matched[:, 1]


_DENSE_MAX_PAIRS = 2048
"""Up to this many (box, track) pairs every IoU is computed at once (cheaper than sorting)."""


def _iou_candidates(
    boxes: FloatArray, tracks: FloatArray, min_iou: float
) -> tuple[NDArray[np.intp], NDArray[np.intp], FloatArray]:
    """The (box, track) pairs with IoU ≥ ``min_iou``, row-major, and their IoU.

    For a few boxes (or ``min_iou ≤ 0``) all of them, from the full matrix. For many, only
    among each box's :data:`GATE_TRACKS` nearest tracks (:func:`nearest_tracks`): the same
    pairs wherever no box has more tracks than that within reach of an IoU of ``min_iou``, and
    at most that many pairs per box in a crowd of near-duplicate boxes, where listing them all
    would cost the square of the crowd.
    """
    if boxes.shape[0] * tracks.shape[0] <= _DENSE_MAX_PAIRS or not min_iou > 0:
        iou = iou_matrix(boxes, tracks)
        bi, ti = np.nonzero(iou >= min_iou)
        return bi, ti, iou[bi, ti]
    bi, ti = nearest_tracks(boxes, tracks, min_iou, GATE_TRACKS)
    iou = pair_iou(boxes, tracks, bi, ti)
    keep = np.flatnonzero(iou >= min_iou)
    keep = keep[np.lexsort((ti[keep], bi[keep]))]  # row-major, as np.nonzero gives them
    return bi[keep], ti[keep], iou[keep]


GATE_TRACKS = 8
"""At most this many tracks each box is compared with at a stage of :func:`greedy_iou_matches`
of many boxes: its nearest ones (:func:`nearest_tracks`)."""


def nearest_tracks(
    boxes: FloatArray, tracks: FloatArray, min_iou: float, k: int
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Pairs ``(box, track)`` of boxes ``(N, 4)`` and tracks' boxes ``(T, 4)`` (pixels): each
    box's ``k`` nearest tracks among those within its reach, box by box, nearest first.

    The distance of two boxes is the largest difference of their left, top, right and bottom
    edges (pixels). Boxes with an IoU of ``t > 0`` overlap by at least ``t`` of the wider one's
    width, which is at most ``1/t`` of either's: their edges differ by at most
    ``(1 − t)/t·max(w, h)`` of the box's width ``w`` and height ``h``, its reach at
    ``t = min_iou``. A box with at most ``k`` tracks within reach is paired with all of them,
    so with every track of an IoU ≥ ``min_iou``. Boxes that are not finite with right > left
    and bottom > top have an IoU of 0 with every box and are paired with none.
    """
    ib, it = proper_box_rows(boxes), proper_box_rows(tracks)
    k = min(k, it.size)
    if not (ib.size and k):
        return ib[:0], it[:0]
    from scipy.spatial import cKDTree  # here: 0.15 s of imports, needed only for many boxes

    b = boxes[ib]
    reach = (1.0 - min_iou) / min_iou * np.maximum(b[:, 2] - b[:, 0], b[:, 3] - b[:, 1])
    reach *= 1.0 + 1e-9  # rounding of the edges' differences
    tree = cKDTree(tracks[it])
    dist, near = tree.query(b, k=k, p=np.inf, distance_upper_bound=float(reach.max()))
    dist, near = dist.reshape(-1, k), near.reshape(-1, k)
    row, col = np.nonzero(dist <= reach[:, None])
    return ib[row], it[near[row, col]]


def turn_boxes(
    boxes: FloatArray,
    f: float,
    c_x: float,
    c_y: float,
    R_last: FloatArray,
    R_now: FloatArray | None,
) -> tuple[FloatArray, FloatArray]:
    """Where boxes ``(T, 4)`` seen at camera-to-world rotations ``R_last`` ``(T, 3, 3)`` go
    when the camera has turned to ``R_now`` ``(3, 3)`` (pixels), and the depth ratio
    ``Z_new/Z_old`` ``(T,)`` of the points seen at their centres (the ego's own rotation
    changes every target's depth, most for targets off to the side).

    A pure rotation moves every pixel whatever its depth; between two frames it is small, so
    each box is shifted by the motion of its centre (its size changes by a second-order
    amount). ``R_now`` None (rotation unknown) leaves the boxes where they were.

    numpy multiplies ``R_last`` with BLAS when each matrix is contiguous in memory and with a
    loop of its own otherwise, and the two may differ in the last bit: the tracks' rotations
    keep the memory layout :class:`~slopedist.estimators.ours.tracks.Tracks` gives them
    (track axis innermost after :meth:`~slopedist.estimators.ours.tracks.Tracks.concat`,
    outermost after :meth:`~slopedist.estimators.ours.tracks.Tracks.take`), on which the
    records' last digits depend.
    """
    b = np.asarray(boxes, dtype=float)
    if b.shape[0] == 0 or R_now is None:
        return b.copy(), np.ones(b.shape[0])
    c = np.array([c_x, c_y])
    mid = 0.5 * (b[:, :2] + b[:, 2:])  # box centres (u, v)
    ray = np.ones((b.shape[0], 3))
    ray[:, :2] = (mid - c) * (1.0 / f)
    R_now = np.asarray(R_now, dtype=float)
    if (R_last == R_last[0]).all():  # all seen at one rotation: one product for all
        out = ray @ (R_last[0].T @ R_now)  # rows: (R_nowᵀ·R_last·ray)ᵀ
    else:
        out = (R_last @ ray[:, :, None])[..., 0] @ R_now
    z = out[:, 2]
    shift = c + out[:, :2] * (f / np.maximum(z, 1e-6))[:, None] - mid
    return b + np.concatenate([shift, shift], axis=1), z


def depth_ratios(
    boxes_px: FloatArray,
    f: float,
    c_x: float,
    c_y: float,
    R_last: FloatArray,
    R_now: FloatArray | None,
) -> FloatArray:
    """The second output of :func:`turn_boxes` alone: ``Z_new/Z_old`` ``(T,)`` of the points
    seen at the centres of the boxes ``boxes_px`` ``(4, T)`` (as :attr:`Tracks.last_box_px`)
    when the camera turns from the camera-to-world rotations ``R_last`` ``(3, 3, T)`` (as
    :attr:`Tracks.R_world_cam`) to ``R_now`` (ones when it is None)."""
    b = np.asarray(boxes_px, dtype=float)
    if b.shape[1] == 0 or R_now is None:
        return np.ones(b.shape[1])
    # the new depth of the old ray ((u − c_x)/f, (v − c_y)/f, 1) is R_now's z axis (in the
    # world) · R_last·ray, i.e. ray · (R_lastᵀ·R_now[:, 2])
    m = b.shape[1]
    R_rows = np.ascontiguousarray(R_last).reshape(3, 3 * m)  # [a, b·T + t] = R_last[a, b, t]
    q = (np.asarray(R_now, dtype=float)[:, 2] @ R_rows).reshape(3, m)
    inv_2f = 0.5 / f
    return (
        (b[0] + b[2] - 2.0 * c_x) * inv_2f * q[0] + (b[1] + b[3] - 2.0 * c_y) * inv_2f * q[1] + q[2]
    )


def moved_boxes(tracks: Tracks, turned: FloatArray, t: float) -> FloatArray:
    """The tracks' ``turned`` boxes ``(T, 4)`` moved on to time ``t`` at their image velocities
    (pixels); tracks with a single update (no velocity yet) only turn."""
    vel = tracks.box_velocity_px_s.T
    vel = np.where(np.isnan(vel), 0.0, vel)
    return turned + vel * (t - tracks.last_time_s)[:, None]


def box_noise_sums(
    tracks: Tracks, miss: FloatArray, rows: IntArray, t: float, sigma_px: float
) -> tuple[float, int]:
    """Sum of squares and count of the misses of the constant-velocity box predictions
    (``miss`` = box − predicted box, pixels, of the tracks ``rows``) of tracks updated at an
    even pace: second differences of the box edges, variance 6σ² each; a miss beyond
    ``4·√6·sigma_px`` (an id switch, a jump) counts at that cap."""
    dt1 = t - tracks.last_time_s[rows]
    dt0 = tracks.last_time_s[rows] - tracks.previous_time_s[rows]
    even = (
        np.isfinite(dt0)
        & (np.abs(dt1 - dt0) <= 0.2 * dt0)
        & np.all(np.isfinite(tracks.box_velocity_px_s[:, rows]), axis=0)
    )
    if not np.any(even):
        return 0.0, 0
    d2 = miss[even]
    cap = 4.0 * math.sqrt(6.0) * sigma_px
    return float(np.sum(np.minimum(d2 * d2, cap * cap))), int(d2.size)
