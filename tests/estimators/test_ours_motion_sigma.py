"""``ours``' speed σ follows the frame-to-frame noise a track shows, not only the one assumed.

Synthetic traffic (known relative speeds) with box-edge noise of 2 px, four times what the
filter assumes: the speed's σ was far too small (23 % of the errors within 1σ, RMS error/σ
4.6); with the track's measured noise scale it covers them. The distances do not change.
"""

from __future__ import annotations

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.estimators import make_estimator
from slopedist.estimators.base import FrameInput
from slopedist.synthetic.traffic import simulate_traffic

CAM = Camera(721.5, 609.6, 172.9, 1.65, 0.0)


def _run(
    box_noise_px: float, method: str = "ours", **options: object
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distances, speed errors and speed σ over two seeds (``ours-offline``: its smoothed ones)."""
    dist, err, sd = [], [], []
    for seed in range(2):
        sim = simulate_traffic(CAM, 10, 150, seed=seed, box_noise_px=box_noise_px)
        est = make_estimator(method, CAM, **options)
        frames, results = [], []
        for k, t in enumerate(sim.timestamps_s):
            rows = np.flatnonzero(sim.boxes.frame == k)
            if rows.size:
                frame = FrameInput(k, float(t), 0.0, sim.boxes.select(rows), R_world_cam=np.eye(3))
                frames.append(rows)
                results.append(est.estimate(frame))
        if est.offline:
            results = est.finish()
        for rows, r in zip(frames, results, strict=True):
            dist.append(r.distance_m)
            err.append(r.extra["speed_mps"] - sim.speed_mps[rows])
            sd.append(r.extra["speed_sigma_mps"])
    return np.concatenate(dist), np.concatenate(err), np.concatenate(sd)


def test_the_speed_sigma_covers_the_errors_of_boxes_noisier_than_assumed() -> None:
    d_nominal, e_nominal, s_nominal = _run(2.0, noise_time_s=None)
    d, e, s = _run(2.0)
    np.testing.assert_array_equal(d, d_nominal)  # the filter itself is unchanged
    np.testing.assert_array_equal(e[np.isfinite(e)], e_nominal[np.isfinite(e_nominal)])
    ok = np.isfinite(e) & np.isfinite(s)
    z_nominal, z = np.abs(e[ok]) / s_nominal[ok], np.abs(e[ok]) / s[ok]
    assert (z_nominal < 1).mean() < 0.35 and np.sqrt(np.mean(z_nominal**2)) > 3
    assert (z < 1).mean() > 0.7 and np.sqrt(np.mean(z**2)) < 1.6
    assert (s >= s_nominal)[ok].all()  # only ever wider


def test_the_offline_speed_sigma_follows_the_track_noise_too() -> None:
    """``ours-offline`` replaces the speed and its σ by the smoothed ones: those σ are widened
    by the same noise scale (they were the nominal ones, 28 % of the errors within 1σ)."""
    d_nominal, _, s_nominal = _run(2.0, "ours-offline", noise_time_s=None)
    d, e, s = _run(2.0, "ours-offline")
    np.testing.assert_array_equal(d, d_nominal)
    ok = np.isfinite(e) & np.isfinite(s)
    assert (np.abs(e[ok]) / s_nominal[ok] < 1).mean() < 0.35
    assert (np.abs(e[ok]) / s[ok] < 1).mean() > 0.7
    assert (s >= s_nominal)[ok].all()


def test_the_noise_time_is_checked() -> None:
    for bad in (0.0, -1.0, float("inf")):
        with pytest.raises(ConfigurationError, match="noise_time_s"):
            make_estimator("ours", CAM, noise_time_s=bad)
