"""Built-in visual odometry on rendered point scenes with known motion, and on real KITTI frames.

The synthetic scenes are random 3D points drawn as Gaussian blobs into grey images through known
camera poses (forward motion, turns, pitch, a standing car, a vehicle moving with the camera).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from slopedist.core import geometry as geo
from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError, DataMismatchError
from slopedist.odometry import twoview as tv
from slopedist.odometry.base import OdometryResult, OdometryState, lookback_indices
from slopedist.odometry.factory import make_odometry
from slopedist.odometry.image_stats import (
    MIN_EXPOSURE_CHANGE,
    blur_to_energy,
    gradient_energy,
    grey_stats,
    match_exposure,
)
from slopedist.odometry.visual import BuiltinVisualOdometry, VisualOdometryConfig

Points = tuple[NDArray[np.float64], NDArray[np.float64]]
W, H, F = 640, 240, 400.0
CAMERA = Camera(F, W / 2 - 0.5, H / 2 - 0.5).with_image_size(W, H)
DT = 0.1


# ---------------------------------------------------------------------------- scene rendering
def scene_points(n: int = 1500, seed: int = 0) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Random world points (x right, y down, z forward; metres) and blob brightness."""
    rng = np.random.default_rng(seed)
    X = np.c_[rng.uniform(-60, 60, n), rng.uniform(-12, 1.6, n), rng.uniform(15, 220, n)]
    return X, rng.uniform(90, 200, n)


