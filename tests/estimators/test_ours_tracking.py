"""Association of ``ours``: id-less boxes matched to tracks by IoU (greedy, best pair first)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist.estimators.ours import association
from slopedist.estimators.ours.association import associate
from slopedist.estimators.ours.tracks import Tracks, TrackUpdate
from slopedist.io.detections.boxes import iou_matrix


def id_less_tracks(boxes: np.ndarray) -> Tracks:
    k = boxes.shape[0]
    zeros = np.zeros(k)
    first = TrackUpdate(
        np.full(k, -1),
        np.full(k, -1),
        np.zeros((5, k)),
        None,
        zeros,
        zeros,
        zeros,
        boxes,
        0.0,
        np.eye(3),
        None,
    )
    return Tracks.empty(1).with_started(first, np.ones(k, bool), np.arange(k), np.zeros(1))


def test_greedy_iou_association_by_hand() -> None:
    tracks = id_less_tracks(np.array([[0.0, 0, 10, 10], [8.0, 0, 18, 10], [50.0, 0, 60, 10]]))
    boxes = np.array([[1.0, 0, 11, 10], [9.0, 0, 19, 10], [30.0, 0, 40, 10], [7.0, 0, 17, 10]])
    rows = associate(tracks, boxes, np.full(4, -1), min_iou=0.3)
    # box 0 ↔ track 0 and box 1 ↔ track 1 (IoU 9/11 each); box 3 ties with box 1 for track 1
    # (9/11) and loses on row order; box 2 overlaps nothing
    assert rows.tolist() == [0, 1, -1, -1]


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**31), st.sampled_from([0.1, 0.3, 0.6]))
def test_association_of_many_boxes_equals_the_full_iou_matrix(seed: int, min_iou: float) -> None:
    """Above a few thousand pairs each box is compared with its nearest tracks only: the same
    assignment."""
    rng = np.random.default_rng(seed)
    n = 200
    x, y = rng.uniform(0, 1200, n).round(0), rng.uniform(100, 250, n).round(0)
    w, h = rng.uniform(5, 120, n).round(0), rng.uniform(5, 80, n).round(0)
    last = np.stack([x, y, x + w, y + h], axis=1)
    tracks = id_less_tracks(last)
    boxes = last + rng.normal(0, 4, last.shape).round(0)
    boxes[:, 2:] = np.maximum(boxes[:, 2:], boxes[:, :2] + 1)
    boxes = boxes[rng.permutation(n)][: n - 20]
    ids = np.full(boxes.shape[0], -1)
    sparse = associate(tracks, boxes, ids, min_iou)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(association, "_DENSE_MAX_PAIRS", 10**9)
        dense = associate(tracks, boxes, ids, min_iou)
    assert sparse.tolist() == dense.tolist()
    assert np.count_nonzero(sparse >= 0) > n // 2


def _greedy_by_hand(boxes: np.ndarray, tracks: np.ndarray, min_iou: float) -> dict[int, int]:
    """Greedy matching over the full IoU matrix, best pair first, ties row-major."""
    iou = iou_matrix(boxes, tracks)
    pairs = sorted(
        (-iou[b, t], b, t)
        for b in range(len(boxes))
        for t in range(len(tracks))
        if iou[b, t] >= min_iou
    )
    matched: dict[int, int] = {}
    for _, b, t in pairs:
        if b not in matched and t not in matched.values():
            matched[b] = t
    return matched


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**31), st.sampled_from([0.1, 0.3, 0.5, 0.75]))
def test_matching_crowded_boxes_in_stages_of_iou_equals_one_greedy_pass(
    seed: int, min_iou: float
) -> None:
    """Hundreds of boxes on top of each other, matched in stages of falling IoU with every
    track a candidate (the gate open): the matches of one greedy pass over the full matrix,
    equal IoUs included."""
    rng = np.random.default_rng(seed)
    m = 300
    x, y = rng.integers(0, 300, m) * 1.0, rng.integers(0, 60, m) * 1.0
    w, h = rng.integers(10, 80, m) * 1.0, rng.integers(8, 40, m) * 1.0
    tracks = np.stack([x, y, x + w, y + h], axis=1)
    boxes = tracks[rng.integers(0, m, 280)] + rng.integers(-3, 4, (280, 4))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(association, "GATE_TRACKS", m)
        b, t = association.greedy_iou_matches(boxes, tracks, min_iou)
    assert dict(zip(b.tolist(), t.tolist(), strict=True)) == _greedy_by_hand(boxes, tracks, min_iou)


def _edge_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The largest difference of the edges of every pair of boxes ``(N, 4)``, ``(T, 4)``."""
    return np.abs(a[:, None, :] - b[None, :, :]).max(axis=2)


