"""Track bookkeeping of ``ours``: which box of this frame continues which vehicle.

Boxes that carry a track id (``>= 0``) continue the track with that id; boxes without one are
matched to the id-less tracks by 2D IoU (greedy, best pair first). A track not seen for
``max_age_s`` is dropped for good, so a vehicle that is lost and later found again, or another
vehicle that re-uses its id or its place, starts from the prior: no state leaks between
vehicles. The filter state itself lives here as arrays (one row per track) so the estimator can
update all tracks of a frame at once.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from slopedist.detections.boxes import iou_matrix

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass
class TrackArrays:
    """State of the live tracks, one row each.

    Attributes:
        uid: unique id of the track within the sequence (never re-used).
        ext_id: the boxes' track id it follows, or −1 for IoU-associated tracks.
        x, P: distance filter state ``(T, 2)`` (log distance, relative rate) and covariance
            ``(T, 2, 2)``.
        log_w: ``(T, K)`` log belief over the heading hypotheses.
        grad_mean, grad_var: the running estimate of the target gradient from its observations
            (radians, rad²; before the prior is applied).
        grad_var_other: per-vehicle variance of the latest gradient observation (rad²).
        last_t: time of the last update, seconds.
        last_box: ``(T, 4)`` the last box (IoU association).
        prev_t: time of the update before the last.
        box_vel: ``(T, 4)`` the box edges' image velocity (px/s) with the camera's own rotation
            taken out; NaN until a track has two updates.
        R_last: ``(T, 3, 3)`` camera-to-world rotation at the last update (identity if unknown).
        n_obs: number of updates.
    """

    uid: IntArray
    ext_id: IntArray
    x: FloatArray
    P: FloatArray
    log_w: FloatArray
    grad_mean: FloatArray
    grad_var: FloatArray
    grad_var_other: FloatArray
    last_t: FloatArray
    last_box: FloatArray
    prev_t: FloatArray
    box_vel: FloatArray
    R_last: FloatArray
    n_obs: IntArray

    @classmethod
    def empty(cls, n_hypotheses: int) -> TrackArrays:
        z = np.zeros(0)
        return cls(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2)),
                   np.zeros((0, 2, 2)), np.zeros((0, n_hypotheses)), z, z, z, z,
                   np.zeros((0, 4)), z, np.zeros((0, 4)), np.zeros((0, 3, 3)),
                   np.zeros(0, np.int64))

    def __len__(self) -> int:
        return int(self.uid.shape[0])

    def keep(self, mask: NDArray[np.bool_]) -> TrackArrays:
        """The tracks where ``mask`` is true."""
        return TrackArrays(*(getattr(self, f.name)[mask] for f in fields(TrackArrays)))

    def concat(self, other: TrackArrays) -> TrackArrays:
        """These tracks followed by ``other``'s."""
        return TrackArrays(*(np.concatenate([getattr(self, f.name), getattr(other, f.name)])
                             for f in fields(TrackArrays)))


def rotate_boxes(boxes: FloatArray, f: float, c_x: float, c_y: float,
                 R_rel: FloatArray) -> FloatArray:
    """Where boxes ``(T, 4)`` go when the camera turns by ``R_rel`` ``(T, 3, 3)`` (pixels).

    ``R_rel`` maps directions of the old camera frame into the new one (``R_newᵀ·R_old`` for
    camera-to-world rotations). A pure rotation moves every pixel whatever its depth; between
    two frames it is small, so each box is shifted by the motion of its centre (its size
    changes by a second-order amount).
    """
    b = np.asarray(boxes, dtype=float)
    if b.shape[0] == 0:
        return b.copy()
    ray = np.empty((b.shape[0], 3))
    ray[:, 0] = (0.5 * (b[:, 0] + b[:, 2]) - c_x) / f
    ray[:, 1] = (0.5 * (b[:, 1] + b[:, 3]) - c_y) / f
    ray[:, 2] = 1.0
    out = np.einsum("tij,tj->ti", R_rel, ray)
    z = np.maximum(out[:, 2], 1e-6)
    du = c_x + f * out[:, 0] / z - 0.5 * (b[:, 0] + b[:, 2])
    dv = c_y + f * out[:, 1] / z - 0.5 * (b[:, 1] + b[:, 3])
    return b + np.stack([du, dv, du, dv], axis=1)


def relative_rotations(R_last: FloatArray, R_now: FloatArray | None) -> FloatArray:
    """``R_nowᵀ·R_last`` per track ``(T, 3, 3)``; identity when the current rotation is unknown."""
    if R_now is None:
        return np.broadcast_to(np.eye(3), R_last.shape).copy()
    return np.einsum("ji,tjk->tik", np.asarray(R_now, dtype=float), R_last)


def predicted_boxes(tracks: TrackArrays, t: float, R_rel: FloatArray, f: float, c_x: float,
                    c_y: float) -> tuple[FloatArray, FloatArray]:
    """Each track's box at time ``t``: turned with the camera, then moved at its own image
    velocity (pixels); tracks with a single update only turn. Returns (predicted, turned)."""
    turned = rotate_boxes(tracks.last_box, f, c_x, c_y, R_rel)
    vel = np.nan_to_num(tracks.box_vel, nan=0.0)
    return turned + vel * (t - tracks.last_t)[:, None], turned


def associate(
    tracks: TrackArrays, boxes: FloatArray, track_ids: IntArray, min_iou: float = 0.3,
    predicted: FloatArray | None = None,
) -> IntArray:
    """Row of ``tracks`` each box continues, or −1 for a new track.

    Boxes with an id ``>= 0`` follow the live track with that id (a second box with the same id
    in one frame starts a new track); the others are matched by IoU to the live id-less tracks'
    ``predicted`` boxes (default: their last boxes), greedily, best pair first.
    """
    n = boxes.shape[0]
    rows = np.full(n, -1, np.int64)
    if len(tracks) == 0 or n == 0:
        return rows
    by_ext = {int(e): i for i, e in enumerate(tracks.ext_id) if e >= 0}
    used: set[int] = set()
    for k in np.flatnonzero(track_ids >= 0):
        r = by_ext.get(int(track_ids[k]))
        if r is not None and r not in used:
            rows[k] = r
            used.add(r)
    free_boxes = np.flatnonzero(track_ids < 0)
    free_tracks = np.flatnonzero(tracks.ext_id < 0)
    if free_boxes.size and free_tracks.size:
        ref = tracks.last_box if predicted is None else predicted
        iou = iou_matrix(boxes[free_boxes], ref[free_tracks])
        bi, ti = np.nonzero(iou >= min_iou)
        order = np.argsort(-iou[bi, ti], kind="stable")
        taken_b: set[int] = set()
        for o in order:
            b, t = int(bi[o]), int(free_tracks[ti[o]])
            if b in taken_b or t in used:
                continue
            rows[free_boxes[b]] = t
            taken_b.add(b)
            used.add(t)
    return rows
