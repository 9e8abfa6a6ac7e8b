"""The Kalman filters of ``ours`` against simulated approaches with known speed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slopedist.estimators.ours import filter as kf


def _run(
    z0: float,
    speed: float,
    n: int,
    noise_log: float,
    seed: int = 0,
    accel: float = 2.0,
    true_accel: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, list[tuple[float, ...]]]:
    """Simulate an approach (white-noise acceleration of density ``true_accel``) measured in
    log distance with white noise; returns the final state and per-step
    ``(z, d, sd, v, vsd, ttc, ttc_sd, true speed)``."""
    rng = np.random.default_rng(seed)
    dt = 0.1
    x = np.array([[math.log(z0) + rng.normal(0, noise_log), 0.0]])
    P = np.array([[[noise_log**2, 0.0], [0.0, 0.5**2]]])
    out = []
    z, vel = z0, speed
    for _ in range(1, n):
        dv = rng.normal(0.0, true_accel * math.sqrt(dt))
        z += vel * dt + 0.5 * dv * dt
        vel += dv
        x, P = kf.cv_predict(x, P, np.array([dt]), accel)
        y = np.array([math.log(z) + rng.normal(0, noise_log)])
        x, P, _ = kf.cv_update(x, P, y, np.array([noise_log**2]))
        d, sd = kf.distance_moments(x, P)
        v, vsd = kf.speed_moments(x, P)
        ttc, ttc_sd = kf.ttc_moments(x, P)
        out.append((z, d[0], sd[0], v[0], vsd[0], ttc[0], ttc_sd[0], vel))
    return x, P, out


def test_prediction_is_exact_for_constant_velocity() -> None:
    x = np.array([[math.log(40.0), -10.0 / 40.0]])  # 40 m, closing at 10 m/s
    P = np.zeros((1, 2, 2))
    for _ in range(10):
        x, P = kf.cv_predict(x, P, np.array([0.1]), 0.0)
    assert math.exp(x[0, 0]) == pytest.approx(30.0)
    assert x[0, 1] * math.exp(x[0, 0]) == pytest.approx(-10.0)
    assert np.allclose(P, 0.0)


def test_process_noise_grows_the_covariance() -> None:
    x = np.array([[math.log(20.0), 0.0]])
    P = np.zeros((1, 2, 2))
    _, P1 = kf.cv_predict(x, P, np.array([1.0]), 2.0)
    assert P1[0, 1, 1] == pytest.approx(4.0 / 400.0)  # (a/Z)²·dt
    assert P1[0, 0, 0] == pytest.approx(4.0 / 400.0 / 3.0)
    assert np.all(np.linalg.eigvalsh(P1[0]) >= 0)


def test_filter_recovers_speed_and_ttc_of_an_approach() -> None:
    _, _, out = _run(z0=60.0, speed=-12.0, n=30, noise_log=0.01)
    z, d, _, v, vsd, ttc, ttc_sd, _ = out[-1]
    assert d == pytest.approx(z, rel=0.03)
    assert v == pytest.approx(-12.0, abs=2.0)
    assert ttc == pytest.approx(z / 12.0, rel=0.2)
    assert abs(v + 12.0) < 3 * vsd  # the stated uncertainty covers the error
    assert ttc_sd > 0


def test_filter_uncertainty_is_calibrated_over_many_runs() -> None:
    """When the target accelerates as the filter assumes, errors/σ have unit spread."""
    errs, verr = [], []
    for seed in range(60):
        _, _, out = _run(z0=50.0, speed=-8.0, n=25, noise_log=0.02, seed=seed, true_accel=2.0)
        z, d, sd, v, vsd, _, _, vel = out[-1]
        errs.append((d - z) / sd)
        verr.append((v - vel) / vsd)
    assert 0.7 < np.std(errs) < 1.4
    assert 0.7 < np.std(verr) < 1.4


def test_filter_smooths_white_noise() -> None:
    _, _, out = _run(z0=30.0, speed=3.0, n=60, noise_log=0.05, seed=3)
    arr = np.array(out)[:, :2]
    raw = 0.05 * arr[:, 0]
    filt_err = np.abs(arr[20:, 1] - arr[20:, 0])
    assert np.sqrt(np.mean(filt_err**2)) < 0.6 * np.sqrt(np.mean(raw[20:] ** 2))


def test_receding_target_has_no_ttc() -> None:
    x = np.array([[math.log(20.0), 0.1]])
    P = np.eye(2)[None] * 1e-4
    ttc, sd = kf.ttc_moments(x, P)
    assert np.isnan(ttc[0]) and np.isnan(sd[0])


def test_random_walk_update() -> None:
    m, v = kf.random_walk_update(
        np.array([0.0]), np.array([1.0]), 1.0, 1.0, np.array([2.0]), np.array([2.0])
    )
    assert m[0] == pytest.approx(1.0) and v[0] == pytest.approx(1.0)
    m2, v2 = kf.random_walk_update(
        np.array([0.5]), np.array([1.0]), 0.0, 0.0, np.array([np.nan]), np.array([1.0])
    )
    assert m2[0] == 0.5 and v2[0] == 1.0


def test_row_layout_matches_the_matrix_layout() -> None:
    rng = np.random.default_rng(2)
    m = 7
    x = np.c_[np.log(rng.uniform(5, 60, m)), rng.normal(0, 0.3, m)]
    A = rng.normal(0, 0.1, (m, 2, 2))
    P = A @ np.swapaxes(A, 1, 2) + 1e-4 * np.eye(2)
    rows = kf.rows_of(x, P)
    x2, P2 = kf.states_of(rows)
    np.testing.assert_array_equal(x2, x)
    np.testing.assert_array_equal(P2, P)
    d, sd = kf.distance_moments(x, P, 0.01)
    d2, sd2 = kf.distance_moments_rows(rows, 0.01)
    np.testing.assert_allclose(d2, d, rtol=1e-12)
    np.testing.assert_allclose(sd2, sd, rtol=1e-12)
    v, vsd = kf.speed_moments(x, P)
    ttc, ttc_sd = kf.ttc_moments(x, P)
    v2, vsd2, ttc2, ttc_sd2 = kf.motion_moments_rows(rows)
    np.testing.assert_allclose(v2, v, rtol=1e-12)
    np.testing.assert_allclose(vsd2, vsd, rtol=1e-12)
    np.testing.assert_allclose(ttc2, ttc, rtol=1e-12)  # NaN where receding, in both
    np.testing.assert_allclose(ttc_sd2, ttc_sd, rtol=1e-12)
    assert np.isnan(ttc2[x[:, 1] >= 0]).all() and np.isfinite(ttc2[x[:, 1] < 0]).all()
