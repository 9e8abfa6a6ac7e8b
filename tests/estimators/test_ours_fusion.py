"""Fusion of the log-distance cues of ``ours``: inverse-variance fusion, mixtures over the
hypotheses and censoring by upper bounds, against hand-computed values and numerical
integration."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slopedist.estimators.ours import fusion
from slopedist.estimators.ours.cues import SizeCue


def test_fuse_log_cues_weights_by_variance_and_scores_consistency() -> None:
    a = fusion.LogCue(np.array(math.log(20.0)), np.array(0.01), np.array(0.001), np.array(0.0))
    b = fusion.LogCue(np.array(math.log(25.0)), np.array(0.04), np.array(0.04), np.array(0.0))
    out = fusion.fuse_log_cues(a, b)
    assert out.mean == pytest.approx(0.8 * math.log(20.0) + 0.2 * math.log(25.0))
    assert out.var == pytest.approx(0.008)
    assert out.var_white == pytest.approx(0.64 * 0.001 + 0.04 * 0.04)
    far = fusion.fuse_log_cues(
        a, fusion.LogCue(np.array(math.log(60.0)), b.var, b.var_white, b.loglik)
    )
    assert far.loglik < out.loglik  # an inconsistent cue is less likely
    none = fusion.fuse_log_cues(a, fusion.LogCue(np.array(np.nan), b.var, b.var_white, b.loglik))
    assert none.mean == a.mean and none.var == a.var


def test_collapse_hypotheses_moments() -> None:
    cue = fusion.LogCue(
        np.array([[1.0, 2.0]]), np.array([[0.1, 0.2]]), np.array([[0.01, 0.02]]), np.zeros((1, 2))
    )
    out, w = fusion.collapse_hypotheses(cue, np.log([[0.25, 0.75]]))
    assert w == pytest.approx(np.array([[0.25, 0.75]]))
    assert out.mean[0] == pytest.approx(1.75)
    assert out.var[0] == pytest.approx(0.25 * 0.1 + 0.75 * 0.2 + 0.25 * 0.75**2 + 0.75 * 0.25**2)
    assert out.var_white[0] == pytest.approx(0.25 * 0.01 + 0.75 * 0.02)


@pytest.mark.parametrize("bound", [-3.0, -0.4, 0.0, 0.7, 4.0])
def test_censor_upper_matches_numerical_integration(bound: float) -> None:
    # N(μ=0.2, v=0.09) times the bound's likelihood Φ((bound − ℓ)/s), s² = 0.04
    from scipy import stats

    mu, var, s2 = 0.2, 0.09, 0.04
    cue = fusion.LogCue(np.array([mu]), np.array([var]), np.array([0.03]), np.array([0.0]))
    out = fusion.censor_upper(cue, np.array([bound]), np.array([s2]), np.array([True]))
    x = np.linspace(mu - 12 * math.sqrt(var), mu + 12 * math.sqrt(var), 200001)
    post = stats.norm.pdf(x, mu, math.sqrt(var)) * stats.norm.cdf((bound - x) / math.sqrt(s2))
    z = np.trapezoid(post, x)
    m = np.trapezoid(x * post, x) / z
    v = np.trapezoid((x - m) ** 2 * post, x) / z
    assert out.mean[0] == pytest.approx(m, abs=1e-6)
    assert out.var[0] == pytest.approx(v, rel=1e-5)
    assert out.loglik[0] == pytest.approx(math.log(z), abs=1e-6)
    assert out.var_white[0] == pytest.approx(0.03 * v / var, rel=1e-5)


def test_censor_upper_leaves_unmasked_and_missing_bounds_alone() -> None:
    cue = fusion.LogCue(
        np.array([1.0, 1.0]), np.array([0.1, 0.1]), np.array([0.05, 0.05]), np.array([-1.0, -1.0])
    )
    out = fusion.censor_upper(
        cue, np.array([0.0, np.nan]), np.array([0.01, 0.01]), np.array([False, True])
    )
    for k in ("mean", "var", "var_white", "loglik"):
        assert getattr(out, k) == pytest.approx(getattr(cue, k))


def test_cue_consistency_check_widens_only_cues_that_disagree() -> None:
    from slopedist.estimators.ours.fusion import LogCue, check_consistency

    size = LogCue(np.log([20.0, 20.0, 20.0]), np.full(3, 0.01), np.full(3, 0.005), np.zeros(3))
    ground = LogCue(
        np.log([21.0, 40.0, np.nan]), np.array([0.03, 0.03, np.nan]), np.full(3, 0.0), np.zeros(3)
    )
    fused = LogCue(np.log([20.2, 25.0, 20.0]), np.full(3, 0.008), np.full(3, 0.004), np.zeros(3))
    out, gap = check_consistency(fused, size, ground, 3.0)
    d = math.log(20 / 40)
    assert gap[0] == pytest.approx(math.log(20 / 21) / 0.2)
    assert gap[1] == pytest.approx(d / 0.2) and gap[1] < -3
    assert np.isnan(gap[2])
    assert out.var[0] == 0.008 and out.var[2] == 0.008  # agree, or no ground contact
    assert out.var[1] == pytest.approx(0.02 + d * d / 4)
    assert np.array_equal(out.mean, fused.mean) and np.array_equal(out.var_white, fused.var_white)


def test_fused_is_never_much_worse_than_the_better_single_cue(kitti_tracking_dir) -> None:
    """On two shared sequences with ground-truth boxes, the fused distance against the size
    cue alone and the ground contact alone (all capped at 80 m); the gap is recorded."""
    from slopedist.estimators import make_estimator
    from slopedist.io.kitti.tracking import RotationSource, load_sequence, protocol_mask
    from slopedist.streaming.step import estimate_sequence

    for name in ("0004", "0018"):
        seq = load_sequence(kitti_tracking_dir, name)
        gt = seq.labels.select(protocol_mask(seq.labels))
        track = seq.rotations(RotationSource.ORBSLAM3)
        res = estimate_sequence(make_estimator("ours", seq.camera), gt, seq.timestamps_s, track)
        z = res.boxes.extra["z"]
        extra = res.estimates.extra
        assert np.isfinite(extra["cue_gap_sigma"]).mean() > 0.9

        size, ground, fused = (
            _capped_rmse(d, z)
            for d in (
                extra["distance_size_m"],
                extra["distance_ground_contact_m"],
                res.estimates.distance_m,
            )
        )
        assert fused <= 1.05 * min(size, ground), name


def _capped_rmse(d: np.ndarray, z: np.ndarray) -> float:
    return float(np.sqrt(np.nanmean((np.minimum(d, 80.0) - z) ** 2)))


def test_shape_gap_is_the_best_headings_height_width_gap_in_sigma() -> None:
    """Two targets × two headings; the class prior's log spreads 0.1 (height) and 0.1 (width),
    uncorrelated, no pixel noise: ``var(y_h − y_w) = 0.02``. Target 0's width agrees with its
    height at heading 1 (gap 0); target 1's box is 40 % too narrow at both (a truck called a
    car): ``log 1.4 / √0.02``. A missing width cue gives NaN."""
    ell = math.log(10.0)
    zero = np.zeros((3, 2))
    height = SizeCue(np.full((3, 2), ell), np.ones((3, 2)), zero, zero)
    width_mean = np.array(
        [[ell + 0.3, ell], [ell - math.log(1.4), ell - math.log(1.4)], [np.nan, np.nan]]
    )
    width = SizeCue(width_mean, np.ones((3, 2)), zero, zero)
    gap = fusion.shape_gap_sigma(height, width, 0.1, 0.1, 0.0)
    assert gap[0] == pytest.approx(0.0)
    assert gap[1] == pytest.approx(math.log(1.4) / math.sqrt(0.02))
    assert math.isnan(gap[2])
