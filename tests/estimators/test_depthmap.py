"""The depth-map baseline on analytic scenes: a flat road plus box-shaped cars, exact depth."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError, DataMismatchError
from slopedist.estimators import DepthMapEstimator, FrameInput, make_estimator
from slopedist.estimators.depthmap import DepthSample, sample_box_depth
from slopedist.io.detections.boxes import BoxTable

W, H = 1240, 375
CAMERA = Camera(720.0, 620.0, 180.0, height_m=1.65).with_image_size(W, H)
CAR_W, CAR_H = 1.6, 1.5


def car_box(x_m: float, z_m: float, cam: Camera = CAMERA) -> np.ndarray:
    """Pixel box of a car's rear face (1.6 m × 1.5 m) standing on the road at (x, z)."""
    return np.array(
        [
            cam.c_x + cam.f * (x_m - CAR_W / 2) / z_m,
            cam.c_y + cam.f * (cam.height_m - CAR_H) / z_m,
            cam.c_x + cam.f * (x_m + CAR_W / 2) / z_m,
            cam.c_y + cam.f * cam.height_m / z_m,
        ]
    )


def render(cars: list[tuple[float, float]], cam: Camera = CAMERA) -> np.ndarray:
    """True depth (metres, float32 H×W) of a level road plus the cars' rear faces; sky = NaN."""
    rows = np.arange(H, dtype=float)[:, None]
    with np.errstate(divide="ignore"):
        road = np.where(rows > cam.c_y, cam.f * cam.height_m / (rows - cam.c_y), np.nan)
    depth = np.broadcast_to(road, (H, W)).copy()
    for x, z in sorted(cars, key=lambda c: -c[1]):  # far first, near cars overwrite
        left, top, right, bottom = car_box(x, z, cam)
        r0, r1 = max(math.ceil(top), 0), min(math.floor(bottom) + 1, H)
        c0, c1 = max(math.ceil(left), 0), min(math.floor(right) + 1, W)
        depth[r0:r1, c0:c1] = z
    return depth.astype(np.float32)


def frame_of(
    cars: list[tuple[float, float]], depth: np.ndarray | None, k: int = 0, **extra: np.ndarray
) -> FrameInput:
    boxes = np.array([car_box(x, z) for x, z in cars]).reshape(-1, 4)
    return FrameInput(
        k, 0.1 * k, 0.0, BoxTable.build(np.full(len(boxes), k), boxes, **extra), depth_m=depth
    )


CARS = [(-3.0, 9.0), (0.0, 21.5), (3.5, 44.0)]


@pytest.mark.parametrize("sample", ["centre", "window", "lower"])
def test_true_depth_gives_the_true_distance(sample: str) -> None:
    out = DepthMapEstimator(CAMERA, sample=sample).estimate(frame_of(CARS, render(CARS)))
    assert list(out.reason) == ["", "", ""]
    np.testing.assert_allclose(out.distance_m, [z for _, z in CARS], rtol=1e-6)
    assert set(out.reference) == {"box_centre_pixel"}
    np.testing.assert_allclose(out.extra["depth_scale"], 1.0)


def test_is_registered_and_needs_depth_not_rotation() -> None:
    est = make_estimator("depthmap", CAMERA)
    assert isinstance(est, DepthMapEstimator)
    assert est.needs_depth and not est.needs_rotation
    frame = FrameInput(
        0, 0.0, math.nan, BoxTable.build([0], [car_box(0, 10)]), depth_m=render([(0, 10)])
    )
    assert est.estimate(frame).distance_m[0] == pytest.approx(10.0)


def test_window_median_is_robust_to_noise_and_holes() -> None:
    rng = np.random.default_rng(4)
    depth = render(CARS) * rng.normal(1.0, 0.05, (H, W)).astype(np.float32)
    for _, z in CARS:  # punch a hole at each box centre
        b = car_box(_, z)
        depth[round((b[1] + b[3]) / 2), round((b[0] + b[2]) / 2)] = np.nan
    centre = DepthMapEstimator(CAMERA, sample="centre").estimate(frame_of(CARS, depth))
    assert list(centre.reason) == ["no_depth"] * 3 and np.all(np.isnan(centre.distance_m))
    window = DepthMapEstimator(CAMERA, sample="window", window_px=7).estimate(frame_of(CARS, depth))
    np.testing.assert_allclose(window.distance_m, [z for _, z in CARS], rtol=0.03)


def test_missing_depth_map_and_boxes_outside_the_image() -> None:
    out = DepthMapEstimator(CAMERA).estimate(frame_of(CARS, None))
    assert list(out.reason) == ["no_depth"] * 3
    frame = FrameInput(
        0,
        0.0,
        0.0,
        BoxTable.build([0, 0], [[2000, 10, 2100, 50], [5, 50, 3, 60]]),
        depth_m=render([]),
    )
    reasons = DepthMapEstimator(CAMERA).estimate(frame).reason
    assert list(reasons) == ["outside_image", "inverted_box"]


