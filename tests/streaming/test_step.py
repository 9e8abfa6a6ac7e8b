"""The streaming estimator equals batch use, keeps bounded history, and handles gaps."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError, DataMismatchError
from slopedist.estimators import available_methods, make_estimator
from slopedist.estimators.base import FrameEstimates, ReferencePoint
from slopedist.estimators.references import own_half_extent_m, to_reference
from slopedist.io.detections import BoxTable
from slopedist.odometry import RotationTrack
from slopedist.streaming.step import (
    EgoGradientTracker,
    FrameStep,
    close_records,
    concat_estimates,
    ego_gradients,
    estimate_sequence,
    iter_records,
    open_records,
    stream_track,
)

CAMERA = Camera(721.5, 609.6, 172.9, 1.65)


def synthetic_sequence(n: int = 60, seed: int = 0) -> tuple[RotationTrack, BoxTable]:
    rng = np.random.default_rng(seed)
    pitch = np.cumsum(rng.normal(0, 0.3, n))
    yaw = np.cumsum(rng.normal(0, 1.0, n))
    R = Rotation.from_euler("xy", np.c_[pitch, yaw], degrees=True).as_matrix()
    valid = rng.random(n) > 0.1
    track = RotationTrack.from_arrays(np.arange(n) * 0.1, R, valid)
    frames, boxes, tids = [], [], []
    for k in range(n):
        for tid in range(rng.integers(0, 4)):
            left, top = rng.uniform(100, 1000), rng.uniform(120, 200)
            w, h = rng.uniform(20, 200), rng.uniform(15, 120)
            frames.append(k)
            boxes.append([left, top, left + w, top + h])
            tids.append(tid)
    boxes_arr = np.asarray(boxes)
    boxes_arr[3] = [np.nan, 1, 2, 3]
    boxes_arr[5] = [50, 60, 40, 70]
    return track, BoxTable.build(frames, boxes_arr, tids)


def run_streaming(method: str, track: RotationTrack, boxes: BoxTable):
    step = FrameStep(make_estimator(method, CAMERA))
    parts = [result.estimates for _, _, result in stream_track(step, track, boxes)]
    if step.estimator.offline:  # its estimates come once the drive has ended
        parts = step.finish()
    return concat_estimates(parts), step


@pytest.mark.parametrize("method", ["flat", "ego", "paper"])
def test_streaming_equals_batch(method: str) -> None:
    track, boxes = synthetic_sequence()
    streamed, _ = run_streaming(method, track, boxes)
    batch = estimate_sequence(make_estimator(method, CAMERA), boxes, track.timestamps_s, track)
    np.testing.assert_array_equal(streamed.reason, batch.estimates.reason)
    np.testing.assert_allclose(
        streamed.distance_m, batch.estimates.distance_m, rtol=1e-12, equal_nan=True
    )
    np.testing.assert_allclose(
        streamed.theta_adj_rad, batch.estimates.theta_adj_rad, rtol=1e-12, equal_nan=True
    )
    assert "non_finite_box" in set(batch.estimates.reason)
    assert "inverted_box" in set(batch.estimates.reason)
    if method != "flat":
        assert "no_rotation" in set(batch.estimates.reason)


def test_every_registered_method_streams_like_batch() -> None:
    """Methods added later (tracking, self-calibration) must keep streaming == batch."""
    track, boxes = synthetic_sequence(30, seed=3)
    for method in available_methods():
        if make_estimator(method, CAMERA).needs_depth:
            continue
        streamed, _ = run_streaming(method, track, boxes)
        batch = estimate_sequence(make_estimator(method, CAMERA), boxes, track.timestamps_s, track)
        np.testing.assert_allclose(
            streamed.distance_m,
            batch.estimates.distance_m,
            rtol=1e-9,
            equal_nan=True,
            err_msg=method,
        )


def test_history_is_bounded_by_the_lookback() -> None:
    tracker = EgoGradientTracker(lookback_s=1.0)
    for k in range(10_000):
        tracker.update(k * 0.1, np.eye(3))
        assert len(tracker) <= 12


def test_gradient_tracker_matches_vectorised_gradients_with_gaps() -> None:
    track, _ = synthetic_sequence(80, seed=5)
    t = np.cumsum(np.r_[0.0, np.where(np.arange(79) % 13 == 0, 0.3, 0.1)])
    track = RotationTrack.from_arrays(t, track.R_world_cam, track.valid)
    tracker = EgoGradientTracker()
    streamed = [
        tracker.update(float(t[k]), track.R_world_cam[k] if track.valid[k] else None)
        for k in range(len(track))
    ]
    np.testing.assert_allclose(streamed, ego_gradients(track), equal_nan=True, atol=1e-12)


def test_a_nan_rotation_in_a_stream_is_no_rotation_as_in_batch() -> None:
    """A NaN rotation (FrameStep's "no rotation") was kept in the look-back: θ NaN a second
    later where batch (``valid`` False) looked past it, and the rotation a jump frame's
    estimator got when the jump came next."""
    t = 0.1 * np.arange(16)
    R = np.stack([Rotation.from_euler("X", 0.02 * k, degrees=True).as_matrix() for k in t])
    R[2] = np.nan
    R[3] = Rotation.from_euler("X", 6.0, degrees=True).as_matrix()  # a jump after the NaN
    track = RotationTrack.from_arrays(t, R, np.isfinite(R).all(axis=(1, 2)))
    tracker = EgoGradientTracker()
    streamed = []
    for k in range(len(t)):
        streamed.append(tracker.update(float(t[k]), R[k]))
        if k == 3:
            assert tracker.jump
            np.testing.assert_array_equal(tracker.trusted_rotation, R[1])
    assert np.isfinite(streamed[12])
    np.testing.assert_allclose(streamed, ego_gradients(track), equal_nan=True, atol=1e-12)


def test_timestamps_going_backwards_are_an_error() -> None:
    step = FrameStep(make_estimator("ego", CAMERA))
    empty = BoxTable.empty()
    step.step(0, 0.0, np.eye(3), empty)
    with pytest.raises(DataMismatchError, match="does not follow"):
        step.step(1, 0.0, np.eye(3), empty)


@pytest.mark.parametrize("bad", [-3.0, 0.9, math.nan])
@pytest.mark.parametrize("frame", [5, 9])
def test_batch_refuses_the_timestamps_a_stream_refuses_in_frames_without_boxes(
    bad: float, frame: int
) -> None:
    """Batch use skipped the frames without boxes, so a time going backwards (or NaN) there
    passed in batch and stopped the stream: streaming != batch."""
    t = np.arange(10) * 0.1 + 1.0
    t[frame] = bad
    box = np.array([[500.0, 180.0, 600.0, 250.0]])
    boxes = BoxTable.build(
        [0, 2, 7][: 3 if frame == 5 else 2], np.repeat(box, 3 if frame == 5 else 2, axis=0)
    )
    for track in (
        None,
        RotationTrack.from_arrays(np.arange(10) * 0.1 + 1.0, np.tile(np.eye(3), (10, 1, 1))),
    ):
        with pytest.raises(DataMismatchError, match=rf"frame {frame}: timestamp"):
            estimate_sequence(make_estimator("flat", CAMERA), boxes, t, track)
    step = FrameStep(make_estimator("flat", CAMERA))
    by_frame = boxes.frame_index()
    with pytest.raises(DataMismatchError, match=rf"frame {frame}: timestamp"):
        for k in range(10):
            step.step(k, float(t[k]), np.eye(3), by_frame.get(k))


@pytest.mark.parametrize("t", [math.nan, math.inf])
def test_a_timestamp_that_is_not_finite_is_an_error(t: float) -> None:
    """A NaN timestamp passed the order check (NaN <= t is false), twice in a row."""
    step = FrameStep(make_estimator("paper", CAMERA))
    box = BoxTable.build([0], [[500.0, 180.0, 600.0, 250.0]])
    with pytest.raises(DataMismatchError, match=r"frame 0: timestamp .* is not finite"):
        step.step(0, t, np.eye(3), box)
    with pytest.raises(DataMismatchError, match="not finite"):
        step.estimate(0, t, 0.0, np.eye(3), box)


@pytest.mark.parametrize("R", [np.eye(4), np.ones(3), [[1.0, 0.0], [0.0, 1.0]], "eye"])
def test_a_rotation_that_is_not_3x3_is_an_error(R: object) -> None:
    """It failed deep in numpy (a bare ValueError from einsum or matmul)."""
    box = BoxTable.build([0], [[500.0, 180.0, 600.0, 250.0]])
    for method in ("flat", "paper", "ours"):
        with pytest.raises(DataMismatchError, match="rotation must be a 3×3 matrix"):
            FrameStep(make_estimator(method, CAMERA)).step(0, 0.0, R, box)  # type: ignore[arg-type]
        with pytest.raises(DataMismatchError, match="rotation must be a 3×3 matrix"):
            FrameStep(make_estimator(method, CAMERA)).estimate(0, 0.0, 0.0, R, box)  # type: ignore[arg-type]


@pytest.mark.parametrize("R", [5 * np.eye(3), np.diag([1.0, 1.0, -1.0]), np.ones((3, 3))])
def test_a_matrix_that_is_not_a_rotation_is_an_error(R: np.ndarray) -> None:
    """A scaled matrix, a reflection or any 3×3 of numbers passed as the camera rotation; a
    NaN one still means "no rotation" and a rotation drifted by 1e-6 is taken."""
    box = BoxTable.build([0], [[500.0, 180.0, 600.0, 250.0]])
    with pytest.raises(DataMismatchError, match="not a rotation matrix"):
        FrameStep(make_estimator("paper", CAMERA)).step(0, 0.0, R, box)
    FrameStep(make_estimator("paper", CAMERA)).step(0, 0.0, np.full((3, 3), np.nan), box)
    FrameStep(make_estimator("paper", CAMERA)).step(0, 0.0, np.eye(3) * (1 + 1e-6), box)


def test_flat_runs_without_rotation_ego_does_not() -> None:
    boxes = BoxTable.build([0], [[500, 150, 600, 250]])
    flat = FrameStep(make_estimator("flat", CAMERA)).step(0, 0.0, None, boxes).estimates
    ego = FrameStep(make_estimator("ego", CAMERA)).step(0, 0.0, None, boxes).estimates
    assert flat.distance_m[0] == pytest.approx(721.5 * 1.65 / (250 - 172.9))
    assert ego.reason[0] == "no_rotation" and math.isnan(ego.distance_m[0])


def test_records_csv_written_frame_by_frame(tmp_path: Path) -> None:
    track, boxes = synthetic_sequence(20, seed=1)
    res = estimate_sequence(make_estimator("paper", CAMERA), boxes, track.timestamps_s, track)
    out = tmp_path / "records.csv"
    writer = open_records(out)
    writer.write_rows(iter_records(res.boxes, res.timestamps_s, res.estimates, "paper"))
    assert out.read_bytes().count(b"\n") == len(boxes) + 1  # flushed before close
    close_records(writer)
    assert b"\r" not in out.read_bytes()
    text = out.read_text().splitlines()
    assert text[0].startswith("frame,timestamp_s,track_id")
    assert any(",missing,non_finite_box" in line for line in text)


def test_empty_records_file_keeps_its_header(tmp_path: Path) -> None:
    out = tmp_path / "records.csv"
    close_records(open_records(out))
    assert out.read_text().splitlines()[0].startswith("frame,timestamp_s,track_id")


def test_frame_step_returns_the_theta_its_estimates_use() -> None:
    track, boxes = synthetic_sequence(40, seed=2)
    step = FrameStep(make_estimator("paper", CAMERA))
    thetas = []
    for frame_boxes, _, result in stream_track(step, track, boxes):
        thetas.append(result.theta_rad)
        np.testing.assert_array_equal(
            result.estimates.theta_rad, np.full(len(frame_boxes), result.theta_rad)
        )
    np.testing.assert_allclose(thetas, ego_gradients(track), equal_nan=True, atol=1e-12)


def test_frames_without_boxes_do_not_reach_the_estimator() -> None:
    class Counting(type(make_estimator("flat", CAMERA))):  # type: ignore[misc]
        calls = 0

        def estimate(self, frame):  # type: ignore[no-untyped-def]
            Counting.calls += 1
            return super().estimate(frame)

    step = FrameStep(Counting(CAMERA))
    none = step.step(0, 0.0, np.eye(3), None)
    empty = step.step(1, 0.1, np.eye(3), BoxTable.empty())
    assert len(none.estimates) == 0 and len(empty.estimates) == 0 and Counting.calls == 0
    step.step(2, 0.2, np.eye(3), BoxTable.build([2], [[500, 150, 600, 250]]))
    assert Counting.calls == 1


def test_no_look_back_across_an_odometry_segment() -> None:
    """A new segment forgets the history: its first frame looks back to itself (θ = 0 at θ0 = 0)
    and later ones only to frames of the same segment."""
    pitch = Rotation.from_euler("x", np.arange(30)[:, None] * 0.5, degrees=True).as_matrix()
    tracker = EgoGradientTracker(lookback_s=1.0)
    jump = Rotation.from_euler("x", 20, degrees=True).as_matrix()
    thetas = []
    for k in range(30):
        seg = int(k >= 15)
        R = pitch[k] @ jump if seg else pitch[k]
        thetas.append(tracker.update(k * 0.1, R, seg))
    assert thetas[15] == pytest.approx(0.0, abs=1e-12)
    # frame 20 looks back 0.5 s (to frame 15, its segment's first frame), not 1 s to frame 10
    same_segment = EgoGradientTracker(lookback_s=1.0)
    expected = [same_segment.update(k * 0.1, pitch[k] @ jump) for k in range(15, 30)]
    np.testing.assert_allclose(thetas[15:], expected, atol=1e-12)
    assert abs(thetas[14]) > 0.01 and abs(thetas[20] - thetas[14]) > 0.001


def test_a_sequence_without_boxes_keeps_the_box_columns() -> None:
    boxes = BoxTable.build([], np.zeros((0, 4)), row=np.zeros(0, np.int64))
    res = estimate_sequence(make_estimator("paper", CAMERA), boxes, np.arange(5) * 0.1, None)
    assert len(res.boxes) == 0 and res.boxes.extra["row"].shape == (0,)
    assert len(res.estimates.distance_m) == 0


def test_a_camera_pitched_far_down_at_rest_keeps_its_gradient() -> None:
    """The 30° bound is on θ beyond the camera at rest: a camera mounted 32° down (a truck's
    close-range camera) at rest has θ = −32°, a road's 0°, not an odometry glitch."""
    camera = Camera(721.5, 609.6, 172.9, 1.65, math.radians(32.0), 1242, 375)
    step = FrameStep(make_estimator("paper", camera))
    boxes = BoxTable.build([0], [[600.0, 200.0, 660.0, 250.0]])
    for k in range(12):
        result = step.step(k, 0.1 * k, np.eye(3), boxes)
    assert result.theta_rad == pytest.approx(-math.radians(32.0))


@pytest.mark.parametrize("method", ["ours", "paper"])
def test_a_rotation_that_jumps_90_degrees_is_no_rotation_not_a_car_2_m_ahead(method: str) -> None:
    """An odometry glitch (the camera pitched 90° for one frame) gave θ = 90°: the vanishing
    line at −∞ put two cars 63–67 m ahead at 2.0 m, ``ok`` with σ 0.35 m (``ours``)."""
    from slopedist.synthetic.traffic import simulate_traffic

    camera = Camera(721.5, 609.6, 172.9, 1.65, 0.0, 1242, 375)
    sim = simulate_traffic(camera, 8, 80, seed=3, box_noise_px=0.5)
    t = sim.timestamps_s
    R = np.tile(np.eye(3), (len(t), 1, 1))
    R[60] = Rotation.from_euler("x", 90, degrees=True).as_matrix()
    track = RotationTrack.from_arrays(t, R)
    batch = estimate_sequence(make_estimator(method, camera), sim.boxes, t, track).estimates
    glitch = sim.boxes.frame == 60
    assert glitch.any()
    ok = batch.status == "ok"
    assert np.all(np.abs(batch.distance_m[ok] / sim.z_m[ok] - 1) < 0.5)
    if method == "paper":  # a jump faster than a car pitches, before the 30° bound sees it
        assert set(batch.reason[glitch]) == {"odometry_jump"}
    assert np.isnan(batch.theta_rad[glitch]).all()
    step = FrameStep(make_estimator(method, camera))
    by_frame = sim.boxes.frame_index()
    results = [step.step(k, float(t[k]), R[k], by_frame.get(k)) for k in range(len(t))]
    assert math.isnan(results[60].theta_rad)
    stream = concat_estimates([r.estimates for r in results if len(r.estimates)])
    np.testing.assert_array_equal(stream.distance_m, batch.distance_m)


@pytest.mark.parametrize("lookback", [float("nan"), 0.0, -1.0, math.inf, "1", True])
def test_a_lookback_that_is_no_duration_is_a_configuration_error(lookback: object) -> None:
    """A NaN, zero or negative look-back gave θ = 0 or NaN for every frame without a word,
    in the stream and in batch alike."""
    track, boxes = synthetic_sequence(10)
    with pytest.raises(ConfigurationError, match="lookback_s must be a finite number"):
        FrameStep(make_estimator("paper", CAMERA), lookback_s=lookback)  # type: ignore[arg-type]
    with pytest.raises(ConfigurationError, match="lookback_s must be a finite number"):
        estimate_sequence(
            make_estimator("paper", CAMERA),
            boxes,
            track.timestamps_s,
            track,
            lookback_s=lookback,  # type: ignore[arg-type]
        )
    with pytest.raises(ConfigurationError, match="lookback_s must be a finite number"):
        ego_gradients(track, lookback_s=lookback)  # type: ignore[arg-type]


def test_vehicle_classes_given_as_one_text_is_a_configuration_error() -> None:
    """``vehicle_classes="Car"`` became ("C", "a", "r"): every Car was ``not_a_vehicle``."""
    with pytest.raises(ConfigurationError, match=r"vehicle_classes must be a collection.*'Car'"):
        FrameStep(make_estimator("paper", CAMERA), vehicle_classes="Car")
    track, boxes = synthetic_sequence(10)
    with pytest.raises(ConfigurationError, match="vehicle_classes"):
        estimate_sequence(
            make_estimator("paper", CAMERA), boxes, track.timestamps_s, track, vehicle_classes="Car"
        )


@pytest.mark.parametrize(
    ("timestamps", "message"),
    [
        (lambda t: t[None], "timestamps_s must be one per frame \\(N,\\), got shape \\(1, 10\\)"),
        (lambda t: ["x"] * len(t), "timestamps_s: could not convert"),
    ],
)
def test_timestamps_that_are_not_one_per_frame_are_a_data_mismatch(
    timestamps: object, message: str
) -> None:
    """A 2-D array failed with a bare TypeError deep in the loop, text with a ValueError."""
    track, boxes = synthetic_sequence(10)
    with pytest.raises(DataMismatchError, match=message):
        estimate_sequence(
            make_estimator("paper", CAMERA),
            boxes,
            timestamps(track.timestamps_s),  # type: ignore[operator]
            track,
        )


def test_a_timestamp_that_is_not_a_number_is_a_data_mismatch() -> None:
    """It failed with math.isfinite's bare TypeError."""
    step = FrameStep(make_estimator("paper", CAMERA))
    with pytest.raises(DataMismatchError, match=r"frame 0: timestamp must be a number.*'0\.0'"):
        step.step(0, "0.0", np.eye(3), None)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("rotation_times", "frame"),
    [
        (np.arange(10) * 0.1 + 0.3, 0),  # an offset of 3 frames
        (np.arange(10) * 0.05, 2),  # poses at 20 Hz for frames at 10 Hz
    ],
)
def test_rotations_of_other_times_than_their_frames_are_a_data_mismatch(
    rotation_times: np.ndarray, frame: int
) -> None:
    """They were paired by index and silently gave the θ of other frames."""
    track, boxes = synthetic_sequence(10)
    moved = RotationTrack.from_arrays(rotation_times, track.R_world_cam, track.valid)
    message = rf"frame {frame}: its rotation is of time .* but the frame is at .* half the frame"
    with pytest.raises(DataMismatchError, match=message):
        estimate_sequence(make_estimator("paper", CAMERA), boxes, track.timestamps_s, moved)


