"""Self-calibration of ``ours`` against a known mis-calibration."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.estimators import make_estimator
from slopedist.estimators.ours import OursEstimator, SelfCalConfig, SelfCalibrator
from slopedist.odometry.base import RotationTrack
from slopedist.streaming.step import estimate_sequence
from slopedist.synthetic.traffic import simulate_traffic

TRUE = Camera(721.5, 609.6, 172.9, 1.65, 0.0)
WRONG = TRUE.with_mount(height_m=1.65 * 1.1, mount_angle_rad=math.radians(1.0))


def _at_rest(t: np.ndarray) -> RotationTrack:
    return RotationTrack.from_arrays(t, np.broadcast_to(np.eye(3), (len(t), 3, 3)))


def test_selfcalibrator_recovers_mount_and_height_from_direct_observations() -> None:
    """Rows of box bottoms generated with h = 1.5 m and θ0 = −0.8°, size errors per vehicle."""
    rng = np.random.default_rng(4)
    f, c_y = 721.5, 172.9
    h_true, th0_true = 1.5, math.radians(-0.8)
    cal = SelfCalibrator(f, mount_angle_rad=0.0, height_m=1.65)
    theta_cfg = 0.0  # camera at rest with the configured θ0 = 0
    v_cfg = c_y - f * math.tan(theta_cfg)
    v_true = c_y + f * math.tan(th0_true)
    for frame in range(150):
        keys = np.arange(frame // 15 * 6, frame // 15 * 6 + 6)  # six vehicles per 1.5 s
        near_true = 6.0 + (keys * 7.3) % 45.0 + 0.1 * (frame % 15)
        size_err = np.exp(0.08 * np.sin(keys * 12.9898) * 1.7)  # constant per vehicle
        bottom = v_true + f * h_true / near_true + rng.normal(0, 1.0, keys.size)
        cal.update(
            keys,
            bottom,
            np.full(keys.size, v_cfg),
            np.full(keys.size, theta_cfg),
            near_true * size_err,
        )
    c = cal.calibration()
    assert c.mount_angle_rad == pytest.approx(th0_true, abs=math.radians(0.25))
    assert c.height_m == pytest.approx(h_true, rel=0.06)
    assert c.mount_angle_sigma_rad < math.radians(0.5)
    assert c.height_sigma_m < 0.1
    assert c.n_tracks == 60 and c.n_observations == 900


def test_selfcalibrator_ignores_unusable_targets_and_rejects_bad_config() -> None:
    cal = SelfCalibrator(721.5, 0.0, 1.65)
    before = cal.calibration()
    cal.update(
        np.array([1, 2]),
        np.array([np.nan, 300.0]),
        np.array([172.9, 172.9]),
        np.zeros(2),
        np.array([10.0, 0.5]),
    )  # NaN row; 0.5 m is closer than min_near
    assert cal.calibration() == replace(before, n_frames=1)  # a frame seen, nothing used
    with pytest.raises(ConfigurationError):
        SelfCalConfig(height_sigma_m=0.0)


def test_ours_selfcal_recovers_a_wrong_calibration_on_simulated_traffic() -> None:
    sim = simulate_traffic(TRUE, 12, 200, seed=0)
    track = _at_rest(sim.timestamps_s)
    est = make_estimator("ours-selfcal", WRONG)
    res = estimate_sequence(est, sim.boxes, sim.timestamps_s, track)
    c = est.calibration()  # type: ignore[attr-defined]
    assert c.mount_angle_rad == pytest.approx(0.0, abs=math.radians(0.3))
    assert c.height_m == pytest.approx(1.65, rel=0.05)
    assert c.mount_angle_sigma_rad < math.radians(0.6)
    # the records carry the running estimate; it converges towards the truth
    h_col = res.estimates.extra["calib_height_m"]
    assert abs(h_col[-1] - 1.65) < abs(h_col[0] - 1.65)
    assert np.all(np.isfinite(res.estimates.extra["calib_mount_angle_sigma_rad"]))


def test_selfcal_brings_accuracy_back_under_a_wrong_calibration() -> None:
    errs: dict[str, list[float]] = {"right": [], "wrong": [], "wrong+selfcal": []}
    for seed in range(3):
        sim = simulate_traffic(TRUE, 10, 150, seed=seed, size_spread=0.5)
        track = _at_rest(sim.timestamps_s)
        for key, cam, opts in (
            ("right", TRUE, {}),
            ("wrong", WRONG, {}),
            ("wrong+selfcal", WRONG, {"self_calibrate": True}),
        ):
            r = estimate_sequence(OursEstimator(cam, **opts), sim.boxes, sim.timestamps_s, track)
            errs[key] += list(r.estimates.distance_m - sim.z_m)
    # (a car beside the ego lies wholly left of any image the camera fits: outside_image, NaN)
    rmse = {k: float(np.sqrt(np.nanmean(np.square(v)))) for k, v in errs.items()}
    assert rmse["wrong"] > 1.05 * rmse["right"]
    assert rmse["wrong+selfcal"] < rmse["wrong"]
    assert rmse["wrong+selfcal"] < 1.1 * rmse["right"]


def _feed(cal: SelfCalibrator, size_bias: dict[int, float], shape_gap: float = 0.0) -> None:
    """Targets of a camera 1.65 m high at θ0 = 0 at rest; vehicle ``k``'s size cue is off by
    the factor ``size_bias.get(k, 1)`` (a vehicle larger than its class prior)."""
    f, c_y = 721.5, 172.9
    keys = np.arange(12)
    for frame in range(40):
        near = 8.0 + 2.5 * keys + 0.05 * frame
        bias = np.array([size_bias.get(int(k), 1.0) for k in keys])
        cal.update(
            keys,
            c_y + f * 1.65 / near,
            np.full(keys.size, c_y),
            np.zeros(keys.size),
            near * bias,
            np.full(keys.size, shape_gap),
        )


def test_the_vehicle_jackknife_grows_when_one_vehicle_disagrees() -> None:
    """Leave-one-vehicle-out: vehicles that agree give a jackknife σ of h near zero (noise-free
    rows); one vehicle 40 % larger than its class moves the estimate and the jackknife sees it,
    far beyond the model's own σ of that difference."""
    agree = SelfCalibrator(721.5, 0.0, 1.65)
    _feed(agree, {})
    assert math.sqrt(agree.track_jackknife()[1, 1]) < 1e-3
    odd = SelfCalibrator(721.5, 0.0, 1.65)
    _feed(odd, {5: 0.6})
    shift = abs(odd.calibration().height_m - agree.calibration().height_m)
    jack_h = math.sqrt(odd.track_jackknife()[1, 1])
    assert shift > 0.005 and jack_h > 0.5 * shift
    assert SelfCalibrator(721.5, 0.0, 1.65).track_jackknife().tolist() == [[0, 0], [0, 0]]


