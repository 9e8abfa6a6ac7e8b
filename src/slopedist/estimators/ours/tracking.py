"""Track bookkeeping of ``ours``: which box of this frame continues which vehicle.

Boxes that carry a track id (``>= 0``) continue the track with that id; boxes without one are
matched to the id-less tracks by 2D IoU (greedy, best pair first). A track not seen for
``max_age_s`` is dropped for good, so a vehicle that is lost and later found again, or another
vehicle that re-uses its id or its place, starts from the prior: no state leaks between
vehicles. The filter state itself lives here as arrays (one row per track) so the estimator can
update all tracks of a frame at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slopedist.io.detections.boxes import iou_matrix, overlapping_pairs, pair_iou

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


# Rows of TrackArrays.state (one float column per track; a frame gathers the columns of its
# tracks with one indexing operation, and each field is then a contiguous row).
ROW_L, ROW_RATE = 0, 1
"""Distance filter state: log distance ℓ (Z in m) and relative rate Ż/Z (1/s)."""
ROW_P00, ROW_P01, ROW_P11 = 2, 3, 4
"""Its covariance (symmetric 2×2: ℓℓ, ℓr, rr)."""
ROW_FILTER = slice(0, 5)
"""The five rows of the distance filter (as :mod:`~slopedist.estimators.ours.filter` takes)."""
ROW_GRAD_MEAN, ROW_GRAD_VAR, ROW_GRAD_OTHER = 5, 6, 7
"""Target gradient estimate (rad), its variance and the per-vehicle variance of the latest
observation (rad²)."""
ROW_BOX_VEL = slice(8, 12)
"""Box edges' image velocity (px/s) with the camera's own rotation taken out; NaN until the
track has two updates."""
ROW_LAST_BOX = slice(12, 16)
"""The last box (l, t, r, b), pixels."""
ROW_LAST_T, ROW_PREV_T = 16, 17
"""Time of the last update and of the one before it (NaN until two updates), seconds."""
ROW_ROT = slice(18, 27)
"""Camera-to-world rotation at the last update, row-major (identity if unknown)."""
ROW_N_OBS = 27
"""Number of updates."""
ROW_SIZE = slice(28, 30)
"""The track's learned size: log of its dimensions over its class prior's (isotropic scale
b, dimensionless) and that log's variance, NaN while it is the class prior's
(:mod:`~slopedist.estimators.ours.size_learning`)."""
ROW_ODD = 30
"""The track's evidence that its size is not its class's: the odd-object mode's log-likelihood
ratio summed over its frames, each weighed by ``min(1, dt/τ)``, 0 for a new track
(:mod:`~slopedist.estimators.ours.odd_objects`)."""
ROW_NOISE = 31
"""The track's measurement-noise scale: a running mean of its distance filter's normalised
innovation squared against the nominal frame-to-frame noise, 1 for a new track
(:func:`~slopedist.estimators.ours.frame_cues.filter_distance`)."""
ROW_LOG_W = 32
"""First row of the log belief over the heading hypotheses (K rows)."""


@dataclass
class TrackArrays:
    """State of the live tracks, one column each.

    Attributes:
        uid: ``(T,)`` unique id of the track within the sequence (never re-used).
        ext_id: ``(T,)`` the boxes' track id it follows, or −1 for IoU-associated tracks.
        state: ``(ROW_LOG_W + K, T)`` float state, rows as the ``ROW_*`` constants; read it
            through the properties.
    """

    uid: IntArray
    ext_id: IntArray
    state: FloatArray
    _by_ext: dict[int, int] | None = field(default=None, init=False, repr=False, compare=False)

    @classmethod
    def empty(cls, n_hypotheses: int) -> TrackArrays:
        z = np.zeros(0, np.int64)
        return cls(z, z.copy(), np.zeros((ROW_LOG_W + n_hypotheses, 0)))

    @classmethod
    def start(
        cls,
        uid: IntArray,
        ext_id: IntArray,
        filter_rows: FloatArray,
        log_w: FloatArray,
        grad_mean: FloatArray,
        grad_var: FloatArray,
        grad_var_other: FloatArray,
        t: float,
        boxes: FloatArray,
        R_world_cam: FloatArray,
    ) -> TrackArrays:
        """New tracks after their first update at time ``t``: ``filter_rows`` ``(5, k)`` (the
        :data:`ROW_FILTER` rows), ``log_w`` ``(k, K)``, ``boxes`` ``(k, 4)``, the others
        ``(k,)``; their size (:data:`ROW_SIZE`) the class prior's."""
        k = uid.shape[0]
        st = np.empty((ROW_LOG_W + log_w.shape[1], k))
        st[ROW_FILTER] = filter_rows
        st[ROW_GRAD_MEAN] = grad_mean
        st[ROW_GRAD_VAR] = grad_var
        st[ROW_GRAD_OTHER] = grad_var_other
        st[ROW_BOX_VEL] = np.nan
        st[ROW_LAST_BOX] = boxes.T
        st[ROW_LAST_T] = t
        st[ROW_PREV_T] = np.nan
        st[ROW_ROT] = np.asarray(R_world_cam, dtype=float).reshape(9, 1)
        st[ROW_N_OBS] = 1.0
        st[ROW_SIZE.start] = 0.0
        st[ROW_SIZE.start + 1] = np.nan
        st[ROW_ODD] = 0.0
        st[ROW_NOISE] = 1.0
        st[ROW_LOG_W:] = log_w.T
        return cls(uid, ext_id, st)

    def __len__(self) -> int:
        return int(self.uid.shape[0])

    def row_of_id(self) -> dict[int, int]:
        """Column of each box track id the tracks follow (ids are distinct among live tracks:
        see :meth:`OursEstimator._store`); built once per set of tracks."""
        if self._by_ext is None:
            self._by_ext = {e: i for i, e in enumerate(self.ext_id.tolist()) if e >= 0}
        return self._by_ext

    @property
    def x(self) -> FloatArray:
        """``(T, 2)`` distance filter states (ℓ, r)."""
        return self.state[ROW_L : ROW_RATE + 1].T

    @property
    def P(self) -> FloatArray:
        """``(T, 2, 2)`` their covariances."""
        p00, p01, p11 = self.state[ROW_P00], self.state[ROW_P01], self.state[ROW_P11]
        return np.stack([np.stack([p00, p01], -1), np.stack([p01, p11], -1)], -2)

    @property
    def log_w(self) -> FloatArray:
        """``(T, K)`` log belief over the heading hypotheses."""
        return self.state[ROW_LOG_W:].T

    @property
    def grad_mean(self) -> FloatArray:
        """``(T,)`` target gradient estimates (rad, before the prior is applied)."""
        return self.state[ROW_GRAD_MEAN]

    @property
    def grad_var(self) -> FloatArray:
        """``(T,)`` their variances (rad²)."""
        return self.state[ROW_GRAD_VAR]

    @property
    def grad_var_other(self) -> FloatArray:
        """``(T,)`` per-vehicle variance of the latest gradient observation (rad²)."""
        return self.state[ROW_GRAD_OTHER]

    @property
    def last_t(self) -> FloatArray:
        """``(T,)`` time of the last update, seconds."""
        return self.state[ROW_LAST_T]

    @property
    def prev_t(self) -> FloatArray:
        """``(T,)`` time of the update before the last (NaN until two updates)."""
        return self.state[ROW_PREV_T]

    @property
    def last_box(self) -> FloatArray:
        """``(T, 4)`` the last boxes, pixels."""
        return self.state[ROW_LAST_BOX].T

    @property
    def box_vel(self) -> FloatArray:
        """``(T, 4)`` box edge velocities, px/s (NaN until two updates)."""
        return self.state[ROW_BOX_VEL].T

    @property
    def n_obs(self) -> FloatArray:
        """``(T,)`` number of updates."""
        return self.state[ROW_N_OBS]

    @property
    def R_last(self) -> FloatArray:
        """``(T, 3, 3)`` camera-to-world rotations at the last update."""
        return self.state[ROW_ROT].T.reshape(-1, 3, 3)

    def keep(self, mask: NDArray[np.bool_]) -> TrackArrays:
        """The tracks where ``mask`` is true."""
        return TrackArrays(self.uid[mask], self.ext_id[mask], self.state[:, mask])

    def concat(self, other: TrackArrays) -> TrackArrays:
        """These tracks followed by ``other``'s."""
        return TrackArrays(
            np.concatenate([self.uid, other.uid]),
            np.concatenate([self.ext_id, other.ext_id]),
            np.concatenate([self.state, other.state], axis=1),
        )