def test_rotation_times_within_half_a_frame_period_are_accepted() -> None:
    """Clocks of camera and pose source a few ms apart (jitter up to 0.049 s at 10 Hz)."""
    track, boxes = synthetic_sequence(10)
    jitter = np.array([0.0, 0.049, -0.049, 0.02, 0.0, -0.01, 0.049, 0.0, 0.03, -0.049])
    near = RotationTrack.from_arrays(track.timestamps_s + jitter, track.R_world_cam, track.valid)
    result = estimate_sequence(make_estimator("paper", CAMERA), boxes, track.timestamps_s, near)
    assert len(result.boxes) == len(boxes)


def glitched_traffic(
    glitch_frames: range | list[int], pitch_deg: float = 5.0, n_frames: int = 120
) -> tuple[Camera, object, RotationTrack]:
    """Cars on a flat road seen by a level camera whose odometry pitches by ``pitch_deg`` in
    ``glitch_frames`` (a pose-file or visual-odometry glitch; the camera did not move)."""
    from slopedist.synthetic.traffic import simulate_traffic

    camera = Camera(721.5, 609.6, 172.9, 1.65, 0.0, 1242, 375)
    sim = simulate_traffic(camera, 8, n_frames, seed=3, box_noise_px=0.5)
    R = np.tile(np.eye(3), (n_frames, 1, 1))
    R[list(glitch_frames)] = Rotation.from_euler("x", pitch_deg, degrees=True).as_matrix()
    return camera, sim, RotationTrack.from_arrays(sim.timestamps_s, R)


