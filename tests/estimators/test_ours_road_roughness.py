"""The drive's road roughness from the ego's gradient history (``adapt_contact_trust``)."""

from __future__ import annotations

import math

import numpy as np

from slopedist.core.camera import Camera
from slopedist.estimators.ours import OursEstimator
from slopedist.estimators.ours.road_roughness import (
    KITTI_THETA_RMS_RAD,
    MAX_SCALE,
    RoadRoughness,
)
from slopedist.odometry.base import RotationTrack
from slopedist.streaming.step import estimate_sequence
from slopedist.synthetic.traffic import simulate_traffic

CAM = Camera(721.5, 609.6, 172.9, 1.65, 0.0)


def _scale_after(theta_change_rad: np.ndarray, period_s: float = 0.1) -> float:
    rough = RoadRoughness()
    for k, th in enumerate(theta_change_rad):
        rough.update(k * period_s, float(th))
    return rough.scale


def test_a_flat_history_lowers_the_scale_as_its_duration_grows() -> None:
    # 1 + 0 over 1 + T look-backs: the KITTI prior weighs one second
    assert math.isclose(_scale_after(np.zeros(101)), 1.0 / 11.0)
    assert math.isclose(_scale_after(np.zeros(201)), 1.0 / 21.0)
    assert _scale_after(np.zeros(1)) == 1.0  # the first frame's θ spans no interval


def test_kitti_roughness_keeps_the_scale_and_a_rough_road_raises_it() -> None:
    rng = np.random.default_rng(0)
    kitti_like = rng.normal(0.0, KITTI_THETA_RMS_RAD, 3000)
    assert abs(_scale_after(kitti_like) - 1.0) < 0.1
    assert math.isclose(_scale_after(3.0 * kitti_like), MAX_SCALE)  # bounded
    rough = RoadRoughness()
    rough.update(0.0, 0.001)
    rough.update(10.0, 0.001)  # a gap weighs one look-back at most
    assert math.isclose(rough.scale, (1.0 + (0.001 / KITTI_THETA_RMS_RAD) ** 2) / 2.0)


def test_a_flat_road_trusts_the_ground_contact_more() -> None:
    sim = simulate_traffic(CAM, 10, 150, seed=1, box_noise_px=0.5)
    n = len(sim.timestamps_s)
    track = RotationTrack(sim.timestamps_s, np.repeat(np.eye(3)[None], n, 0), np.ones(n, bool))
    err, median_sigma = {}, {}
    for adapt in (False, True):
        est = OursEstimator(CAM, adapt_contact_trust=adapt)
        res = estimate_sequence(est, sim.boxes, sim.timestamps_s, track)
        late = sim.boxes.frame >= 100
        e = res.estimates.distance_m[late] - sim.z_m[late]
        err[adapt] = float(np.sqrt(np.mean(e * e)))
        median_sigma[adapt] = float(
            np.median(res.estimates.extra["target_gradient_sigma_rad"][late])
        )
    assert err[True] < 0.95 * err[False]
    # the tracks' gradient spread follows the lowered prior
    assert median_sigma[True] < 0.7 * median_sigma[False]