class TrackUpdate(NamedTuple):
    """What a frame writes into the tracks, one column per box of the frame.

    Attributes:
        rows: ``(n,)`` the track column each box continues, −1 where it starts a track.
        track_ids: ``(n,)`` the boxes' track ids (−1: none).
        filter_rows: ``(5, n)`` the distance filter's rows (:data:`ROW_FILTER`).
        log_heading_belief: ``(n, K)`` the heading belief, or None when it is not kept (tracks
            then carry the prior).
        gradient_mean_rad, gradient_var_rad2: ``(n,)`` the target gradient's random walk.
        gradient_var_other_rad2: ``(n,)`` per-vehicle variance of the latest observation.
        boxes_px: ``(n, 4)`` this frame's boxes.
        time_s: the frame's time.
        R_world_cam: ``(3, 3)`` camera-to-world rotation (identity when unknown).
        turned_boxes_px: ``(T, 4)`` the tracks' last boxes turned with the camera, or None when
            the box motion is not kept (only id-less tracks and the box-noise estimate use it).
        size_rows: ``(2, n)`` the learned size (:data:`ROW_SIZE`), or None when it is not
            learned (tracks keep the class prior).
        odd_evidence: ``(n,)`` the odd-object evidence (:data:`ROW_ODD`), or None when this
            frame has none (tracks keep theirs; a new track starts from 0).
        noise_scale: ``(n,)`` the measurement-noise scale (:data:`ROW_NOISE`), or None when it
            is not estimated (tracks keep theirs; a new track starts from 1).
    """

    rows: IntArray
    track_ids: IntArray
    filter_rows: FloatArray
    log_heading_belief: FloatArray | None
    gradient_mean_rad: FloatArray
    gradient_var_rad2: FloatArray
    gradient_var_other_rad2: FloatArray
    boxes_px: FloatArray
    time_s: float
    R_world_cam: FloatArray
    turned_boxes_px: FloatArray | None
    size_rows: FloatArray | None = None
    odd_evidence: FloatArray | None = None
    noise_scale: FloatArray | None = None


