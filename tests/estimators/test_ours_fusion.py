"""Fusion of the log-distance cues of ``ours``: inverse-variance fusion, mixtures over the
hypotheses and censoring by upper bounds, against hand-computed values and numerical
integration."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slopedist.estimators.ours import fusion


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