@pytest.mark.parametrize("method", ["paper", "ego", "ours"])
def test_a_one_frame_5_degree_pitch_glitch_gives_no_confident_wrong_distance(method: str) -> None:
    """A pose jumping 5° in pitch for one frame moved the vanishing line by f·tan 5° ≈ 63 px:
    every car of that frame came out ``ok`` at a fraction of its distance (49 m at 14 m on
    KITTI 0001), and again one look-back later, the glitch being that frame's reference."""
    camera, sim, track = glitched_traffic(range(60, 61))
    batch = estimate_sequence(make_estimator(method, camera), sim.boxes, sim.timestamps_s, track)
    est = batch.estimates
    glitch = sim.boxes.frame == 60
    assert glitch.any() and (sim.z_m[glitch] > 30).any()
    ok = est.status == "ok"
    assert np.isnan(est.theta_rad[glitch]).all()
    if method == "ours":  # the size cue carries the frame, as it would without the glitch
        assert ok[glitch].mean() > 0.5
        clean = estimate_sequence(
            make_estimator(method, camera), sim.boxes, sim.timestamps_s, glitched_traffic([])[2]
        ).estimates
        rows = glitch & ok
        np.testing.assert_allclose(est.distance_m[rows], clean.distance_m[rows], rtol=0.05)
    else:
        far_ok = ok & (sim.z_m > 30)  # contact vs centre: a few % off there
        assert np.all(np.abs(est.distance_m[far_ok] / sim.z_m[far_ok] - 1) < 0.25)
        assert set(est.reason[glitch]) == {"odometry_jump"}
        assert (est.status[glitch] == "missing").all()
        assert (est.status[~glitch] == "ok").mean() > 0.9
    streamed, _ = run_streaming_on(method, camera, track, sim.boxes)
    np.testing.assert_array_equal(streamed.reason, est.reason)
    np.testing.assert_allclose(streamed.distance_m, est.distance_m, rtol=1e-9, equal_nan=True)


