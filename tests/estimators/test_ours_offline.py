"""``ours-offline``: the Rauch–Tung–Striebel smoother and the pass over the whole drive."""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.estimators import (
    causal_methods,
    make_estimator,
    offline_method,
    with_offline,
)
from slopedist.estimators.ours import filter as kf
from slopedist.io.detections.boxes import BoxTable
from slopedist.odometry.base import RotationTrack
from slopedist.streaming.step import FrameStep, estimate_sequence
from slopedist.synthetic.traffic import simulate_traffic

CAM = Camera(721.5, 609.6, 172.9, 1.65, 0.0)


def _filtered_track(seed: int = 0, n: int = 80, noise: float = 0.05):
    """An approach at −5 m/s from 40 m measured in log distance with white noise: the
    filter's updated and predicted rows, the time steps and the true log distances."""
    rng = np.random.default_rng(seed)
    dt = 0.1
    z = 40.0 - 5.0 * dt * np.arange(n)
    s = np.array([[math.log(z[0]) + rng.normal(0, noise)], [0.0], [noise**2], [0.0], [0.25]])
    upd, pred = [s[:, 0].copy()], [np.full(5, np.nan)]
    for k in range(1, n):
        p = kf.cv_predict_rows(s, np.array([dt]), 2.0)
        s, _ = kf.cv_update_rows(
            p, np.array([math.log(z[k]) + rng.normal(0, noise)]), np.array([noise**2])
        )
        pred.append(p[:, 0])
        upd.append(s[:, 0].copy())
    return np.array(upd).T, np.array(pred).T, np.full(n, dt), np.log(z)


def test_the_smoother_uses_the_future() -> None:
    errs = {"filtered": [], "smoothed": []}
    for seed in range(5):
        upd, pred, dt, truth = _filtered_track(seed)
        smooth = kf.rts_smooth_rows(upd, pred, dt)
        assert smooth[:, -1] == pytest.approx(upd[:, -1])  # the last state has no future
        assert (smooth[2] <= upd[2] + 1e-12).all()  # more data, less variance
        errs["filtered"].append(upd[0] - truth)
        errs["smoothed"].append(smooth[0] - truth)
    rmse = {k: float(np.sqrt(np.mean(np.concatenate(v) ** 2))) for k, v in errs.items()}
    assert rmse["smoothed"] < 0.7 * rmse["filtered"]
    # the smoothed rate is the true relative rate Ż/Z = −5/Z, within a few σ
    upd, pred, dt, truth = _filtered_track(0)
    smooth = kf.rts_smooth_rows(upd, pred, dt)
    rate = -5.0 / np.exp(truth)
    assert np.abs(smooth[1, 10:-10] - rate[10:-10]).max() < 4 * np.sqrt(smooth[4, 10:-10]).max()


def test_offline_names() -> None:
    assert offline_method("ours") == "ours-offline" == offline_method("ours-offline")
    with pytest.raises(ConfigurationError, match="no offline mode"):
        offline_method("paper")
    assert with_offline(["flat", "ours", "paper"]) == ["flat", "ours", "ours-offline", "paper"]
    assert with_offline(["ours", "ours-offline"]) == ["ours", "ours-offline"]
    assert "ours-offline" not in causal_methods() and "ours" in causal_methods()


def _drive():
    sim = simulate_traffic(
        CAM, 6, 120, seed=2, box_noise_px=0.5, vehicle_types={"Car": 0.6, "Van": 0.4}
    )
    n = sim.timestamps_s.size
    track = RotationTrack(sim.timestamps_s, np.repeat(np.eye(3)[None], n, 0), np.ones(n, bool))
    return sim, track


def test_offline_is_reported_apart_and_leaves_ours_alone() -> None:
    sim, track = _drive()
    ours = estimate_sequence(make_estimator("ours", CAM), sim.boxes, sim.timestamps_s, track)
    off = estimate_sequence(make_estimator("ours-offline", CAM), sim.boxes, sim.timestamps_s, track)
    again = estimate_sequence(make_estimator("ours", CAM), sim.boxes, sim.timestamps_s, track)
    np.testing.assert_array_equal(ours.estimates.distance_m, again.estimates.distance_m)
    assert off.method == "ours-offline" and ours.method == "ours"
    np.testing.assert_array_equal(off.boxes.boxes, ours.boxes.boxes)
    d = off.estimates.distance_m
    assert np.isfinite(d).all() and not np.array_equal(d, ours.estimates.distance_m)
    ex = off.estimates.extra
    np.testing.assert_allclose(ex["distance_centre_m"], d)
    assert (ex["distance_nearest_face_m"] < d).all() and (ex["sigma_m"] > 0).all()
    assert np.isfinite(ex["size_scale"]).all()
    truth = sim.z_m[np.argsort(sim.boxes.frame, kind="stable")]
    rmse = {
        k: float(np.sqrt(np.mean((e.estimates.distance_m - truth) ** 2)))
        for k, e in (("ours", ours), ("offline", off))
    }
    assert rmse["offline"] < rmse["ours"]


def test_a_causal_method_has_no_offline_pass() -> None:
    step = FrameStep(make_estimator("ours", CAM))
    with pytest.raises(NotImplementedError, match="causal"):
        step.finish()


def test_the_offline_pass_does_not_hold_the_drives_images() -> None:
    """``ours-offline`` keeps every frame for its second pass: the boxes, times and rotations,
    not the pixels (``run --offline`` hands it every image: 1.4 MB a KITTI frame, 28 GB over
    a 20 000-frame drive)."""
    step = FrameStep(make_estimator("ours-offline", CAM))
    tracemalloc.start()
    try:
        for k in range(40):
            image = np.full((375, 1242, 3), k, np.uint8)
            boxes = BoxTable.build([k], [[600.0, 150.0, 700.0, 220.0]], [1])
            step.step(k, 0.1 * k, np.eye(3), boxes, image)
        held, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert held < 10e6  # 56 MB when the images were kept
    assert len(step.finish()) == 40


def test_the_offline_pass_keeps_little_per_frame() -> None:
    """Memory grows with the drive (the second pass needs every frame), but by little: of the
    causal pass only the three columns the second pass reads, and the smoothed estimates
    replace the second pass's frame by frame (1000 frames of 6 vehicles: 8.0 MB after pass 1
    and 24.9 MB at the peak of the end when the whole estimates were kept and copied)."""
    sim = simulate_traffic(
        CAM, 6, 1000, seed=1, speed_range_mps=(-0.01, 0.01), z_range_m=(10.0, 60.0)
    )
    assert len(sim.boxes) == 6000
    by_frame = sim.boxes.frame_lookup()
    step = FrameStep(make_estimator("ours-offline", CAM))
    tracemalloc.start()
    try:
        for k, t in enumerate(sim.timestamps_s):
            step.step(k, float(t), np.eye(3), by_frame.get(k))
        after_pass_1, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        offline = step.finish()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert after_pass_1 < 4e6 and peak < 18e6
    assert len(offline) == 1000 and all(e.status.tolist() == ["ok"] * 6 for e in offline)