def test_targets_of_a_shape_unlike_their_class_are_counted_and_left_out() -> None:
    cal = SelfCalibrator(721.5, 0.0, 1.65)
    _feed(cal, {}, shape_gap=3.5)  # beyond the 3σ gate: nothing used
    c = cal.calibration()
    assert (c.n_observations, c.n_shape_checked, c.n_shape_outliers) == (0, 480, 480)
    assert c.shape_outlier_share == 1.0 and c.height_m == 1.65
    cal = SelfCalibrator(721.5, 0.0, 1.65)
    _feed(cal, {}, shape_gap=1.0)
    c = cal.calibration()
    assert (c.n_observations, c.n_shape_outliers, c.shape_outlier_share) == (480, 0, 0.0)
    assert math.isnan(SelfCalibrator(721.5, 0.0, 1.65).calibration().shape_outlier_share)


def test_selfcal_on_simulated_traffic_finds_every_box_shape_fits_its_class() -> None:
    sim = simulate_traffic(TRUE, 10, 150, seed=3)
    est = OursEstimator(TRUE, self_calibrate=True)
    estimate_sequence(est, sim.boxes, sim.timestamps_s, _at_rest(sim.timestamps_s))
    c = est.calibration()
    assert c.n_shape_checked > 500 and c.shape_outlier_share < 0.01


def test_selfcal_does_not_learn_from_a_frame_without_a_trusted_rotation() -> None:
    """An odometry jump (and any frame without θ) leaves ``ours`` at its resting θ with a wide
    jitter; the self-calibration took that θ as measured and learned the mount from the frame."""
    from scipy.spatial.transform import Rotation

    sim = simulate_traffic(TRUE, 6, 60, seed=1)
    clean = _at_rest(sim.timestamps_s)
    glitch = clean.R_world_cam.copy()
    jumps = (20, 40)
    glitch[list(jumps)] = Rotation.from_euler("x", 5, degrees=True).as_matrix()
    glitched = RotationTrack.from_arrays(sim.timestamps_s, glitch)
    counts = []
    for track in (clean, glitched):
        est = make_estimator("ours-selfcal", TRUE)
        estimate_sequence(est, sim.boxes, sim.timestamps_s, track)
        counts.append(est.calibration().n_observations)  # type: ignore[attr-defined]
    on_jump_frames = int(np.count_nonzero(np.isin(sim.boxes.frame, jumps)))
    assert counts[0] - on_jump_frames <= counts[1] < counts[0]