def run_streaming_on(method: str, camera: Camera, track: RotationTrack, boxes: BoxTable):
    step = FrameStep(make_estimator(method, camera))
    results = list(stream_track(step, track, boxes))
    return concat_estimates([r.estimates for _, _, r in results]), [r for _, _, r in results]


@pytest.mark.parametrize("method", ["paper", "ours"])
def test_a_pitch_step_that_persists_is_accepted_after_the_settling_time(method: str) -> None:
    """An odometry re-initialised 5° off: the first 0.5 s are ``odometry_jump``, then the new
    level is the reference (θ ≈ 0 again, no second of θ = 5°) and the run goes on."""
    camera, sim, track = glitched_traffic(range(60, 120))
    streamed, results = run_streaming_on(method, camera, track, sim.boxes)
    theta = np.array([r.theta_rad for r in results])
    assert np.isnan(theta[60:65]).all()
    np.testing.assert_allclose(theta[65:], 0.0, atol=1e-12)
    batch = estimate_sequence(make_estimator(method, camera), sim.boxes, sim.timestamps_s, track)
    np.testing.assert_allclose(ego_gradients(track), theta, atol=1e-12)
    np.testing.assert_array_equal(streamed.reason, batch.estimates.reason)
    after = sim.boxes.frame >= 65
    ok = batch.estimates.status == "ok"
    assert ok[after].mean() > 0.9
    clean = estimate_sequence(
        make_estimator(method, camera), sim.boxes, sim.timestamps_s, glitched_traffic([])[2]
    ).estimates
    rows = ok & after
    np.testing.assert_allclose(batch.estimates.distance_m[rows], clean.distance_m[rows], rtol=0.05)
    if method == "paper":
        settling = (sim.boxes.frame >= 60) & ~after
        assert set(batch.estimates.reason[settling]) == {"odometry_jump"}