def test_contact_median_scaling_recovers_scale_less_depth() -> None:
    """A relative-depth model (depth × 0.37) is rescaled by the flat-ground distances."""
    est = DepthMapEstimator(CAMERA, scaling="contact")
    out = est.estimate(frame_of(CARS, 0.37 * render(CARS)))
    np.testing.assert_allclose(out.distance_m, [z for _, z in CARS], rtol=1e-5)
    np.testing.assert_allclose(out.extra["depth_scale"], 1 / 0.37, rtol=1e-5)
    np.testing.assert_allclose(out.extra["depth_raw_m"], [0.37 * z for _, z in CARS], rtol=1e-5)


def test_truth_scaling_uses_the_supplied_column_and_carries_the_scale() -> None:
    est = DepthMapEstimator(CAMERA, scaling="truth")
    cars = [(0.0, 12.0), (3.0, 30.0)]
    gt = np.array([12.0, 30.0])
    out = est.estimate(frame_of(cars, 3.0 * render(cars), gt_distance_m=gt))
    np.testing.assert_allclose(out.distance_m, gt, rtol=1e-5)
    # next frame has no truth: the last scale is reused
    out2 = est.estimate(frame_of(cars, 3.0 * render(cars), k=1, gt_distance_m=np.full(2, np.nan)))
    np.testing.assert_allclose(out2.distance_m, gt, rtol=1e-5)
    est.reset()
    out3 = est.estimate(frame_of(cars, render(cars), k=0, gt_distance_m=np.full(2, np.nan)))
    assert list(out3.reason) == ["no_scale", "no_scale"]
    with pytest.raises(ConfigurationError, match="gt_distance_m"):
        est.estimate(frame_of(cars, render(cars)))


@pytest.mark.parametrize("value", [1e-30, 0.05, -3.0, 0.0, 1500.0, 1e30, np.inf, np.nan])
@pytest.mark.parametrize("sample", ["centre", "window", "lower"])
def test_implausible_metric_depth_is_no_depth_not_a_clamped_number(
    value: float, sample: str
) -> None:
    """A network output of 1e-30 (or 1e30, 5 cm, ...) over the whole car is no measurement."""
    cars = [(0.0, 15.0)]
    depth = render(cars)
    depth[depth == 15.0] = value
    out = DepthMapEstimator(CAMERA, sample=sample).estimate(frame_of(cars, depth))
    assert list(out.reason) == ["no_depth"] and math.isnan(out.distance_m[0])


def test_plausibility_applies_to_metres_after_scaling() -> None:
    """Scale-less maps may hold any positive unit: the check is on the scaled metres."""
    cars = [(-3.0, 9.0), (0.0, 21.5)]
    tiny = DepthMapEstimator(CAMERA, scaling="contact").estimate(
        frame_of(cars, 1e-4 * render(cars))
    )
    np.testing.assert_allclose(tiny.distance_m, [9.0, 21.5], rtol=1e-4)
    truth = DepthMapEstimator(CAMERA, scaling="truth")
    out = truth.estimate(frame_of(cars, render(cars), gt_distance_m=np.array([9.0, 21.5])))
    assert list(out.reason) == ["", ""]
    # the scale learnt on frame 0 turns frame 1's 1e-6 m into micrometres: no depth
    far = render(cars)
    far[far == 9.0] = 1e-6
    out1 = truth.estimate(frame_of(cars, far, k=1, gt_distance_m=np.full(2, np.nan)))
    assert list(out1.reason) == ["no_depth", ""]


def test_a_depth_is_never_capped() -> None:
    """A depth beyond 80 m was capped to 80 m and marked ``ok`` (the README: never clamped)."""
    cars = [(0.0, 100.0)]
    out = DepthMapEstimator(CAMERA).estimate(frame_of(cars, render(cars)))
    assert out.distance_m[0] == pytest.approx(100.0) and out.reason[0] == ""
    beyond = render(cars)
    beyond[beyond == 100.0] = 1500.0  # not a road scene's depth
    out = DepthMapEstimator(CAMERA).estimate(frame_of(cars, beyond))
    assert out.reason[0] == "no_depth" and np.isnan(out.distance_m[0])


