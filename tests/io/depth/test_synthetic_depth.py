"""Depth files from the synthetic renderer: true depth plus noise, through files, into the
depth-map baseline, against the scenario's exact truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slopedist.estimators import DepthMapEstimator, FrameInput
from slopedist.io.depth import FileDepthSource, write_kitti_depth_png

synthetic = pytest.importorskip(
    "slopedist.synthetic.sequence",
    reason="the synthetic renderer (slopedist.synthetic) is not in this build",
)
scenarios = pytest.importorskip("slopedist.synthetic.scenarios")

FRAMES = (0, 50)


def _noisy(depth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """5 % multiplicative noise and 10 % of the pixels dropped (no value)."""
    out = depth * rng.normal(1.0, 0.05, depth.shape)
    out[rng.random(depth.shape) < 0.1] = np.nan
    return out


@pytest.mark.parametrize("name", ["target_steep_uphill", "same_flat"])
def test_noisy_true_depth_files_give_the_rear_face_distance(tmp_path: Path, name: str) -> None:
    seq = synthetic.SyntheticSequence(scenarios.load_scenario(name))
    rng = np.random.default_rng(7)
    frames = {k: seq.frame(k) for k in FRAMES}
    (tmp_path / "npy").mkdir()
    for k, f in frames.items():
        noisy = _noisy(f.depth_m.astype(float), rng)
        write_kitti_depth_png(tmp_path / "png" / f"{k:010d}.png", noisy)
        np.save(tmp_path / "npy" / f"{k:06d}.npy", noisy.astype(np.float32))
    w, h = seq.image_size
    camera = seq.camera.with_image_size(w, h)
    for folder in ("png", "npy"):
        source = FileDepthSource(tmp_path / folder, expected_shape=(h, w))
        est = DepthMapEstimator(camera, sample="window", window_px=9)
        for k, f in frames.items():
            out = est.estimate(FrameInput(k, f.timestamp_s, 0.0, f.exact, depth_m=source.depth(k)))
            rear = seq.truth.z_rear_m[k][seq.truth.in_view[k]]
            assert len(rear) == len(out.distance_m) > 0
            # the box-centre pixel sees the rear face: its depth, not the label's centre z
            np.testing.assert_allclose(out.distance_m, rear, rtol=0.03)
            assert np.all(out.distance_m < f.exact.extra["z"])


def test_scale_less_synthetic_depth_is_recovered_by_contact_scaling() -> None:
    seq = synthetic.SyntheticSequence(scenarios.load_scenario("same_flat"))
    w, h = seq.image_size
    est = DepthMapEstimator(seq.camera.with_image_size(w, h), scaling="contact")
    for k in FRAMES:
        f = seq.frame(k)
        out = est.estimate(FrameInput(k, f.timestamp_s, 0.0, f.exact, depth_m=0.02 * f.depth_m))
        rear = seq.truth.z_rear_m[k][seq.truth.in_view[k]]
        np.testing.assert_allclose(out.distance_m, rear, rtol=0.05)
