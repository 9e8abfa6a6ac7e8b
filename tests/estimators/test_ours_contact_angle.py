"""The contact's angle error from each track's cues over its distances (experimental setting
``learn_contact_angle``) and the horizon jitter from θ (``learn_horizon_jitter``)."""

from __future__ import annotations

import math

import numpy as np

from slopedist.estimators.ours.contact_angle import ContactAngleEvidence, track_intercepts
from slopedist.estimators.ours.road_roughness import HorizonJitter

H = 1.65


def _track_sums(delta_rad: float, size_dev: float, z_m: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """The sums of one track whose contact is off by the angle ``delta_rad`` and whose size
    cue is off by the factor ``1 − size_dev``."""
    x = (1.0 - size_dev) / z_m
    y = 1.0 / z_m + delta_rad / H - x
    return np.array([x.size, x.sum(), y.sum(), x @ x, x @ y, y @ y, t_s[0], t_s[-1]])


def test_the_intercept_tells_the_angle_apart_from_the_size_deviation() -> None:
    z = np.linspace(40.0, 10.0, 50)
    t = np.arange(50) * 0.1
    for delta, dev in ((0.0, 0.08), (math.radians(0.5), -0.05), (math.radians(-1.0), 0.0)):
        d, var = track_intercepts(_track_sums(delta, dev, z, t)[None], H)
        assert abs(d[0] - delta) < 1e-9 and var[0] < 1e-12
    # at one distance the two look alike: no intercept
    d, _ = track_intercepts(_track_sums(0.01, 0.05, np.full(50, 20.0), t)[None], H)
    assert np.isnan(d[0])


def test_exact_contacts_lower_the_scale_and_biased_ones_keep_it() -> None:
    rng = np.random.default_rng(3)
    n = 12  # vehicles seen together for 8 s
    for delta_sigma, low in ((0.0, True), (math.radians(2.0), False)):
        evidence = ContactAngleEvidence(math.radians(1.0), 1.0)
        z0, speed = rng.uniform(15, 60, n), rng.uniform(-8, 4, n)
        delta, dev = rng.normal(0, delta_sigma, n), rng.normal(0, 0.07, n)
        for k in range(80):
            z = np.maximum(z0 + speed * 0.1 * k, 5.0)
            noise = rng.normal(0, 2e-4, (2, n))
            inv_size = (1 - dev) / z + noise[0]
            inv_contact = 1 / z + delta / H + noise[1]
            evidence.add(np.arange(n), inv_size, inv_contact, 0.1 * k, H)
        assert (evidence.scale < 0.1) if low else (evidence.scale == 1.0)


def test_the_horizon_jitter_follows_the_white_noise_of_theta() -> None:
    rng = np.random.default_rng(0)
    for sigma in (0.0, math.radians(0.1)):
        jitter = HorizonJitter(math.radians(0.3))
        for k in range(600):
            jitter.update(0.1 * k, 0.01 * math.sin(0.2 * k * 0.1) + rng.normal(0, sigma))
        assert abs(jitter.sigma_rad - sigma) < 0.15 * sigma + math.radians(0.03)
    gappy = HorizonJitter(math.radians(0.3))
    for t in (0.0, 0.1, 0.5, 0.6, 2.0):  # no evenly spaced triple
        gappy.update(t, 0.0)
    assert math.isclose(gappy.sigma_rad, math.radians(0.3))