def render_blobs(
    uv: NDArray[np.float64],
    brightness: NDArray[np.float64],
    sigma: float = 1.5,
    background: float = 40.0,
    image: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Add Gaussian blobs at pixel positions ``uv`` ``(N, 2)`` to a float image."""
    img = np.full((H, W), background) if image is None else image
    r = 4
    d = np.arange(-r, r + 1)
    dx, dy = (g.ravel() for g in np.meshgrid(d, d))
    px = np.rint(uv[:, :1]) + dx
    py = np.rint(uv[:, 1:]) + dy
    val = brightness[:, None] * np.exp(
        -((px - uv[:, :1]) ** 2 + (py - uv[:, 1:]) ** 2) / (2 * sigma**2)
    )
    ok = (px >= 0) & (px < W) & (py >= 0) & (py < H)
    np.add.at(img, (py[ok].astype(int), px[ok].astype(int)), val[ok])
    return img


def render(
    X: NDArray[np.float64],
    brightness: NDArray[np.float64],
    R_world_cam: NDArray[np.float64],
    centre: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Float image of the world points seen by a camera at ``centre`` with ``R_world_cam``."""
    Xc = (X - centre) @ R_world_cam
    front = Xc[:, 2] > 1.0
    uv = F * Xc[front, :2] / Xc[front, 2:] + [CAMERA.c_x, CAMERA.c_y]
    inside = np.all((uv > -5) & (uv < [W + 5, H + 5]), axis=1)
    return render_blobs(uv[inside], brightness[front][inside])


def to_uint8(img: NDArray[np.float64]) -> NDArray[np.uint8]:
    return np.clip(img, 0, 255).astype(np.uint8)


def trajectory(
    n: int, speed: float = 10.0, yaw_rate_deg: float = 0.0, pitch_rate_deg: float = 0.0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Camera-to-world rotations ``(n, 3, 3)`` and centres ``(n, 3)`` of a car driving forward
    at ``speed`` m/s and turning/pitching at constant rates (degrees per second)."""
    w = np.radians([pitch_rate_deg, yaw_rate_deg, 0.0]) * DT
    Rs, cs = [np.eye(3)], [np.zeros(3)]
    for _ in range(n - 1):
        cs.append(cs[-1] + Rs[-1] @ np.array([0.0, 0.0, speed * DT]))
        Rs.append(Rs[-1] @ tv.so3_exp(w))
    return np.array(Rs), np.array(cs)


def run(
    vo: BuiltinVisualOdometry,
    images: Sequence[NDArray[np.uint8]],
    times: Sequence[float],
    boxes: NDArray[np.float64] | None = None,
) -> list[OdometryResult]:
    return [vo.process(img, t, boxes) for img, t in zip(images, times)]


def lookback_errors_deg(
    results: list[OdometryResult], R_true: NDArray[np.float64], times: Sequence[float]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Relative-rotation and θ errors (degrees) over the one-second look-back, frames ≥ 1."""
    L = lookback_indices(np.asarray(times))
    rel, theta = [], []
    for k in range(1, len(results)):
        Ra, Rb = results[L[k]].R_world_cam, results[k].R_world_cam
        assert Ra is not None and Rb is not None
        rel.append(geo.rotation_angle_rad((Ra.T @ Rb).T @ (R_true[L[k]].T @ R_true[k])))
        theta.append(geo.ego_road_gradient(Ra, Rb) - geo.ego_road_gradient(R_true[L[k]], R_true[k]))
    return np.degrees(rel), np.degrees(theta)


@pytest.fixture(scope="module")
def points() -> Points:
    return scene_points()


# ---------------------------------------------------------------------------- accuracy
@pytest.mark.parametrize(
    ("motion", "median_deg", "max_deg"),
    [
        ({"pitch_rate_deg": 2.0}, 0.05, 0.12),  # straight, the road steepening
        ({"yaw_rate_deg": 20.0, "pitch_rate_deg": 1.0}, 0.08, 0.25),  # a sharp turn
    ],
)
def test_rotation_over_one_second(
    points: Points,
    motion: dict[str, float],
    median_deg: float,
    max_deg: float,
) -> None:
    R, c = trajectory(25, **motion)
    images = [to_uint8(render(*points, R[k], c[k])) for k in range(len(R))]
    times = [k * DT for k in range(len(R))]
    results = run(BuiltinVisualOdometry(CAMERA), images, times)
    assert all(r.state is OdometryState.OK for r in results)
    assert all(r.inliers >= 20 for r in results[1:])
    rel, theta = lookback_errors_deg(results, R, times)
    # f = 400 px: 0.05° is a third of a pixel over the second
    assert np.median(rel) < median_deg
    assert np.max(rel) < max_deg
    assert np.sqrt(np.mean(theta**2)) < 0.05


def test_standing_car_uses_the_rotation_only_model(
    points: Points,
) -> None:
    R, c = trajectory(15, speed=0.0, yaw_rate_deg=5.0, pitch_rate_deg=-1.0)
    images = [to_uint8(render(*points, R[k], c[k])) for k in range(len(R))]
    times = [k * DT for k in range(len(R))]
    vo = BuiltinVisualOdometry(CAMERA)
    results = run(vo, images, times)
    assert all(r.state is OdometryState.OK for r in results)
    assert vo.last_fit is not None and vo.last_fit.model == "rotation"
    rel, _ = lookback_errors_deg(results, R, times)
    assert np.max(rel) < 0.02


def test_completely_static_camera_stays_at_identity(
    points: Points,
) -> None:
    image = to_uint8(render(*points, np.eye(3), np.zeros(3)))
    results = run(BuiltinVisualOdometry(CAMERA), [image] * 12, [k * DT for k in range(12)])
    assert all(r.state is OdometryState.OK for r in results)
    assert results[-1].R_world_cam is not None
    assert np.degrees(geo.rotation_angle_rad(results[-1].R_world_cam)) < 0.01


def test_dropped_frame(points: Points) -> None:
    R, c = trajectory(25, yaw_rate_deg=8.0, pitch_rate_deg=1.5)
    keep = [k for k in range(len(R)) if k != 13]  # frame 13 never arrives: a 0.2 s gap
    images = [to_uint8(render(*points, R[k], c[k])) for k in keep]
    times = [k * DT for k in keep]
    results = run(BuiltinVisualOdometry(CAMERA), images, times)
    assert all(r.state is OdometryState.OK for r in results)
    rel, _ = lookback_errors_deg(results, R[keep], times)
    assert np.max(rel) < 0.15


def test_masked_vehicle_is_ignored(points: Points) -> None:
    # a textured vehicle ahead that keeps its place in the image (it drives with the camera)
    rng = np.random.default_rng(5)
    box = np.array([[180.0, 60.0, 460.0, 220.0]])
    car_uv = np.c_[rng.uniform(190, 450, 250), rng.uniform(70, 210, 250)]
    car_brightness = rng.uniform(120, 220, 250)
    R, c = trajectory(25, yaw_rate_deg=6.0, pitch_rate_deg=1.0)
    images = []
    for k in range(len(R)):
        img = render(*points, R[k], c[k])
        img[60:221, 180:461] = 60.0  # the car hides the scene behind it
        images.append(to_uint8(render_blobs(car_uv, car_brightness, image=img)))
    times = [k * DT for k in range(len(R))]
    vo = BuiltinVisualOdometry(CAMERA)
    results = run(vo, images, times, boxes=box)
    assert all(r.state is OdometryState.OK for r in results)
    pts = vo.tracks  # tracks alive now: none inside the masked box
    inside = (pts[:, 0] >= 180) & (pts[:, 0] <= 460) & (pts[:, 1] >= 60) & (pts[:, 1] <= 220)
    assert not inside.any()
    rel, _ = lookback_errors_deg(results, R, times)
    assert np.median(rel) < 0.06


@pytest.mark.parametrize(
    "gain",
    [
        pytest.param(lambda k: 0.35 if k >= 10 else 1.0, id="exposure-drops-and-stays"),
        pytest.param(lambda k: 0.6 if k % 2 else 1.0, id="flicker"),
        pytest.param(lambda k: 0.2 if 9 <= k <= 12 else 1.0, id="dark-then-normal"),
    ],
)
def test_exposure_changes_keep_tracking(points: Points, gain: Callable[[int], float]) -> None:
    R, c = trajectory(25, yaw_rate_deg=8.0, pitch_rate_deg=1.5)
    images = [to_uint8(gain(k) * render(*points, R[k], c[k])) for k in range(len(R))]
    times = [k * DT for k in range(len(R))]
    vo = BuiltinVisualOdometry(CAMERA)
    results = run(vo, images, times)
    assert all(r.state is OdometryState.OK for r in results)
    assert vo.segment == 0
    rel, theta = lookback_errors_deg(results, R, times)
    assert np.median(rel) < 0.08
    assert np.sqrt(np.mean(theta**2)) < 0.05


@pytest.mark.parametrize(("sigma_px", "lost"), [(2.0, False), (4.0, True)])
def test_blurred_frames(points: Points, sigma_px: float, lost: bool) -> None:
    """Frames 9–11 blurred (a jolt): a mild blur is tracked (both frames of a pair blurred
    alike), a heavy one is LOST and bridged; either way the sharp frames after it continue the
    same segment at full accuracy."""
    import cv2

    R, c = trajectory(25, yaw_rate_deg=8.0, pitch_rate_deg=1.5)
    images = [to_uint8(render(*points, R[k], c[k])) for k in range(len(R))]
    for k in (9, 10, 11):
        images[k] = np.asarray(cv2.GaussianBlur(images[k], (0, 0), sigma_px))
    times = [k * DT for k in range(len(R))]
    vo = BuiltinVisualOdometry(CAMERA)
    results = run(vo, images, times)
    states = [r.state for r in results]
    blurred_states = {states[k] for k in (9, 10, 11)}
    assert blurred_states == ({OdometryState.LOST} if lost else {OdometryState.OK})
    assert all(states[k] is OdometryState.OK for k in range(len(R)) if k not in (9, 10, 11))
    assert vo.segment == 0
    ok = [k for k in range(len(R)) if states[k] is OdometryState.OK]
    rel, theta = lookback_errors_deg([results[k] for k in ok], R[ok], [times[k] for k in ok])
    assert np.median(rel) < 0.08
    assert np.sqrt(np.mean(theta**2)) < 0.05


def test_blur_to_energy_reaches_the_blurrier_frame(points: Points) -> None:
    import cv2

    sharp = to_uint8(render(*points, np.eye(3), np.zeros(3)))
    blurred = np.asarray(cv2.GaussianBlur(sharp, (0, 0), 2.0))
    target = gradient_energy(blurred)
    assert gradient_energy(sharp) > 2 * target
    matched = blur_to_energy(sharp, target)
    assert abs(np.log(gradient_energy(matched) / target)) < np.log(1.25)
    # gain- and offset-free: the exposure does not change the sharpness measure
    darker = to_uint8(0.4 * sharp.astype(float) + 10)
    assert gradient_energy(darker) == pytest.approx(gradient_energy(sharp), rel=0.05)


def test_match_exposure_undoes_a_gain_and_offset() -> None:
    rng = np.random.default_rng(3)
    reference = rng.integers(20, 220, size=(60, 80)).astype(np.uint8)
    darker = np.clip(0.5 * reference.astype(float) + 4.0, 0, 255).astype(np.uint8)
    matched = match_exposure(darker, reference, MIN_EXPOSURE_CHANGE)
    assert matched is not None
    # quantisation of the darker frame (half the levels) leaves at most ~1.5 levels
    assert np.max(np.abs(matched.astype(int) - reference.astype(int))) <= 2
    assert match_exposure(reference, reference, MIN_EXPOSURE_CHANGE) is None  # no change
    blank = np.full((60, 80), 40, dtype=np.uint8)
    assert match_exposure(blank, reference, MIN_EXPOSURE_CHANGE) is None  # nothing to match
    # statistics passed in (cached from an earlier frame) give the same mapping
    again = match_exposure(
        darker,
        reference,
        MIN_EXPOSURE_CHANGE,
        image_stats=grey_stats(darker),
        reference_stats=grey_stats(reference),
    )
    assert again is not None and np.array_equal(again, matched)


# ---------------------------------------------------------------------------- states
def test_lost_on_blank_frames_then_recovers(
    points: Points,
) -> None:
    R, c = trajectory(30, yaw_rate_deg=5.0)
    images = [to_uint8(render(*points, R[k], c[k])) for k in range(len(R))]
    blank = np.full((H, W), 40, dtype=np.uint8)
    vo = BuiltinVisualOdometry(CAMERA)
    assert vo.process(blank, 0.0).state is OdometryState.NOT_INITIALISED
    states = []
    for k in range(1, 30):
        image = blank if k in (8, 9) or 15 <= k <= 22 else images[k]
        result = vo.process(image, k * DT)
        states.append((k, result.state, result.segment))
        if result.state is not OdometryState.OK:
            assert result.R_world_cam is None
    by_frame = {k: (s, seg) for k, s, seg in states}
    assert by_frame[1] == (OdometryState.OK, 0)  # the first textured frame is the origin
    assert by_frame[8][0] is OdometryState.LOST and by_frame[9][0] is OdometryState.LOST
    assert by_frame[10] == (OdometryState.OK, 0)  # bridged from frame 7: same segment
    assert all(by_frame[k][0] is OdometryState.LOST for k in range(15, 23))
    assert by_frame[23] == (OdometryState.OK, 1)  # too long without a good frame: new segment
    assert by_frame[29] == (OdometryState.OK, 1)


def test_bridged_rotation_is_accurate(points: Points) -> None:
    R, c = trajectory(22, yaw_rate_deg=6.0, pitch_rate_deg=1.5)
    blank = np.full((H, W), 40, dtype=np.uint8)
    vo = BuiltinVisualOdometry(CAMERA)
    results = [
        vo.process(blank if k in (12, 13) else to_uint8(render(*points, R[k], c[k])), k * DT)
        for k in range(len(R))
    ]
    assert results[21].R_world_cam is not None and results[11].R_world_cam is not None
    rel = results[11].R_world_cam.T @ results[21].R_world_cam
    assert np.degrees(geo.rotation_angle_rad(rel.T @ (R[11].T @ R[21]))) < 0.15


# ---------------------------------------------------------------------------- bad input
def test_timestamps_must_increase() -> None:
    vo = BuiltinVisualOdometry(CAMERA)
    image = np.full((H, W), 40, dtype=np.uint8)
    vo.process(image, 1.0)
    with pytest.raises(DataMismatchError, match="does not follow"):
        vo.process(image, 0.9)
    with pytest.raises(DataMismatchError, match="does not follow"):
        vo.process(image, 1.0)
    with pytest.raises(DataMismatchError, match="finite"):
        vo.process(image, float("nan"))
    vo.reset()
    vo.process(image, 0.0)  # a new sequence may start again at 0


def test_image_size_and_type_are_checked() -> None:
    vo = BuiltinVisualOdometry(CAMERA)
    with pytest.raises(DataMismatchError, match="640×240 px of the camera calibration"):
        vo.process(np.zeros((200, 640), dtype=np.uint8), 0.0)
    with pytest.raises(DataMismatchError, match="grey H×W uint8"):
        vo.process(np.zeros((H, W, 3), dtype=np.uint8), 0.0)
    with pytest.raises(DataMismatchError, match="grey H×W uint8"):
        vo.process(np.zeros((H, W), dtype=np.float32), 0.0)
    with pytest.raises(DataMismatchError, match=r"mask_boxes must be \(N, 4\)"):
        vo.process(np.zeros((H, W), dtype=np.uint8), 0.0, np.zeros((2, 3)))

    unsized = BuiltinVisualOdometry(Camera(F, W / 2, H / 2))
    unsized.process(np.zeros((H, W), dtype=np.uint8), 0.0)
    with pytest.raises(DataMismatchError, match="of the first frame"):
        unsized.process(np.zeros((H + 2, W), dtype=np.uint8), 0.1)
    far_off = BuiltinVisualOdometry(Camera(F, 900.0, 500.0))
    with pytest.raises(DataMismatchError, match="calibration and frames do not match"):
        far_off.process(np.zeros((H, W), dtype=np.uint8), 0.0)


@pytest.mark.parametrize("size", [(1, 1), (600, 1), (1, 40)])
def test_frames_one_pixel_high_or_wide_are_never_initialised(size: tuple[int, int]) -> None:
    """They failed inside OpenCV's resize (the half-size copy): an internal error in ``run``."""
    width, height = size
    vo = BuiltinVisualOdometry(Camera(700.0, width / 2, height / 2))
    rng = np.random.default_rng(0)
    for k in range(3):
        frame = rng.integers(0, 255, (height, width), dtype=np.uint8)
        result = vo.process(frame, 0.1 * k)
        assert result.R_world_cam is None and result.state is OdometryState.NOT_INITIALISED


def test_configuration_is_checked() -> None:
    with pytest.raises(ConfigurationError):
        VisualOdometryConfig(min_inliers=3)
    with pytest.raises(ConfigurationError):
        VisualOdometryConfig(lookback_s=0.0)
    with pytest.raises(ConfigurationError, match="frame_to_frame_floor_rad"):
        VisualOdometryConfig(frame_to_frame_floor_rad=-1e-4)
    with pytest.raises(ConfigurationError, match="unknown option"):
        make_odometry("builtin", CAMERA, no_such_option=1)
    with pytest.raises(ConfigurationError, match="unknown odometry backend"):
        make_odometry("nope", CAMERA)
    vo = make_odometry("builtin", CAMERA, max_features=120)
    assert isinstance(vo, BuiltinVisualOdometry) and vo.config.max_features == 120


def test_memory_is_bounded(points: Points) -> None:
    R, c = trajectory(8, yaw_rate_deg=3.0)
    images = [to_uint8(render(*points, R[k], c[k])) for k in range(len(R))]
    images += images[::-1]  # drive back and forth: 16 frames per loop
    vo = BuiltinVisualOdometry(CAMERA, VisualOdometryConfig(max_features=150))
    for k in range(64):
        vo.process(images[k % len(images)], k * DT)
        assert vo.history_frames <= 12  # one look-back of frames at 10 Hz, plus the current
        assert len(vo.tracks) <= 150
        assert all(len(rec.ids) <= 150 for rec in vo._history)


# ---------------------------------------------------------------------------- real frames
@pytest.mark.parametrize(
    ("sequence", "theta_rms_max", "rel_median_max"),
    [("seq06_000-050", 0.08, 0.15), ("unknown_000-050", 0.12, 0.30)],
)
def test_real_kitti_frames(
    kitti_odometry_dir: Path, sequence: str, theta_rms_max: float, rel_median_max: float
) -> None:
    from slopedist.io.kitti.odometry import read_kitti_odometry
    from slopedist.odometry.accuracy import OdometryEvaluation, run_odometry

    seq = read_kitti_odometry(kitti_odometry_dir / sequence)
    assert seq.ground_truth is not None
    vo = BuiltinVisualOdometry(seq.camera)
    result = run_odometry(vo, ((t, img) for _, t, img in seq.frames()))
    figures = OdometryEvaluation.from_run(result, seq.ground_truth)
    assert figures.frames_ok == len(seq)
    # measured θ 0.041° / 0.028°, rel 0.048° / 0.209°; identity rotations would give 0.3° / 0.4°
    # and 0.5° / 26° (the sharp turn)
    assert np.degrees(figures.theta_rms_rad) < theta_rms_max
    assert np.degrees(figures.rel_rot_median_rad) < rel_median_max


def _seq06_with(
    kitti_odometry_dir: Path, edit: Callable[[int, NDArray[np.uint8]], NDArray[np.uint8]]
) -> tuple[float, float, int, int]:
    """Run the built-in odometry on seq06 with frame ``k`` replaced by ``edit(k, frame)``:
    (θ RMS error °, relative-rotation median error °, frames ok − frames, segments)."""
    from slopedist.io.kitti.odometry import read_kitti_odometry
    from slopedist.odometry.accuracy import OdometryEvaluation, run_odometry

    seq = read_kitti_odometry(kitti_odometry_dir / "seq06_000-050")
    assert seq.ground_truth is not None
    vo = BuiltinVisualOdometry(seq.camera)
    result = run_odometry(vo, ((t, edit(k, img)) for k, t, img in seq.frames()))
    figures = OdometryEvaluation.from_run(result, seq.ground_truth)
    return (
        float(np.degrees(figures.theta_rms_rad)),
        float(np.degrees(figures.rel_rot_median_rad)),
        figures.frames_ok - len(seq),
        vo.segment,
    )


def test_real_kitti_frames_through_exposure_changes(kitti_odometry_dir: Path) -> None:
    """Real frames whose exposure halves at frame 20, and a dark stretch (×0.15, frames 30–33)
    followed by normal frames: every frame keeps its rotation, at the plain run's accuracy."""

    def exposed(k: int, image: NDArray[np.uint8]) -> NDArray[np.uint8]:
        gain = 0.15 if 30 <= k <= 33 else 0.5 if k >= 20 else 1.0
        return np.clip(gain * image.astype(np.float64), 0, 255).astype(np.uint8)

    theta, rel, missing, segment = _seq06_with(kitti_odometry_dir, exposed)
    # measured 0.041° / 0.052° (the unchanged frames give 0.041° / 0.048°); without the exposure
    # match 8 frames are lost and a new segment starts
    assert (missing, segment) == (0, 0)
    assert theta < 0.08
    assert rel < 0.15


def test_real_kitti_frames_through_a_blur(kitti_odometry_dir: Path) -> None:
    """Real frames 20–22 blurred by 4 px: tracked (blurred alike in pairs), same segment."""
    import cv2

    def blurred(k: int, image: NDArray[np.uint8]) -> NDArray[np.uint8]:
        return np.asarray(cv2.GaussianBlur(image, (0, 0), 4.0)) if 20 <= k <= 22 else image

    theta, rel, missing, segment = _seq06_with(kitti_odometry_dir, blurred)
    # measured 0.044° / 0.112°; without the sharpness match frames 23–27 were lost (the sharp
    # frames after the blur did not track) and a new segment started
    assert (missing, segment) == (0, 0)
    assert theta < 0.08
    assert rel < 0.15
