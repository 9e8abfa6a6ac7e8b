"""The tracks of ``ours``: what each vehicle carries from frame to frame.

A track holds its distance filter, its road gradient's random walk, its last box and rotation
(for the association of the next frame), its heading belief, its learned size, its odd-object
evidence and its measurement-noise scale. A track not seen for ``max_age_s`` is dropped for
good, so a vehicle that is lost and later found again, or another vehicle that re-uses its id or
its place, starts from the prior: no state leaks between vehicles.

Every field of :class:`Tracks` has the track axis last (a number per track is ``(T,)``, a
vector per track ``(d, T)``), so that a frame gathers the columns of its continued tracks with
one index per field (:meth:`Tracks.take`) and the filter functions read contiguous rows. The
tracks are replaced only when the set of tracks changes (a track starts or is dropped): the
memory layout of their arrays is then the gather's or the concatenation's, which the last
digits of the records depend on (:func:`~slopedist.estimators.ours.association.turn_boxes`).
Distances in metres, angles in radians, image coordinates in pixels, times in seconds.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


@dataclass
class Tracks:
    """The live tracks, one column each (track axis last).

    Attributes:
        uid: ``(T,)`` unique id of the track within the sequence (never re-used).
        box_track_id: ``(T,)`` the boxes' track id it follows, or −1 for a track associated
            by IoU.
        filter_rows: ``(5, T)`` the distance filter's state rows: ℓ (log of the centre
            distance Z, m), r = Ż/Z (1/s), P_ℓℓ, P_ℓr, P_rr
            (:mod:`~slopedist.estimators.ours.filter`).
        gradient_mean_rad, gradient_var_rad2: ``(T,)`` the target gradient's random walk
            (before the prior).
        gradient_var_other_rad2: ``(T,)`` per-vehicle variance of its latest observation.
        box_velocity_px_s: ``(4, T)`` the box edges' image velocity with the camera's own
            rotation taken out (NaN until two updates).
        last_box_px: ``(4, T)`` the last box (left, top, right, bottom).
        last_time_s: ``(T,)`` time of the last update.
        previous_time_s: ``(T,)`` time of the update before it (NaN until two updates).
        R_world_cam: ``(3, 3, T)`` camera-to-world rotation at the last update (identity when
            unknown).
        n_updates: ``(T,)`` number of updates.
        size_rows: ``(2, T)`` the learned size: log of the track's dimensions over its class
            prior's, and that log's variance (NaN while it is the class prior's;
            :mod:`~slopedist.estimators.ours.size_learning`).
        odd_evidence: ``(T,)`` the evidence that the track's size is not its class's, nats
            (:mod:`~slopedist.estimators.ours.odd_objects`).
        noise_scale: ``(T,)`` the measurement-noise scale: the running mean of the distance
            filter's normalised innovation squared (1 for a new track).
        log_heading_belief: ``(K, T)`` log belief over the heading hypotheses.
    """

    uid: IntArray
    box_track_id: IntArray
    filter_rows: FloatArray
    gradient_mean_rad: FloatArray
    gradient_var_rad2: FloatArray
    gradient_var_other_rad2: FloatArray
    box_velocity_px_s: FloatArray
    last_box_px: FloatArray
    last_time_s: FloatArray
    previous_time_s: FloatArray
    R_world_cam: FloatArray
    n_updates: FloatArray
    size_rows: FloatArray
    odd_evidence: FloatArray
    noise_scale: FloatArray
    log_heading_belief: FloatArray

    @classmethod
    def empty(cls, n_headings: int) -> Tracks:
        """No track (``n_headings``: K, the heading hypotheses)."""
        return cls(
            uid=np.zeros(0, np.int64),
            box_track_id=np.zeros(0, np.int64),
            filter_rows=np.zeros((5, 0)),
            gradient_mean_rad=np.zeros(0),
            gradient_var_rad2=np.zeros(0),
            gradient_var_other_rad2=np.zeros(0),
            box_velocity_px_s=np.zeros((4, 0)),
            last_box_px=np.zeros((4, 0)),
            last_time_s=np.zeros(0),
            previous_time_s=np.zeros(0),
            R_world_cam=np.zeros((3, 3, 0)),
            n_updates=np.zeros(0),
            size_rows=np.zeros((2, 0)),
            odd_evidence=np.zeros(0),
            noise_scale=np.zeros(0),
            log_heading_belief=np.zeros((n_headings, 0)),
        )

    def __len__(self) -> int:
        return int(self.uid.shape[0])

    def take(self, index: NDArray[np.intp] | BoolArray) -> Tracks:
        """The tracks ``index`` (indices or a mask), a copy."""
        return Tracks(
            **{f.name: getattr(self, f.name)[..., index] for f in dataclasses.fields(self)}
        )

    def concat(self, other: Tracks) -> Tracks:
        """These tracks followed by ``other``'s."""
        return Tracks(
            **{
                f.name: np.concatenate([getattr(self, f.name), getattr(other, f.name)], axis=-1)
                for f in dataclasses.fields(self)
            }
        )

    def row_of_box_track_id(self) -> dict[int, int]:
        """Column of each box track id the tracks follow (ids are distinct among live tracks:
        :meth:`started` gives a second box with a continued id an id-less track)."""
        return {e: i for i, e in enumerate(self.box_track_id.tolist()) if e >= 0}

    def write_continued(self, update: TrackUpdate, continued: BoolArray) -> None:
        """Write the update of the boxes ``continued`` into the tracks they continue (in
        place)."""
        r = update.rows[continued]
        if not r.size:
            return
        boxes = update.boxes_px[continued].T
        t = update.time_s
        self.filter_rows[:, r] = update.filter_rows[:, continued]
        self.gradient_mean_rad[r] = update.gradient_mean_rad[continued]
        self.gradient_var_rad2[r] = update.gradient_var_rad2[continued]
        self.gradient_var_other_rad2[r] = update.gradient_var_other_rad2[continued]
        if update.turned_boxes_px is not None:
            elapsed = np.maximum(t - self.last_time_s[r], 1e-6)
            self.box_velocity_px_s[:, r] = (boxes - update.turned_boxes_px[r].T) / elapsed
        self.previous_time_s[r] = self.last_time_s[r]
        self.last_time_s[r] = t
        self.last_box_px[:, r] = boxes
        self.R_world_cam[:, :, r] = update.R_world_cam[:, :, None]
        self.n_updates[r] += 1.0
        if update.log_heading_belief is not None:
            self.log_heading_belief[:, r] = update.log_heading_belief[continued].T
        if update.size_rows is not None:
            self.size_rows[:, r] = update.size_rows[:, continued]
        if update.odd_evidence is not None:
            self.odd_evidence[r] = update.odd_evidence[continued]
        if update.noise_scale is not None:
            self.noise_scale[r] = update.noise_scale[continued]

    def with_started(
        self, update: TrackUpdate, new: BoolArray, uid: IntArray, prior_log_belief: FloatArray
    ) -> Tracks:
        """These tracks and new ones for the boxes ``new`` (uids ``uid``), after their first
        update.

        A new track that carries a box track id replaces any live track with that id (its
        vehicle failed the distance gate); a second box with an id already continued in this
        frame gets an id-less track. Tracks whose heading belief is not kept start with
        ``prior_log_belief`` ``(K,)``; a new track's size is its class prior's (unless the
        update learns it), its odd-object evidence 0 and its noise scale 1.
        """
        box_track_id = update.track_ids[new].copy()
        taken = set(self.box_track_id[update.rows[~new]].tolist())  # ids continued now
        seen: set[int] = set()
        for i, e in enumerate(box_track_id.tolist()):
            if e >= 0 and (e in taken or e in seen):
                box_track_id[i] = -1
            seen.add(e)
        k = uid.shape[0]
        belief = update.log_heading_belief
        size = np.array([[0.0], [np.nan]]).repeat(k, axis=1)
        started = Tracks(
            uid=uid,
            box_track_id=box_track_id,
            filter_rows=update.filter_rows[:, new],
            gradient_mean_rad=update.gradient_mean_rad[new],
            gradient_var_rad2=update.gradient_var_rad2[new],
            gradient_var_other_rad2=update.gradient_var_other_rad2[new],
            box_velocity_px_s=np.full((4, k), np.nan),
            last_box_px=update.boxes_px[new].T.copy(),
            last_time_s=np.full(k, update.time_s),
            previous_time_s=np.full(k, np.nan),
            R_world_cam=np.repeat(update.R_world_cam[:, :, None], k, axis=2),
            n_updates=np.ones(k),
            size_rows=size if update.size_rows is None else update.size_rows[:, new],
            odd_evidence=np.zeros(k),
            noise_scale=np.ones(k),
            log_heading_belief=(
                np.repeat(prior_log_belief[:, None], k, axis=1) if belief is None else belief[new].T
            ),
        )
        tracks = self
        claimed = box_track_id[box_track_id >= 0]
        if claimed.size and len(tracks):
            replaced = np.isin(tracks.box_track_id, claimed)
            if replaced.any():
                tracks = tracks.take(~replaced)
        return tracks.concat(started)


