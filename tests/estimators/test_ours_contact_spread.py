"""The drive's ground-contact spread from all its targets' cue gaps, and the two readings of
each target (experimental setting ``learn_contact_spread``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.estimators import CLASS_PRIORS
from slopedist.estimators.ours import OursEstimator
from slopedist.estimators.ours.contact_spread import (
    MIN_SHARE,
    ContactSpread,
    mix_readings,
    tight_weights,
)
from slopedist.estimators.ours.fusion import LogCue
from slopedist.estimators.ours.records import FusedCues
from slopedist.odometry.base import RotationTrack
from slopedist.streaming.step import estimate_sequence
from slopedist.synthetic.traffic import simulate_traffic

H = 1.65
CONFIGURED_RAD = math.radians(1.06)  # 1° gradient, 0.2° mount, 0.3° jitter


def _drive(spread: ContactSpread, sigma_delta_rad: float, seed: int = 0) -> None:
    """12 vehicles at 8–60 m for 8 s at 10 Hz: gaps ``δ + b·h/z`` (δ per vehicle, the size
    deviation b 8.5 % per vehicle, a little white noise)."""
    rng = np.random.default_rng(seed)
    n = 12
    z0, speed = rng.uniform(8, 60, n), rng.uniform(-4, 4, n)
    delta, dev = rng.normal(0, sigma_delta_rad, n), rng.normal(0, 0.085, n)
    for k in range(80):
        z = np.maximum(z0 + speed * 0.1 * k, 5.0)
        gap = delta + dev * H / z + rng.normal(0, 1e-4, n)
        spread.add_gaps(np.arange(n), gap, (H / z) ** 2, 0.1 * k)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_flat_road_lowers_the_scale_and_a_rough_one_keeps_it(seed: int) -> None:
    flat = ContactSpread(CONFIGURED_RAD, 0.085)
    _drive(flat, 0.0, seed)
    assert flat.scale < 0.05  # the contact's σ at most a fifth of the configured
    rough = ContactSpread(CONFIGURED_RAD, 0.085)
    _drive(rough, math.radians(1.5), seed)
    assert rough.scale > 0.5
    rough.reset()
    assert rough.scale == 1.0 and rough.tight_share == 0.5


def test_the_tight_share_follows_the_targets_posterior_within_its_bounds() -> None:
    spread = ContactSpread(CONFIGURED_RAD, 0.085)
    assert spread.tight_share == 0.5  # no target yet: even
    for k in range(100):
        spread.add_posterior(np.ones(5), 0.1 * k)
    assert spread.tight_share == pytest.approx(1.0 - MIN_SHARE)
    for k in range(100, 200):
        spread.add_posterior(np.zeros(5), 0.1 * k)
    assert spread.tight_share == pytest.approx(MIN_SHARE)


def _fused(mean: float, var: float, white: float, loglik: list[float]) -> FusedCues:
    one = np.array([mean])
    cue = LogCue(one, np.array([var]), np.array([white]), np.zeros(1))
    ll = np.array([loglik])
    return FusedCues(cue, cue, ll, np.log(np.full_like(ll, 1.0 / ll.shape[1])), ll, one, one, one)


def test_the_readings_weigh_by_their_marginal_likelihood_and_share() -> None:
    tight = _fused(1.0, 0.1, 0.01, [-1.0, -3.0])
    wide = _fused(2.0, 0.3, 0.02, [-2.0, -2.0])
    # marginal likelihoods ½(e⁻¹ + e⁻³) and e⁻², prior odds 1 : 3
    odds = 0.5 * (math.exp(-1) + math.exp(-3)) / math.exp(-2) / 3.0
    w = tight_weights(tight, wide, 0.25)
    assert w[0] == pytest.approx(odds / (1 + odds))
    mixed = mix_readings(tight, wide, np.array([0.25])).measurement
    assert mixed.mean[0] == pytest.approx(1.75)
    assert mixed.var[0] == pytest.approx(0.25 * 0.1 + 0.75 * 0.3 + 0.25 * 0.75 * 1.0)
    assert mixed.var_white[0] == pytest.approx(0.25 * 0.01 + 0.75 * 0.02)


def _flat_road_errors(options: dict[str, object]) -> tuple[float, float]:
    """RMSE (m) of ``ours`` and of eq. 1 (+ half the Car length) on flat-road traffic with an
    exact calibration (the flat-road benchmark's KITTI camera, seed 0)."""
    cam = Camera(721.5, 609.6, 172.9, 1.65, 0.0)
    sim = simulate_traffic(cam, 10, 150, seed=0, box_noise_px=0.5, frame_period_s=0.1)
    n = len(sim.timestamps_s)
    track = RotationTrack(sim.timestamps_s, np.repeat(np.eye(3)[None], n, 0), np.ones(n, bool))
    est = OursEstimator(cam, reference="centre", **options)
    out = estimate_sequence(est, sim.boxes, sim.timestamps_s, track).estimates
    bottom = np.asarray(sim.boxes.boxes)[:, 3]
    eq1 = cam.f * cam.height_m / (bottom - cam.c_y) + 0.5 * CLASS_PRIORS["Car"].length_m
    ok = np.asarray(out.status, dtype=object) == "ok"
    err, err_eq1 = (np.asarray(out.distance_m) - sim.z_m)[ok], (eq1 - sim.z_m)[ok]
    return float(np.sqrt(np.mean(err**2))), float(np.sqrt(np.mean(err_eq1**2)))


def test_on_a_flat_road_the_learned_spread_matches_eq1() -> None:
    ours, eq1 = _flat_road_errors({})
    assert ours > 1.5 * eq1  # the configured trust leans on the size cues
    ours, eq1 = _flat_road_errors({"learn_contact_spread": True})
    assert ours < eq1