def write_continued(
    tracks: TrackArrays, update: TrackUpdate, continued: NDArray[np.bool_] | None
) -> None:
    """Write the update of the boxes that continue a track into ``tracks`` (in place);
    ``continued`` is None when every box does."""
    r = update.rows if continued is None else update.rows[continued]
    if not r.size:
        return
    b, filt = update.boxes_px.T, update.filter_rows
    g_mean, g_var = update.gradient_mean_rad, update.gradient_var_rad2
    g_other = update.gradient_var_other_rad2
    belief = update.log_heading_belief
    log_w = None if belief is None else belief.T
    if continued is not None:
        b, filt, g_mean, g_var, g_other = (
            a[..., continued] for a in (b, filt, g_mean, g_var, g_other)
        )
        log_w = None if log_w is None else log_w[..., continued]
    S = tracks.state[:, r]
    t = update.time_s
    S[ROW_FILTER] = filt
    S[ROW_GRAD_MEAN] = g_mean
    S[ROW_GRAD_VAR] = g_var
    S[ROW_GRAD_OTHER] = g_other
    if update.turned_boxes_px is not None:
        S[ROW_BOX_VEL] = (b - update.turned_boxes_px[r].T) / np.maximum(t - S[ROW_LAST_T], 1e-6)
    S[ROW_PREV_T] = S[ROW_LAST_T]
    S[ROW_LAST_T] = t
    S[ROW_LAST_BOX] = b
    S[ROW_ROT] = update.R_world_cam.reshape(9, 1)
    S[ROW_N_OBS] += 1.0
    if log_w is not None:
        S[ROW_LOG_W:] = log_w
    if update.size_rows is not None:
        S[ROW_SIZE] = update.size_rows if continued is None else update.size_rows[:, continued]
    if update.odd_evidence is not None:
        odd = update.odd_evidence
        S[ROW_ODD] = odd if continued is None else odd[continued]
    if update.noise_scale is not None:
        scale = update.noise_scale
        S[ROW_NOISE] = scale if continued is None else scale[continued]
    tracks.state[:, r] = S