def _reach(boxes: np.ndarray, min_iou: float) -> np.ndarray:
    """How far a box's edges may lie from those of a box with an IoU of ``min_iou``, with
    the gate's margin for rounding (``1e-9`` relative: (1 − 0.9)/0.9 · 9 px rounds below 1)."""
    size = np.maximum(boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1])
    return (1.0 - min_iou) / min_iou * size * (1.0 + 1e-9)


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**31), st.sampled_from([0.3, 0.5, 0.7]))
def test_gated_matching_equals_the_full_greedy_matching_within_the_gate(
    seed: int, min_iou: float
) -> None:
    """Clusters of up to GATE_TRACKS tracks on top of each other, far apart: every box has at
    most that many tracks within its reach, and the gated stages give the matches of one
    greedy pass over the full matrix."""
    rng = np.random.default_rng(seed)
    k = association.GATE_TRACKS
    centres = np.stack(
        [rng.permutation(40)[:24] * 400.0, rng.integers(0, 2, 24) * 400.0 + 100.0], axis=1
    )
    per = rng.integers(1, k + 1, len(centres))
    mid = np.repeat(centres, per, axis=0) + rng.integers(-6, 7, (per.sum(), 2))
    half = np.repeat(rng.integers(10, 30, (len(centres), 2)), per, axis=0) * 1.0
    half = half + rng.integers(-3, 4, half.shape)
    tracks = np.concatenate([mid - half, mid + half], axis=1)
    boxes = tracks[rng.permutation(len(tracks))] + rng.integers(-3, 4, tracks.shape)
    boxes = boxes[: len(boxes) - 5]
    assert len(boxes) * len(tracks) > association._DENSE_MAX_PAIRS  # the gated path
    within = _edge_distance(boxes, tracks) <= _reach(boxes, min_iou)[:, None]
    assert within.sum(axis=1).max() <= k  # the premise: no box has more tracks within reach
    b, t = association.greedy_iou_matches(boxes, tracks, min_iou)
    assert dict(zip(b.tolist(), t.tolist(), strict=True)) == _greedy_by_hand(boxes, tracks, min_iou)
    assert np.count_nonzero(within.sum(axis=1) > 1) > len(boxes) // 2  # they compete


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31), st.sampled_from([0.2, 0.5, 0.9]), st.sampled_from([1, 3, 8]))
def test_nearest_tracks_are_the_nearest_within_reach(seed: int, min_iou: float, k: int) -> None:
    """Each box is paired with its k nearest tracks within reach (all of them if fewer), on a
    coarse grid of many equal distances; boxes that are not finite and proper with none."""
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(0, 60)), int(rng.integers(0, 60))
    lt_b, lt_t = rng.integers(0, 40, (n, 2)) * 1.0, rng.integers(0, 40, (m, 2)) * 1.0
    boxes = np.concatenate([lt_b, lt_b + rng.integers(-1, 12, (n, 2))], axis=1)
    tracks = np.concatenate([lt_t, lt_t + rng.integers(-1, 12, (m, 2))], axis=1)
    boxes[rng.random(n) < 0.1, rng.integers(0, 4)] = np.nan
    tracks[rng.random(m) < 0.1, rng.integers(0, 4)] = np.inf
    bi, ti = association.nearest_tracks(boxes, tracks, min_iou, k)
    usable_b = np.isfinite(boxes).all(axis=1) & (boxes[:, 2:] > boxes[:, :2]).all(axis=1)
    usable_t = np.isfinite(tracks).all(axis=1) & (tracks[:, 2:] > tracks[:, :2]).all(axis=1)
    with np.errstate(invalid="ignore"):
        dist = _edge_distance(boxes, tracks)
        within = (dist <= _reach(boxes, min_iou)[:, None]) & usable_b[:, None] & usable_t[None, :]
    for box in range(n):
        got = ti[bi == box]
        want = np.flatnonzero(within[box])
        assert len(set(got.tolist())) == len(got) == min(k, len(want))
        assert set(got.tolist()) <= set(want.tolist())
        if len(got) < len(want):  # none left out is nearer than one taken
            left_out = np.setdiff1d(want, got)
            assert dist[box, left_out].min() >= dist[box, got].max()