def test_a_jump_frame_gives_the_estimator_the_last_trusted_rotation() -> None:
    """A tracking method compensates the camera's rotation between frames: a glitch frame
    gives it none since the last trusted frame, not the glitch nor the identity (a camera
    turned 80° would have turned back 80° for its tracks), in a stream as in a batch."""
    n = 30
    yaw = Rotation.from_euler("y", 80, degrees=True).as_matrix()
    R = np.tile(yaw, (n, 1, 1))
    R[12] = yaw @ Rotation.from_euler("x", 5, degrees=True).as_matrix()
    track = RotationTrack.from_arrays(0.1 * np.arange(n), R)
    boxes = BoxTable.build(list(range(n)), np.tile([600.0, 200.0, 660.0, 250.0], (n, 1)))
    seen: dict[str, list[np.ndarray]] = {"stream": [], "batch": []}
    for mode, runs in seen.items():
        estimator = make_estimator("paper", CAMERA)
        estimate = estimator.estimate

        def spy(frame, runs=runs, estimate=estimate):
            runs.append(frame.R_world_cam)
            return estimate(frame)

        estimator.estimate = spy  # type: ignore[method-assign]
        if mode == "stream":
            list(stream_track(FrameStep(estimator), track, boxes))
        else:
            estimate_sequence(estimator, boxes, track.timestamps_s, track)
        np.testing.assert_array_equal(runs[12], yaw)
        np.testing.assert_array_equal(runs[13], yaw)


