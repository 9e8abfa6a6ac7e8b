"""Metrics against hand-computed values, the cap rule and detection matching."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from slopedist.evaluation.accuracy_tables import rmse_table, uncertainty_table
from slopedist.evaluation.metrics import (
    GAUSSIAN_COVERAGE,
    SIGMA_LEVELS,
    PooledScores,
    ScoredSet,
    binned_metrics,
    cap_estimates,
    distance_metrics,
    match_boxes,
    match_by_frame,
    pool,
    pool_methods,
    uncertainty_metrics,
)
from slopedist.io.detections import BoxTable


def test_metrics_hand_computed() -> None:
    m = distance_metrics([10.0, 22.0], [10.0, 20.0])
    assert m["n"] == 2
    assert m["rmse"] == pytest.approx(math.sqrt(2.0))  # sqrt((0 + 4) / 2)
    assert m["mae"] == pytest.approx(1.0)
    assert m["abs_rel"] == pytest.approx(0.05)  # (0 + 2/20) / 2
    assert m["sq_rel"] == pytest.approx(0.1)  # (0 + 4/20) / 2
    assert m["rmse_log"] == pytest.approx(math.sqrt(math.log(1.1) ** 2 / 2))
    assert m["delta_1.25"] == 1.0
    m2 = distance_metrics([30.0, 38.0], [20.0, 20.0])  # ratios 1.5 and 1.9
    assert (m2["delta_1.25"], m2["delta_1.25^2"], m2["delta_1.25^3"]) == (0.0, 0.5, 1.0)


def test_empty_metrics() -> None:
    m = distance_metrics([], [])
    assert m["n"] == 0 and math.isnan(m["rmse"])


def test_bins_split_by_truth() -> None:
    b = binned_metrics([5.0, 15.0, 45.0], [5.0, 10.0, 50.0])
    assert b["0-10"]["n"] == 2 and b["0-10"]["rmse"] == pytest.approx(math.sqrt(12.5))
    assert b["40-80"]["n"] == 1 and b["10-20"]["n"] == 0


def test_cap_rule() -> None:
    d, ok = cap_estimates(
        [10.0, 120.0, np.nan, np.nan, np.nan],
        ["", "", "below_horizon", "no_rotation", "near_horizon"],
        80.0,
    )
    np.testing.assert_array_equal(d[[0, 1, 2, 4]], [10.0, 80.0, 80.0, 80.0])
    assert list(ok) == [True, True, True, False, True]


def test_greedy_matching_best_pair_first() -> None:
    gt = np.array([[0, 0, 10, 10], [8, 0, 18, 10]])
    det = np.array([[1, 0, 11, 10], [0, 0, 10, 10]])
    d, g = match_boxes(det, gt)
    # det 1 = gt 0 exactly (IoU 1) is taken first; det 0 then overlaps gt 1 with IoU < 0.5
    assert list(zip(d, g)) == [(1, 0)]


def test_match_by_frame_never_crosses_frames() -> None:
    gt = BoxTable.build([0, 1], [[0, 0, 10, 10], [0, 0, 10, 10]])
    det = BoxTable.build([1, 1], [[0, 0, 10, 10], [0, 0, 10, 11]])
    d, g = match_by_frame(det, gt)
    assert list(d) == [0] and list(g) == [1]


@given(
    st.lists(
        st.tuples(st.floats(0, 50), st.floats(0, 50), st.floats(1, 30), st.floats(1, 30)),
        max_size=8,
    ),
    st.lists(
        st.tuples(st.floats(0, 50), st.floats(0, 50), st.floats(1, 30), st.floats(1, 30)),
        max_size=8,
    ),
)
def test_matching_is_one_to_one_and_above_threshold(a: list, b: list) -> None:
    det = np.array([[x, y, x + w, y + h] for x, y, w, h in a]).reshape(-1, 4)
    gt = np.array([[x, y, x + w, y + h] for x, y, w, h in b]).reshape(-1, 4)
    d, g = match_boxes(det, gt, 0.5)
    assert len(set(d)) == len(d) and len(set(g)) == len(g)
    from slopedist.io.detections import iou_matrix

    if len(d):
        assert np.all(iou_matrix(det, gt)[d, g] >= 0.5)


def _set(pred: list[float], gt: list[float], missing: str = "") -> ScoredSet:
    info = {"missing": missing} if missing else {}
    return ScoredSet(np.array(pred), np.array(gt), n_gt=len(gt), frames=1, info=info)


def test_pool_methods_own_sequences_and_common_pool() -> None:
    per_seq = {
        "a": {"x": _set([10.0], [11.0]), "y": _set([12.0], [11.0])},
        "b": {"x": _set([20.0, 22.0], [20.0, 20.0]), "y": _set([], [], "no poses")},
    }
    scores = pool_methods(per_seq, ["x", "y"])
    assert scores.pooled == {"x": ["a", "b"], "y": ["a"]}
    # x pooled over its own sequences: errors 1, 0, 2
    assert scores.overall["x"]["rmse"] == pytest.approx(math.sqrt(5.0 / 3.0))
    assert scores.overall["y"]["rmse"] == pytest.approx(1.0)
    assert scores.summaries["b"]["y"]["missing"] == "no poses"
    assert scores.common is not None and scores.common["sequences"] == ["a"]
    assert scores.common["methods"]["x"]["rmse"] == pytest.approx(1.0)
    back = PooledScores.from_report(
        {"methods": scores.method_reports(), "overall_common": scores.common}
    )
    assert back == scores


def test_pool_methods_no_common_when_every_method_ran_everywhere() -> None:
    scores = pool_methods({"a": {"x": _set([1.0], [1.0]), "y": _set([2.0], [1.0])}}, ["x", "y"])
    assert scores.common is None and scores.pooled == {"x": ["a"], "y": ["a"]}


def test_uncertainty_metrics_hand_computed() -> None:
    # errors 0.5, -3, 1.5, 10 m against σ 1, 2, 1, 2: |error|/σ = 0.5, 1.5, 1.5, 5
    u = uncertainty_metrics([10.5, 17.0, 31.5, 50.0], [10.0, 20.0, 30.0, 40.0], [1, 2, 1, 2])
    assert u["n_sigma"] == 4
    assert u["within_1sigma"] == pytest.approx(0.25)
    assert u["within_2sigma"] == pytest.approx(0.75)
    assert u["within_3sigma"] == pytest.approx(0.75)
    assert u["z_rms"] == pytest.approx(math.sqrt((0.25 + 2.25 + 2.25 + 25.0) / 4))


def test_uncertainty_metrics_leave_out_targets_without_a_sigma() -> None:
    u = uncertainty_metrics([11.0, 12.0, 13.0], [10.0, 10.0, 10.0], [2.0, math.nan, 0.0])
    assert u["n_sigma"] == 1 and u["within_1sigma"] == 1.0 and u["z_rms"] == pytest.approx(0.5)
    none = uncertainty_metrics([11.0], [10.0], [math.nan])
    assert none["n_sigma"] == 0 and math.isnan(none["z_rms"])


def test_a_right_gaussian_sigma_covers_as_a_gaussian() -> None:
    rng = np.random.default_rng(3)
    truth = rng.uniform(5.0, 80.0, 20000)
    sigma = 0.05 * truth
    u = uncertainty_metrics(truth + sigma * rng.standard_normal(truth.size), truth, sigma)
    for k in SIGMA_LEVELS:
        assert u[f"within_{k}sigma"] == pytest.approx(GAUSSIAN_COVERAGE[k], abs=0.01)
    assert u["z_rms"] == pytest.approx(1.0, abs=0.02)
    # a σ half the true spread promises too much
    assert uncertainty_metrics(truth + sigma * rng.standard_normal(truth.size), truth, sigma / 2)[
        "within_1sigma"
    ] == pytest.approx(0.383, abs=0.01)


def test_sigma_is_pooled_only_when_every_set_has_one() -> None:
    with_sigma = ScoredSet(np.array([11.0]), np.array([10.0]), 1, sigma_m=np.array([2.0]))
    also = ScoredSet(np.array([14.0]), np.array([10.0]), 1, sigma_m=np.array([2.0]))
    without = _set([10.0], [10.0])
    pooled = pool([with_sigma, also]).summary(with_recall=False)["uncertainty"]
    assert pooled["n_sigma"] == 2 and pooled["within_1sigma"] == pytest.approx(0.5)
    assert "uncertainty" not in pool([with_sigma, without]).summary(with_recall=False)
    scores = pool_methods({"a": {"x": with_sigma, "y": without}}, ["x", "y"])
    table = uncertainty_table(scores)
    assert table is not None and [r[0] for r in table.rows] == ["x"]
    assert table.rows[0][1:] == [1, 1.0, 1.0, 1.0, 0.5]
    assert uncertainty_table(pool_methods({"a": {"y": without}}, ["y"])) is None


def test_rmse_rows_over_different_targets_mark_no_best() -> None:
    """`ours` withheld two boxes of sequence b that `flat` scored: its lower RMSE there is over
    fewer targets, so that row (and the overall one) marks no best, and a note says why."""

    def summary(n: int, rmse: float) -> dict[str, float]:
        return {"n": n, "rmse": rmse}

    summaries = {
        "a": {"flat": summary(10, 3.0), "ours": summary(10, 1.0)},
        "b": {"flat": summary(12, 4.0), "ours": summary(10, 2.0)},
    }
    overall = {"flat": summary(22, 3.6), "ours": summary(20, 1.6)}
    pooled = {"flat": ["a", "b"], "ours": ["a", "b"]}
    table = rmse_table(PooledScores(["flat", "ours"], ["a", "b"], summaries, overall, pooled))
    assert [r[:2] for r in table.rows] == [["a", 10], ["b", 12], ["overall", 22]]
    assert [row[2:] for row in table.bold] == [[False, True], [False, False], [False, False]]
    assert (
        "b (n: flat 12, ours 10), overall (n: flat 22, ours 20): the methods were scored over "
        "different targets" in table.note
    )
