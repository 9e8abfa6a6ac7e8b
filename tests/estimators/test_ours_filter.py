"""The Kalman filters of ``ours`` against simulated approaches with known speed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slopedist.estimators.ours import filter as kf


def _matrix_predict(
    x: np.ndarray, P: np.ndarray, dt: float, accel: float
) -> tuple[np.ndarray, np.ndarray]:
    """The reference the state rows are checked against: the textbook extended Kalman
    prediction of one state ``(ℓ, r)`` with its 2×2 covariance (``Z' = Z + Ż·dt``: ``ℓ' = ℓ +
    log(1 + r·dt)``, ``r' = r/(1 + r·dt)``; white-noise acceleration ``accel`` m/s² per √s,
    which is ``accel/Z'`` in ``r``)."""
    log_z, r = x
    grow = max(1.0 + r * dt, kf.MIN_GROWTH)
    F = np.array([[1.0, dt / grow], [0.0, 1.0 / grow**2]])
    z_new = math.exp(log_z) * grow
    q = (accel / z_new) ** 2
    Q = q * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    return np.array([log_z + math.log(grow), r / grow]), F @ P @ F.T + Q


def _matrix_update(
    x: np.ndarray, P: np.ndarray, y: float, r: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """The reference update with a measurement ``y`` of ℓ of variance ``r``: state,
    covariance and normalised innovation squared."""
    H = np.array([[1.0, 0.0]])
    S = float((H @ P @ H.T)[0, 0]) + r
    K = (P @ H.T / S)[:, 0]
    nu = y - x[0]
    return x + K * nu, P - np.outer(K, H @ P), nu * nu / S


def _rows(x: np.ndarray, P: np.ndarray) -> np.ndarray:
    """The state rows ``(5, 1)`` of one state and covariance."""
    return np.array([[x[0]], [x[1]], [P[0, 0]], [P[0, 1]], [P[1, 1]]])


def _run(
    z0: float,
    speed: float,
    n: int,
    noise_log: float,
    seed: int = 0,
    accel: float = 2.0,
    true_accel: float = 0.0,
) -> tuple[np.ndarray, list[tuple[float, ...]]]:
    """Simulate an approach (white-noise acceleration of density ``true_accel``) measured in
    log distance with white noise; returns the final state rows and per-step
    ``(z, d, sd, v, vsd, ttc, ttc_sd, true speed)``."""
    rng = np.random.default_rng(seed)
    dt = 0.1
    s = kf.start_rows(
        np.array([math.log(z0) + rng.normal(0, noise_log)]), np.array([noise_log**2]), 0.5
    )
    out = []
    z, vel = z0, speed
    for _ in range(1, n):
        dv = rng.normal(0.0, true_accel * math.sqrt(dt))
        z += vel * dt + 0.5 * dv * dt
        vel += dv
        s = kf.cv_predict_rows(s, np.array([dt]), accel)
        y = np.array([math.log(z) + rng.normal(0, noise_log)])
        s, _ = kf.cv_update_rows(s, y, np.array([noise_log**2]))
        d, sd = kf.distance_moments_rows(s)
        v, vsd, ttc, ttc_sd = kf.motion_moments_rows(s)
        out.append((z, d[0], sd[0], v[0], vsd[0], ttc[0], ttc_sd[0], vel))
    return s, out


def test_prediction_is_exact_for_constant_velocity() -> None:
    s = _rows(np.array([math.log(40.0), -10.0 / 40.0]), np.zeros((2, 2)))  # closing at 10 m/s
    for _ in range(10):
        s = kf.cv_predict_rows(s, np.array([0.1]), 0.0)
    assert math.exp(s[0, 0]) == pytest.approx(30.0)
    assert s[1, 0] * math.exp(s[0, 0]) == pytest.approx(-10.0)
    assert np.allclose(s[2:], 0.0)


def test_process_noise_grows_the_covariance() -> None:
    s = kf.cv_predict_rows(_rows(np.array([math.log(20.0), 0.0]), np.zeros((2, 2))), 1.0, 2.0)
    assert s[4, 0] == pytest.approx(4.0 / 400.0)  # (a/Z)²·dt
    assert s[2, 0] == pytest.approx(4.0 / 400.0 / 3.0)
    assert np.all(np.linalg.eigvalsh([[s[2, 0], s[3, 0]], [s[3, 0], s[4, 0]]]) >= 0)


def test_filter_recovers_speed_and_ttc_of_an_approach() -> None:
    _, out = _run(z0=60.0, speed=-12.0, n=30, noise_log=0.01)
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
        _, out = _run(z0=50.0, speed=-8.0, n=25, noise_log=0.02, seed=seed, true_accel=2.0)
        z, d, sd, v, vsd, _, _, vel = out[-1]
        errs.append((d - z) / sd)
        verr.append((v - vel) / vsd)
    assert 0.7 < np.std(errs) < 1.4
    assert 0.7 < np.std(verr) < 1.4


def test_filter_smooths_white_noise() -> None:
    _, out = _run(z0=30.0, speed=3.0, n=60, noise_log=0.05, seed=3)
    arr = np.array(out)[:, :2]
    raw = 0.05 * arr[:, 0]
    filt_err = np.abs(arr[20:, 1] - arr[20:, 0])
    assert np.sqrt(np.mean(filt_err**2)) < 0.6 * np.sqrt(np.mean(raw[20:] ** 2))


def test_receding_target_has_no_ttc() -> None:
    _, _, ttc, sd = kf.motion_moments_rows(_rows(np.array([math.log(20.0), 0.1]), 1e-4 * np.eye(2)))
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


def test_the_state_rows_are_the_matrix_filter() -> None:
    """Prediction, update and the reported moments of the state rows against the textbook
    2×2 filter and the log-normal / first-order moments written out."""
    rng = np.random.default_rng(2)
    for _ in range(7):
        x = np.array([math.log(rng.uniform(5, 60)), rng.normal(0, 0.3)])
        A = rng.normal(0, 0.1, (2, 2))
        P = A @ A.T + 1e-4 * np.eye(2)
        dt = float(rng.uniform(0.05, 0.5))
        xp, Pp = _matrix_predict(x, P, dt, 2.0)
        pred = kf.cv_predict_rows(_rows(x, P), np.array([dt]), 2.0)
        np.testing.assert_allclose(pred[:, 0], _rows(xp, Pp)[:, 0], rtol=1e-12, atol=1e-15)
        y, r = float(xp[0] + rng.normal(0, 0.05)), 0.05**2
        xu, Pu, nis = _matrix_update(xp, Pp, y, r)
        upd, nis_rows = kf.cv_update_rows(pred, np.array([y]), np.array([r]))
        np.testing.assert_allclose(upd[:, 0], _rows(xu, Pu)[:, 0], rtol=1e-12, atol=1e-15)
        assert nis_rows[0] == pytest.approx(nis, rel=1e-12)
        extra = 0.01
        s2 = Pu[0, 0] + extra
        mean = math.exp(xu[0] + 0.5 * s2)
        d, sd = kf.distance_moments_rows(upd, extra)
        assert d[0] == pytest.approx(mean, rel=1e-12)
        assert sd[0] == pytest.approx(mean * math.sqrt(math.expm1(s2)), rel=1e-12)
        z, rate = math.exp(xu[0]), xu[1]
        J = np.array([rate * z, z])  # ∂(r·Z)/∂(ℓ, r)
        v, vsd, ttc, ttc_sd = kf.motion_moments_rows(upd)
        assert v[0] == pytest.approx(rate * z, rel=1e-12)
        assert vsd[0] == pytest.approx(math.sqrt(J @ Pu @ J), rel=1e-12)
        if rate < 0:
            assert ttc[0] == pytest.approx(-1.0 / rate, rel=1e-12)
            assert ttc_sd[0] == pytest.approx(math.sqrt(Pu[1, 1]) / rate**2, rel=1e-12)
        else:
            assert np.isnan(ttc[0]) and np.isnan(ttc_sd[0])
