"""The occlusion-aware size cue of ``ours``: which box sides nearer boxes may cut, the censored
cue's variance, and a car whose box shows only its visible part."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist.core.camera import Camera
from slopedist.estimators.base import FrameInput
from slopedist.estimators.ours import OursEstimator, cues, occlusion
from slopedist.io.detections.boxes import BoxTable

CAM = Camera(721.5, 609.6, 172.9, 1.65, 0.0)
CAR = np.array([1.53, 1.63, 3.88])
VAN = np.array([2.18, 1.91, 5.08])  # the Van prior: roof above the camera


def test_hidden_sides_by_hand() -> None:
    boxes = np.array(
        [
            [100, 100, 200, 150],  # right edge on box 1, left edge on box 2
            [150, 120, 300, 200],  # nearer than box 0; its edges are clear
            [0, 0, 120, 300.0],  # nearest (lowest bottom)
            [500, 100, 520, 120],  # alone
            [301, 150, 340, 180],
        ]
    )  # left edge touches box 1 (within 1.5 px)
    cut_w, cut_h = occlusion.hidden_sides(boxes)
    assert cut_w.tolist() == [True, False, False, False, True]
    # box 0: top (row 100) on box 2's rows [0, 300]; bottom (150) on boxes 1 and 2
    assert cut_h.tolist() == [True, False, False, False, True]
    cut_w, cut_h = occlusion.hidden_sides(boxes, tol_px=0.5)  # 1 px apart: no longer touching
    assert cut_w.tolist() == [True, False, False, False, False]
    # a farther box covering a nearer one does not cut it
    assert occlusion.hidden_sides(boxes[[2, 0]])[0].tolist() == [False, True]


def _brute_force(b: np.ndarray, tol: float) -> tuple[list[bool], list[bool]]:
    cut_w, cut_h = [], []
    for i in range(len(b)):
        w = h = False
        for j in range(len(b)):
            if b[j, 3] <= b[i, 3]:
                continue
            lo, hi = b[j, :2] - tol, b[j, 2:] + tol
            if not all(min(b[i, 2 + a], hi[a]) > max(b[i, a], lo[a]) for a in (0, 1)):
                continue
            w |= any(lo[0] <= b[i, k] <= hi[0] for k in (0, 2))
            h |= any(lo[1] <= b[i, k] <= hi[1] for k in (1, 3))
        cut_w.append(w)
        cut_h.append(h)
    return cut_w, cut_h


@settings(max_examples=80, deadline=None)
@given(
    st.lists(
        st.tuples(st.floats(0, 500), st.floats(0, 300), st.floats(1, 200), st.floats(1, 100)),
        min_size=1,
        max_size=8,
    ),
    st.floats(0.0, 3.0),
)
def test_hidden_sides_match_a_brute_force_loop(
    raw: list[tuple[float, float, float, float]], tol: float
) -> None:
    b = np.array([[x, y, x + w, y + h] for x, y, w, h in raw])
    cut_w, cut_h = occlusion.hidden_sides(b, tol)
    assert (cut_w.tolist(), cut_h.tolist()) == _brute_force(b, tol)


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**31), st.floats(0.0, 3.0))
def test_hidden_sides_of_many_boxes_match_a_brute_force_loop(seed: int, tol: float) -> None:
    """Above a few dozen boxes only the overlapping pairs are visited (a sweep): same flags."""
    rng = np.random.default_rng(seed)
    n = occlusion._DENSE_MAX_BOXES + 70
    x, y = rng.uniform(0, 1200, n).round(1), rng.uniform(100, 250, n).round(1)
    w, h = rng.uniform(1, 120, n).round(1), rng.uniform(1, 80, n).round(1)
    b = np.stack([x, y, x + w, y + h], axis=1)
    b[:5, 2:] = b[5:10, :2] - tol  # edges exactly touching a widened neighbour
    b[:5, :2] = b[:5, 2:] - 10.0
    cut_w, cut_h = occlusion.hidden_sides(b, tol)
    assert (cut_w.tolist(), cut_h.tolist()) == _brute_force(b, tol)


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 2**31), st.sampled_from([0.0, 0.5, 1.5]), st.sampled_from([1, 10]))
def test_hidden_sides_of_crowded_boxes_match_testing_every_pair(
    seed: int, tol: float, step: int
) -> None:
    """Hundreds of boxes crowding the image on a coarse grid (equal edges, boxes on top of each
    other, a few inverted): the sweep gives the flags of testing every pair, whether the cuts
    are found among the neighbours in column order or by the segment trees."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(occlusion._DENSE_MAX_BOXES + 1, 700))
    x, y = rng.integers(0, 600 // step, n) * step, rng.integers(100 // step, 250 // step, n) * step
    w, h = rng.integers(-1, 200 // step, n) * step, rng.integers(0, 120 // step, n) * step
    b = np.stack([x, y, x + w, y + h], axis=1).astype(float)
    lo, hi = b[:, :2] - tol, b[:, 2:] + tol
    dense_w, dense_h = occlusion._hidden_sides_dense(b, lo, hi)
    for cut_w, cut_h in (
        occlusion.hidden_sides(b, tol),
        occlusion._hidden_sides_pairs(b, lo, hi),
        occlusion._hidden_sides_sweep(b, lo, hi),
    ):
        assert cut_w.tolist() == dense_w.tolist()
        assert cut_h.tolist() == dense_h.tolist()
    assert dense_w.any() and dense_h.any()
    for neighbours in (0, 1):  # every box left to the trees; most of them
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(occlusion, "_WITNESS_NEIGHBOURS", neighbours)
            cut_w, cut_h = occlusion._hidden_sides_sweep(b, lo, hi)
        assert (cut_w.tolist(), cut_h.tolist()) == (dense_w.tolist(), dense_h.tolist())


def test_witnessed_cuts_are_cuts_and_leave_few_in_a_crowd() -> None:
    """In a crowd nearly every box is cut by one of its neighbours in column order; the cuts
    found there are cuts (a subset of the flags)."""
    rng = np.random.default_rng(3)
    n = 1000
    x, y = rng.uniform(0, 200, n), rng.uniform(100, 130, n)
    w, h = rng.uniform(20, 40, n), rng.uniform(15, 30, n)
    b = np.stack([x, y, x + w, y + h], axis=1)
    lo, hi = b[:, :2] - 1.5, b[:, 2:] + 1.5
    seen_w, seen_h = occlusion._witnessed_cuts(b, lo, hi)
    dense_w, dense_h = occlusion._hidden_sides_dense(b, lo, hi)
    assert not (seen_w & ~dense_w).any() and not (seen_h & ~dense_h).any()
    assert np.count_nonzero(dense_w & ~seen_w) < n // 20


def test_censored_cue_variance() -> None:
    # a cue 0.5 (log) farther than the reference, noise 0.01 + 0.01: 3σ test → 0.25 − 0.18
    ux = occlusion.unexplained_excess(math.log(30.0) + 0.5, 0.01, math.log(30.0), 0.01, 3.0)
    assert ux == pytest.approx(0.25 - 9 * 0.02)
    assert occlusion.occlusion_log_var(ux, True) == pytest.approx(0.25 - 0.18)
    assert occlusion.occlusion_log_var(ux, False) == 0.0  # no edge on a nearer box: not cut
    # nearer than the reference, or within the noise: no extra variance
    assert (
        occlusion.occlusion_log_var(occlusion.unexplained_excess(2.0, 0.01, 2.5, 0.01), True) == 0.0
    )
    assert (
        occlusion.occlusion_log_var(occlusion.unexplained_excess(2.1, 0.01, 2.0, 0.01), True) == 0.0
    )
    assert (
        occlusion.occlusion_log_var(occlusion.unexplained_excess(np.nan, 0.01, 2.0, 0.01), True)
        == 0.0
    )


def _frame(
    k: int, boxes: np.ndarray, ids: list[int], classes: list[str] | None = None
) -> FrameInput:
    table = BoxTable.build(
        np.full(len(boxes), k),
        boxes,
        ids,
        classes=np.array(classes or ["Car"] * len(boxes), dtype=object),
    )
    return FrameInput(k, 0.1 * k, 0.0, table, R_world_cam=np.eye(3))


def test_a_car_half_hidden_behind_a_van_relies_on_ground_contact() -> None:
    """A car 25 m ahead, its left part hidden behind a van 10 m ahead (taller than the camera,
    so the car's roof does not show above it): the box around its visible part is a third of
    its width and the width cue says ~70 m. With the occlusion check the car's distance comes
    from its height and its ground contact."""
    van = cues.project_box(CAM.f, CAM.c_x, CAM.c_y, 1.65, 0.0, 10.0, 0.0, VAN)
    car = cues.project_box(CAM.f, CAM.c_x, CAM.c_y, 1.65, 2.6, 25.0, 0.0, CAR)
    assert van[0] < car[0] < van[2] < car[2] and van[1] < car[1] and car[3] < van[3]
    visible = car.copy()
    visible[0] = van[2]  # what shows right of the van
    assert (visible[2] - visible[0]) < 0.4 * (car[2] - car[0])
    boxes = np.stack([van, visible])
    errs = {}
    for aware in (True, False):
        est = OursEstimator(CAM, occlusion_aware=aware)
        outs = [est.estimate(_frame(k, boxes, [1, 2], ["Van", "Car"])) for k in range(10)]
        errs[aware] = abs(outs[-1].distance_m[1] - 25.0)
        assert outs[-1].distance_m[0] == pytest.approx(10.0, rel=0.1)  # the van: unaffected
    assert errs[True] < 0.1 * 25.0
    assert errs[True] < 0.5 * errs[False]


def test_amodal_boxes_of_overlapping_cars_keep_their_size_cues() -> None:
    """Whole-vehicle boxes (labels) that overlap: the size cues agree with the ground contact
    within their noise, so nothing changes."""
    near = cues.project_box(CAM.f, CAM.c_x, CAM.c_y, 1.65, 0.0, 10.0, 0.0, CAR)
    far = cues.project_box(CAM.f, CAM.c_x, CAM.c_y, 1.65, 1.0, 30.0, 0.0, CAR)
    boxes = np.stack([near, far])
    a = OursEstimator(CAM).estimate(_frame(0, boxes, [1, 2]))
    b = OursEstimator(CAM, occlusion_aware=False).estimate(_frame(0, boxes, [1, 2]))
    np.testing.assert_array_equal(a.distance_m, b.distance_m)