class TrackUpdate(NamedTuple):
    """What a frame writes into the tracks, one column per box of the frame.

    Attributes:
        rows: ``(n,)`` the track column each box continues, −1 where it starts a track.
        track_ids: ``(n,)`` the boxes' track ids (−1: none).
        filter_rows: ``(5, n)`` the distance filter's rows (:attr:`Tracks.filter_rows`).
        log_heading_belief: ``(n, K)`` the heading belief, or None when it is not kept (tracks
            then carry the prior).
        gradient_mean_rad, gradient_var_rad2: ``(n,)`` the target gradient's random walk.
        gradient_var_other_rad2: ``(n,)`` per-vehicle variance of the latest observation.
        boxes_px: ``(n, 4)`` this frame's boxes.
        time_s: the frame's time.
        R_world_cam: ``(3, 3)`` camera-to-world rotation (identity when unknown).
        turned_boxes_px: ``(T, 4)`` the tracks' last boxes turned with the camera, or None when
            the box motion is not kept (only id-less tracks and the box-noise estimate use it).
        size_rows: ``(2, n)`` the learned size (:attr:`Tracks.size_rows`), or None when it is
            not learned (tracks keep the class prior).
        odd_evidence: ``(n,)`` the odd-object evidence, or None when this frame has none
            (tracks keep theirs; a new track starts from 0).
        noise_scale: ``(n,)`` the measurement-noise scale, or None when it is not estimated
            (tracks keep theirs; a new track starts from 1).
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