@settings(max_examples=40, deadline=None)
@given(
    dts=st.lists(st.floats(0.01, 0.4), min_size=2, max_size=50),
    data=st.data(),
)
def test_the_stream_and_the_batch_find_the_same_jumps_and_gradients(dts, data) -> None:
    """Irregular frame periods, frames without a rotation, glitches of any size (one frame or
    persisting): θ frame by frame equals θ of the whole track at once."""
    n = len(dts)
    pitch = np.cumsum(data.draw(st.lists(st.floats(-1.0, 1.0), min_size=n, max_size=n)))
    sizes = st.sampled_from([0.0, 0.0, 0.0, 6.0, -9.0])  # degrees: none, or a jump
    glitch = np.array(data.draw(st.lists(sizes, min_size=n, max_size=n)))
    valid = np.array(data.draw(st.lists(st.booleans(), min_size=n, max_size=n))) | (glitch == 0)
    R = Rotation.from_euler("YX", np.c_[np.arange(n) * 3.0, pitch + glitch], degrees=True)
    track = RotationTrack.from_arrays(np.cumsum(dts), R.as_matrix(), valid)
    tracker = EgoGradientTracker()
    streamed = [
        tracker.update(float(track.timestamps_s[k]), R.as_matrix()[k] if valid[k] else None)
        for k in range(n)
    ]
    np.testing.assert_allclose(streamed, ego_gradients(track), equal_nan=True, atol=1e-12)