@pytest.mark.parametrize("window_px", [201, 100_001])
def test_a_window_wider_than_the_box_never_leaves_it(window_px: int) -> None:
    """``--depth-window 100001`` gave every target the median of the whole map (15.52 m
    against 20, 42 and 55 m); at 201 px a target read 19.9 m instead of 39.75 m."""
    cars = [(-2.5, 20.0), (0.0, 39.75), (2.5, 55.0)]
    est = DepthMapEstimator(CAMERA, sample="window", window_px=window_px)
    out = est.estimate(frame_of(cars, render(cars)))
    np.testing.assert_allclose(out.distance_m, [z for _, z in cars], rtol=1e-6)
    tiny = np.array([[620.2, 200.2, 620.4, 200.4]])  # covers no pixel centre: the nearest one
    depth = np.full((H, W), 30.0, np.float32)
    assert sample_box_depth(depth, tiny, DepthSample.WINDOW, window_px)[0] == 30.0


def test_bad_options_and_depth_size() -> None:
    for kw in (
        {"sample": "middle"},
        {"scaling": "magic"},
        {"window_px": 4},
        {"lower_fraction": 0.0},
    ):
        with pytest.raises(ConfigurationError, match="depthmap"):
            DepthMapEstimator(CAMERA, **kw)  # type: ignore[arg-type]
    with pytest.raises(DataMismatchError, match=r"depth map is 10×5 pixels"):
        DepthMapEstimator(CAMERA).estimate(frame_of(CARS, np.ones((5, 10), np.float32)))


@settings(max_examples=60, deadline=None)
@given(st.floats(5.0, 75.0), st.floats(-4.0, 4.0), st.sampled_from(list(DepthSample)))
def test_any_car_on_a_flat_road(z: float, x: float, sample: DepthSample) -> None:
    depth = render([(x, z)])
    got = sample_box_depth(depth, car_box(x, z)[None], sample)
    assert got[0] == pytest.approx(z, rel=1e-6)


NEAR = [(-3.0, 7.5), (0.0, 9.0), (3.0, 11.0)]


def test_metric_depth_maps_not_in_metres_are_refused() -> None:
    """Millimetre PNGs read as KITTI's metres × 256 are 1000/256 = 3.9 times too far: after
    five targets 3–12 m ahead the run stops, naming the ratio (it was ok at every distance)."""
    est = DepthMapEstimator(CAMERA)
    est.estimate(frame_of(NEAR, render(NEAR) * 1000 / 256, k=0))  # three targets: not yet
    with pytest.raises(DataMismatchError, match=r"3\.91 times the flat-road distance"):
        est.estimate(frame_of(NEAR, render(NEAR) * 1000 / 256, k=1))


def test_true_metric_depth_passes_the_scale_check_and_it_then_rests() -> None:
    est = DepthMapEstimator(CAMERA)
    for k in range(2):
        out = est.estimate(frame_of(NEAR, render(NEAR), k=k))
        np.testing.assert_allclose(out.distance_m, [z for _, z in NEAR], rtol=1e-6)
    out = est.estimate(frame_of(NEAR, 3.0 * render(NEAR), k=2))  # judged once, per sequence
    np.testing.assert_allclose(out.distance_m, [3 * z for _, z in NEAR], rtol=1e-6)
    est.reset()  # a new sequence is judged again
    est.estimate(frame_of(NEAR, 3.0 * render(NEAR), k=0))
    with pytest.raises(DataMismatchError, match="not metres"):
        est.estimate(frame_of(NEAR, 3.0 * render(NEAR), k=1))


def test_far_targets_and_a_scale_less_model_are_not_judged() -> None:
    far = [(-3.0, 20.0), (0.0, 30.0), (3.0, 45.0)]
    est = DepthMapEstimator(CAMERA)
    for k in range(3):  # beyond 12 m the flat-road distance is no reference on a hill
        est.estimate(frame_of(far, 3.0 * render(far), k=k))
    scaled = DepthMapEstimator(CAMERA, scaling="contact")
    for k in range(3):
        out = scaled.estimate(frame_of(NEAR, 0.37 * render(NEAR), k=k))
    np.testing.assert_allclose(out.distance_m, [z for _, z in NEAR], rtol=1e-5)


def test_boxes_the_bottom_border_cuts_are_not_judged_for_the_scale() -> None:
    """A box whose bottom lies within the border tolerance of the image's last row is cut
    (:func:`~slopedist.io.detections.boxes.border_cuts`): its contact distance is no reference.
    The scale check judged boxes up to the last row itself, by its own rule."""
    z = CAMERA.f * CAMERA.height_m / (H - 1.5 - CAMERA.c_y)  # bottom at row 373.5: cut
    cut = [(-3.0, z), (0.0, z), (3.0, z)]
    assert all(car_box(x, zz)[3] == pytest.approx(H - 1.5) for x, zz in cut)
    est = DepthMapEstimator(CAMERA)
    for k in range(3):
        out = est.estimate(frame_of(cut, 3.0 * render(cut), k=k))
    np.testing.assert_allclose(out.distance_m, [3 * z] * 3, rtol=1e-5)
