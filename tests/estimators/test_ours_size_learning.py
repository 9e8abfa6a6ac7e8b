"""Per-track size learning of ``ours`` (:mod:`slopedist.estimators.ours.size_learning`)."""

from __future__ import annotations

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.estimators import make_estimator
from slopedist.estimators.base import FrameInput
from slopedist.estimators.ours import OursAblation, OursConfig
from slopedist.estimators.ours.class_table import ClassTable
from slopedist.estimators.ours.config import size_evidence_time
from slopedist.estimators.ours.fusion import LogCue
from slopedist.estimators.ours.priors import CLASS_PRIORS, yaw_grid
from slopedist.estimators.ours.size_learning import (
    TrackSize,
    evidence_weight,
    learn,
    scale_hypotheses,
    track_size,
)
from slopedist.odometry.base import RotationTrack
from slopedist.streaming.step import FrameStep, concat_estimates, estimate_sequence, stream_track
from slopedist.synthetic.traffic import SimulatedTraffic, simulate_traffic

CAM = Camera(721.5, 609.6, 172.9, 1.65, 0.0)


def _cue(mean: float, var: float, white: float) -> LogCue:
    return LogCue(np.array([mean]), np.array([var]), np.array([white]), np.zeros(1))


def test_one_frame_of_evidence_by_hand() -> None:
    """Prior b ~ N(0, 0.01); the ground contact 0.2 farther than the size cue with variance
    0.008 + 0.002 (size white) at full weight: b = 0.1, variance 0.005."""
    size = TrackSize(np.zeros(1), np.full(1, 0.01), np.full(1, 0.01))
    ground = _cue(np.log(20.0) + 0.2, 0.008, 0.001)
    cue = _cue(np.log(20.0), 0.02, 0.002)
    rows = learn(size, cue, ground, np.ones(1), np.ones(1, bool))
    assert rows[:, 0] == pytest.approx([0.1, 0.005])
    half = learn(size, cue, ground, np.full(1, 0.5), np.ones(1, bool))  # tempered evidence
    assert half[1, 0] == pytest.approx(1 / (100 + 50))
    unusable = learn(size, cue, ground, np.ones(1), np.zeros(1, bool))
    assert unusable[:, 0].tolist() == [0.0, 0.01]
    # a box a nearer box may cut: "bigger" counts, "smaller" does not
    hidden = np.ones(1, bool)
    assert learn(size, cue, ground, np.ones(1), np.ones(1, bool), hidden)[0, 0] == pytest.approx(
        0.1
    )
    smaller = _cue(np.log(20.0) - 0.2, 0.008, 0.001)
    assert learn(size, cue, smaller, np.ones(1), np.ones(1, bool), hidden)[0, 0] == 0.0


def test_stored_beliefs_and_weights() -> None:
    stored = np.array([[0.3, 0.0], [0.002, np.nan]])  # the second track never learned
    size = track_size(stored, np.array([True, False, True]), np.full(3, 0.1))
    assert size.log_scale.tolist() == [0.3, 0.0, 0.0]
    assert size.log_var == pytest.approx([0.002, 0.01, 0.01])
    assert size.spread_ratio == pytest.approx([np.sqrt(0.2), 1.0, 1.0])
    w = evidence_weight(np.array([0.1, 8.0]), np.array([True, False, True]), 4.0)
    assert w.tolist() == [0.025, 0.0, 1.0]
    assert size_evidence_time(OursConfig(), OursAblation()) == pytest.approx(4.0)  # (1°/0.5°/√s)²


def test_hypotheses_scale_with_the_learned_size() -> None:
    hyp = ClassTable(None, yaw_grid()).gather(np.array(["Car"], dtype=object)).hypotheses
    size = TrackSize(np.log([1.25]), np.array([0.0025]), np.array([0.01]))
    out = scale_hypotheses(hyp, size)
    assert out.height_m == pytest.approx(1.25 * hyp.height_m)
    assert out.half_width_sin_m == pytest.approx(1.25 * hyp.half_width_sin_m)
    assert out.half_extent_m == pytest.approx(1.25 * hyp.half_extent_m)
    assert out.log_sigma_height == pytest.approx(0.5 * hyp.log_sigma_height)
    assert out.half_extent_sigma_m == pytest.approx(0.625 * hyp.half_extent_sigma_m)
    assert (out.corr_height_width == hyp.corr_height_width).all()


