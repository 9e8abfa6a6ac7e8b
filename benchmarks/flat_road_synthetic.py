"""``ours`` against eq. 1 on synthetic flat-road traffic with an exact calibration.

The road is flat and the camera's mount and height are the ones the estimator is given, so the
ground contact (eq. 1) is exact but for the box-bottom noise: what a method that weighs its
cues should match there. For each camera (KITTI's and five others: 1080p and 720p, heights
1.2–2.5 m, 15–30 Hz) and seed, :func:`~slopedist.synthetic.traffic.simulate_traffic` drives 10
Cars (sizes within the Car prior's spread, 0.5 px box-edge noise, 150 frames) past a camera
at rest (identity rotations). Printed per camera: the RMSE (m) of

- ``eq1``: ``f·h/(b − v) + L/2`` with ``v`` the true horizon and ``L`` the Car prior's length
  (eq. 1 at the vehicle's centre, the truth's reference);
- ``ours`` (reference ``centre``, the options given), on the same boxes (its ``ok`` rows);

their ratio, and the 1σ coverage of ``ours``' ``sigma_m`` (share of errors within 1σ, ideal
0.68).

Usage::

    python benchmarks/flat_road_synthetic.py [--seeds 3] [--ours-options '{"...": ...}']
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.estimators import CLASS_PRIORS, make_estimator
from slopedist.odometry.base import RotationTrack
from slopedist.streaming.step import estimate_sequence
from slopedist.synthetic.traffic import simulate_traffic

FloatArray = NDArray[np.float64]

CAMERAS: dict[str, tuple[Camera, float]] = {
    "kitti 1242x375 h1.65 10Hz": (Camera(721.5, 609.6, 172.9, 1.65, 0.0), 0.1),
    "1080p h1.2 30Hz": (Camera(1400.0, 960.0, 540.0, 1.2, 0.0), 1 / 30),
    "1080p h2.5 15Hz": (Camera(1000.0, 960.0, 540.0, 2.5, 0.02), 1 / 15),
    "720p h1.4 30Hz": (Camera(900.0, 640.0, 360.0, 1.4, -0.01), 1 / 30),
    "720p h2.0 15Hz": (Camera(700.0, 640.0, 360.0, 2.0, 0.0), 1 / 15),
    "1080p h1.6 20Hz": (Camera(1200.0, 960.0, 540.0, 1.6, 0.01), 0.05),
}
N_VEHICLES = 10
N_FRAMES = 150


def run_camera(
    camera: Camera, period_s: float, seed: int, options: dict[str, Any]
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per ok row of ``ours``: its error, its σ and eq. 1's error (m)."""
    sim = simulate_traffic(
        camera, N_VEHICLES, N_FRAMES, seed=seed, box_noise_px=0.5, frame_period_s=period_s
    )
    n = len(sim.timestamps_s)
    track = RotationTrack(sim.timestamps_s, np.repeat(np.eye(3)[None], n, 0), np.ones(n, bool))
    est = make_estimator("ours", camera, **{"reference": "centre", **options})
    result = estimate_sequence(
        est, sim.boxes, sim.timestamps_s, track, vehicle_classes=set(sim.boxes.cls)
    )
    out = result.estimates
    z = np.asarray(sim.z_m, dtype=float)  # the estimates are in the boxes' order
    bottom = np.asarray(sim.boxes.boxes, dtype=float)[:, 3]
    v = camera.c_y + camera.f * np.tan(camera.mount_angle_rad)
    with np.errstate(divide="ignore", invalid="ignore"):
        eq1 = camera.f * camera.height_m / (bottom - v) + 0.5 * CLASS_PRIORS["Car"].length_m
    ok = (np.asarray(out.status, dtype=object) == "ok") & np.isfinite(eq1) & (bottom > v)
    d = np.asarray(out.distance_m, dtype=float)
    sigma = np.asarray(out.extra["sigma_m"], dtype=float)
    return (d - z)[ok], sigma[ok], (eq1 - z)[ok]


def rmse(x: FloatArray) -> float:
    return float(np.sqrt(np.mean(x * x))) if x.size else float("nan")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--ours-options", type=json.loads, default={})
    args = parser.parse_args(argv)
    print(f"{'camera':28s} {'n':>6s} {'eq1':>6s} {'ours':>6s} {'ratio':>6s} {'≤1σ':>5s}")
    worst = 0.0
    for name, (camera, period) in CAMERAS.items():
        parts = [run_camera(camera, period, s, args.ours_options) for s in range(args.seeds)]
        err, sigma, eq1 = (np.concatenate([p[i] for p in parts]) for i in range(3))
        ratio = rmse(err) / rmse(eq1)
        worst = max(worst, ratio)
        cover = float(np.mean(np.abs(err) <= sigma))
        print(
            f"{name:28s} {err.size:6d} {rmse(eq1):6.2f} {rmse(err):6.2f} {ratio:6.2f} {cover:5.2f}"
        )
    print(f"worst ratio ours / eq1: {worst:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