def start_tracks(
    tracks: TrackArrays,
    update: TrackUpdate,
    new: NDArray[np.bool_],
    new_uid: IntArray,
    prior_log_w: FloatArray,
) -> TrackArrays:
    """``tracks`` with new tracks for the boxes ``new`` (uids ``new_uid``) appended.

    A new track that carries a box track id replaces any live track with that id (its vehicle
    failed the gate); a second box with an id already continued in this frame gets an id-less
    track. Tracks whose belief is not kept start with ``prior_log_w`` ``(K,)``.
    """
    ext = update.track_ids[new].copy()
    taken = set(tracks.ext_id[update.rows[~new]].tolist())  # ids continued in this frame
    seen: set[int] = set()
    for i, e in enumerate(ext.tolist()):
        if e >= 0 and (e in taken or e in seen):
            ext[i] = -1
        seen.add(e)
    belief = update.log_heading_belief
    k = new_uid.shape[0]
    add = TrackArrays.start(
        new_uid,
        ext,
        update.filter_rows[:, new],
        np.broadcast_to(prior_log_w, (k, prior_log_w.size)) if belief is None else belief[new],
        update.gradient_mean_rad[new],
        update.gradient_var_rad2[new],
        update.gradient_var_other_rad2[new],
        update.time_s,
        update.boxes_px[new],
        update.R_world_cam,
    )
    if update.size_rows is not None:
        add.state[ROW_SIZE] = update.size_rows[:, new]
    claimed = ext[ext >= 0]
    if claimed.size and len(tracks):
        replaced = np.isin(tracks.ext_id, claimed)
        if replaced.any():
            tracks = tracks.keep(~replaced)
    return tracks.concat(add)


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
    """
    b = np.asarray(boxes, dtype=float)
    if b.shape[0] == 0 or R_now is None:
        return b.copy(), np.ones(b.shape[0])
    c = np.array([c_x, c_y])
    mid = 0.5 * (b[:, :2] + b[:, 2:])  # box centres (u, v)
    ray = np.ones((b.shape[0], 3))
    ray[:, :2] = (mid - c) * (1.0 / f)
    R_now = np.asarray(R_now, dtype=float)
    if (R_last == R_last[0]).all():  # all seen at one rotation
        out = ray @ (R_last[0].T @ R_now)  # rows: (R_nowᵀ·R_last·ray)ᵀ
    else:
        out = (R_last @ ray[:, :, None])[..., 0] @ R_now
    z = out[:, 2]
    shift = c + out[:, :2] * (f / np.maximum(z, 1e-6))[:, None] - mid
    return b + np.concatenate([shift, shift], axis=1), z


def depth_ratios(
    box_rows: FloatArray,
    f: float,
    c_x: float,
    c_y: float,
    rot_rows: FloatArray,
    R_now: FloatArray | None,
) -> FloatArray:
    """The second output of :func:`turn_boxes` alone: ``Z_new/Z_old`` ``(T,)`` of the points
    seen at the centres of the boxes ``box_rows`` ``(4, T)`` (l, t, r, b rows) when the camera
    turns from the camera-to-world rotations ``rot_rows`` ``(9, T)`` (row-major entries) to
    ``R_now`` (ones when it is None)."""
    b = np.asarray(box_rows, dtype=float)
    if b.shape[1] == 0 or R_now is None:
        return np.ones(b.shape[1])
    # the new depth of the old ray ((u − c_x)/f, (v − c_y)/f, 1) is R_now's z axis (in the
    # world) · R_last·ray, i.e. ray · (R_lastᵀ·R_now[:, 2])
    m = b.shape[1]
    q = (np.asarray(R_now, dtype=float)[:, 2] @ np.asarray(rot_rows).reshape(3, 3 * m)).reshape(
        3, m
    )
    inv_2f = 0.5 / f
    return (
        (b[0] + b[2] - 2.0 * c_x) * inv_2f * q[0] + (b[1] + b[3] - 2.0 * c_y) * inv_2f * q[1] + q[2]
    )


def box_noise_sums(
    tracks: TrackArrays, miss: FloatArray, rows: IntArray, t: float, sigma_px: float
) -> tuple[float, int]:
    """Sum of squares and count of the misses of the constant-velocity box predictions
    (``miss`` = box − predicted box, pixels, of the tracks ``rows``) of tracks updated at an
    even pace: second differences of the box edges, variance 6σ² each; a miss beyond
    ``4·√6·sigma_px`` (an id switch, a jump) counts at that cap."""
    dt1 = t - tracks.last_t[rows]
    dt0 = tracks.last_t[rows] - tracks.prev_t[rows]
    even = (
        np.isfinite(dt0)
        & (np.abs(dt1 - dt0) <= 0.2 * dt0)
        & np.all(np.isfinite(tracks.box_vel[rows]), axis=1)
    )
    if not np.any(even):
        return 0.0, 0
    d2 = miss[even]
    cap = 4.0 * math.sqrt(6.0) * sigma_px
    return float(np.sum(np.minimum(d2 * d2, cap * cap))), int(d2.size)


def moved_boxes(tracks: TrackArrays, turned: FloatArray, t: float) -> FloatArray:
    """The tracks' ``turned`` boxes moved on to time ``t`` at their image velocities (pixels);
    tracks with a single update (no velocity yet) only turn."""
    vel = np.where(np.isnan(tracks.box_vel), 0.0, tracks.box_vel)
    return turned + vel * (t - tracks.last_t)[:, None]


def associate(
    tracks: TrackArrays,
    boxes: FloatArray,
    track_ids: IntArray,
    min_iou: float = 0.3,
    predicted: FloatArray | None = None,
) -> IntArray:
    """Row of ``tracks`` each box continues, or −1 for a new track.

    Boxes with an id ``>= 0`` follow the live track with that id (a second box with the same id
    in one frame starts a new track); the others are matched by IoU to the live id-less tracks'
    ``predicted`` boxes (default: their last boxes), greedily, best pair first.
    """
    n = boxes.shape[0]
    if len(tracks) == 0 or n == 0:
        return np.full(n, -1, np.int64)
    ids = track_ids.tolist()
    by_id = tracks.row_of_id()
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
    free_tracks = np.flatnonzero(tracks.ext_id < 0)
    if free_boxes.size and free_tracks.size:
        ref = tracks.last_box if predicted is None else predicted
        bi, ti, iou = _iou_candidates(boxes[free_boxes], ref[free_tracks], min_iou)
        order = np.argsort(-iou, kind="stable")
        taken_b: set[int] = set()
        used: set[int] = set()  # id-less tracks are never taken by an id
        for o in order.tolist():
            b, t = int(bi[o]), int(free_tracks[ti[o]])
            if b in taken_b or t in used:
                continue
            rows[free_boxes[b]] = t
            taken_b.add(b)
            used.add(t)
    return rows


_DENSE_MAX_PAIRS = 2048
"""Up to this many (box, track) pairs every IoU is computed at once (cheaper than sorting)."""


def _iou_candidates(
    boxes: FloatArray, tracks: FloatArray, min_iou: float
) -> tuple[NDArray[np.intp], NDArray[np.intp], FloatArray]:
    """The (box, track) pairs with IoU ≥ ``min_iou``, row-major, and their IoU.

    With ``min_iou > 0`` only overlapping boxes can qualify, so for many boxes the IoU is
    computed for the overlapping pairs only (:func:`overlapping_pairs`: near linear in the
    number of boxes); the pairs and values are the same as from the full matrix.
    """
    if boxes.shape[0] * tracks.shape[0] <= _DENSE_MAX_PAIRS or not min_iou > 0:
        iou = iou_matrix(boxes, tracks)
        bi, ti = np.nonzero(iou >= min_iou)
        return bi, ti, iou[bi, ti]
    bi, ti = overlapping_pairs(boxes, tracks)
    iou = pair_iou(boxes, tracks, bi, ti)
    keep = np.flatnonzero(iou >= min_iou)
    keep = keep[np.lexsort((ti[keep], bi[keep]))]  # row-major, as np.nonzero gives them
    return bi[keep], ti[keep], iou[keep]