def _run(sim: SimulatedTraffic, method: str, **options: object) -> tuple[np.ndarray, dict]:
    """Distances (and the last frame's extras) of ``method`` over ``sim`` (true rotations)."""
    est = make_estimator(method, CAM, **options)
    out = np.full(len(sim.boxes), np.nan)
    frames, extra = [], {}
    for k, t in enumerate(sim.timestamps_s):
        rows = np.flatnonzero(sim.boxes.frame == k)
        if rows.size:
            e = est.estimate(
                FrameInput(k, float(t), 0.0, sim.boxes.select(rows), None, None, np.eye(3))
            )
            out[rows] = e.distance_m
            frames.append(rows)
            extra = e.extra
    if est.offline:
        for rows, e in zip(frames, est.finish(), strict=True):
            out[rows] = e.distance_m
    return out, extra


def _van_called_car(z_range: tuple[float, float], speed: tuple[float, float]) -> SimulatedTraffic:
    sim = simulate_traffic(
        CAM,
        1,
        150,
        seed=3,
        vehicle_types={"Van": 1.0},
        z_range_m=z_range,
        speed_range_mps=speed,
        lateral_m=1.5,
        box_noise_px=0.3,
        size_spread=0.0,
    )
    assert set(sim.boxes.cls) == {"Car"} and sim.types.tolist() == ["Van"]
    return sim


def test_a_van_called_car_seen_near_carries_its_size_far() -> None:
    """A van that a class-blind detector calls ``Car`` drives away from 9 m to ~60 m: near,
    its ground contact shows it is bigger than a car; its learned size then keeps it nearer
    right far away, where the ground contact cannot."""
    sim = _van_called_car((9.0, 9.5), (3.5, 3.6))
    plain, _ = _run(sim, "ours")
    learned, extra = _run(sim, "ours", size_learning=True)
    true_scale = sim.dims_hwl[0, 0] / CLASS_PRIORS["Car"].height_m
    # slowly: a frame's evidence weighs dt/4 s (the target road's gradient error persists)
    assert 1.05 < extra["size_scale"][0] < true_scale
    assert extra["size_log_sigma"][0] < 0.8 * CLASS_PRIORS["Car"].height_sigma_m / 1.53
    assert extra["track_height_m"][0] == pytest.approx(1.53 * extra["size_scale"][0], rel=0.01)
    far = sim.z_m > 30
    err = {
        k: np.sqrt(np.mean((d[far] - sim.z_m[far]) ** 2))
        for k, d in (("plain", plain), ("learned", learned))
    }
    assert err["learned"] < 0.7 * err["plain"]  # 5.97 against 9.54 m


def test_offline_carries_the_size_learned_near_back_to_the_far_frames() -> None:
    """The same van approaching from ~60 m: causally its size is learned only at the end;
    ``ours-offline`` uses it on every frame of the track."""
    sim = _van_called_car((60.0, 61.0), (-3.6, -3.5))
    causal, _ = _run(sim, "ours", size_learning=True)
    offline, _ = _run(sim, "ours-offline")
    rmse = {
        k: np.sqrt(np.mean((d - sim.z_m) ** 2))
        for k, d in (("causal", causal), ("offline", offline))
    }
    assert rmse["offline"] < 0.7 * rmse["causal"]  # 4.65 against 7.41 m


def test_off_by_default_and_streaming_equals_batch() -> None:
    sim = simulate_traffic(
        CAM, 6, 60, seed=1, box_noise_px=0.5, vehicle_types={"Car": 0.6, "Van": 0.4}
    )
    default, extra = _run(sim, "ours")
    assert np.isnan(extra["size_scale"]).all()
    assert np.array_equal(default, _run(sim, "ours", size_learning=False)[0])
    n = sim.timestamps_s.size
    track = RotationTrack(sim.timestamps_s, np.repeat(np.eye(3)[None], n, 0), np.ones(n, bool))
    batch = estimate_sequence(
        make_estimator("ours", CAM, size_learning=True), sim.boxes, sim.timestamps_s, track
    )
    step = FrameStep(make_estimator("ours", CAM, size_learning=True))
    streamed = concat_estimates([r.estimates for _, _, r in stream_track(step, track, sim.boxes)])
    np.testing.assert_array_equal(streamed.distance_m, batch.estimates.distance_m)
    np.testing.assert_array_equal(streamed.extra["size_scale"], batch.estimates.extra["size_scale"])
    assert not np.array_equal(batch.estimates.distance_m, default)
