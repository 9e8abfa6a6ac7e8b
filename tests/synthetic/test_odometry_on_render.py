"""The built-in visual odometry on rendered frames recovers the true rotations (the demo's
premise: the renderer's texture is trackable and its geometry consistent).

Measured over the look-back (1 s), as the methods use it: the error of θ (eq. 4) and the
angle of the error of the whole relative rotation."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from slopedist.core import geometry as geo
from slopedist.odometry.base import lookback_indices
from slopedist.synthetic.scenarios import load_scenario
from slopedist.synthetic.sequence import SyntheticSequence

visual = pytest.importorskip(
    "slopedist.odometry.visual", reason="the built-in visual odometry is not in this build"
)

LIMIT_DEG = 0.05
RUNS = {"ego_sag": 80, "bumps_and_curves": 40}
_cache: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def _errors(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(θ error, relative-rotation error, true rotation over the look-back), degrees."""
    if name in _cache:
        return _cache[name]
    seq = SyntheticSequence(load_scenario(name))
    vo = visual.BuiltinVisualOdometry(seq.camera)
    frames = range(RUNS[name])
    R_est = []
    for k in frames:
        f = seq.frame(k)
        res = vo.process(
            cv2.cvtColor(f.image, cv2.COLOR_BGR2GRAY), f.timestamp_s, f.detections.boxes
        )
        assert res.R_world_cam is not None, f"odometry lost at frame {k}"
        R_est.append(res.R_world_cam)
    R = np.asarray(R_est)
    R_true = seq.truth.poses_cam0()[list(frames), :, :3]
    lb = lookback_indices(seq.truth.timestamps_s[list(frames)])
    rel_true = np.swapaxes(R_true[lb], 1, 2) @ R_true
    rel_est = np.swapaxes(R[lb], 1, 2) @ R
    rel_err = np.degrees(geo.rotation_angle_rad(np.swapaxes(rel_true, 1, 2) @ rel_est))
    theta_err = np.degrees(
        geo.ego_road_gradient(R[lb], R) - geo.ego_road_gradient(R_true[lb], R_true)
    )
    _cache[name] = (theta_err, rel_err, np.degrees(geo.rotation_angle_rad(rel_true)))
    return _cache[name]


@pytest.mark.parametrize("name", list(RUNS))
def test_ego_gradient_within_005_deg(name: str) -> None:
    theta_err, _, true_change = _errors(name)
    assert true_change.max() > 0.5, "the stretch must contain real rotation"
    assert np.sqrt(np.mean(theta_err**2)) <= LIMIT_DEG


@pytest.mark.parametrize("name", list(RUNS))
def test_rotation_over_the_lookback_within_005_deg(name: str) -> None:
    _, rel_err, _ = _errors(name)
    assert np.median(rel_err) <= LIMIT_DEG