@pytest.mark.parametrize("method", ["paper", "ours", "depthmap"])
def test_a_frame_step_with_a_reference_moves_every_method_there(method: str) -> None:
    """``FrameStep(reference=...)`` (what ``run`` does) gives every method's distances at the
    point asked for, as :func:`to_reference` moves them; without it each keeps its own."""
    track, boxes = synthetic_sequence(30)
    depth = np.full((375, 1242), 15.0, np.float32) if method == "depthmap" else None

    def stream(reference: ReferencePoint | None) -> FrameEstimates:
        step = FrameStep(make_estimator(method, CAMERA), reference=reference)
        step.reset()
        parts = []
        for k, frame_boxes in boxes.by_frame():
            R = track.R_world_cam[k] if track.valid[k] else None
            parts.append(step.step(k, 0.1 * k, R, frame_boxes, None, depth).estimates)
        return concat_estimates(parts)

    own, centre = stream(None), stream(ReferencePoint.CENTRE)
    face = stream(ReferencePoint.NEAREST_FACE)
    half = own_half_extent_m(own.extra, len(own))
    for wanted, got in ((ReferencePoint.CENTRE, centre), (ReferencePoint.NEAREST_FACE, face)):
        expected = to_reference(own.distance_m, own.reference, boxes.cls, wanted, half)
        np.testing.assert_allclose(got.distance_m, expected, equal_nan=True)
    assert np.isfinite(face.distance_m).sum() > 10
    assert set(centre.reference.tolist()) == {"centre"}
    shown = {"paper": "contact", "ours": "nearest_face", "depthmap": "nearest_face"}[method]
    assert set(face.reference.tolist()) == {shown}
