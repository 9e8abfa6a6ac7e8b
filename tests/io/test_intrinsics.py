"""Boxes of a distorted, non-square-pixel camera mapped into the estimators' ideal pinhole."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist.core.errors import ConfigurationError
from slopedist.io.detections.boxes import BoxTable, box_problems
from slopedist.io.intrinsics import Intrinsics, in_frame_pixels

K = np.array([[700.0, 0.0, 640.0], [0.0, 650.0, 360.0], [0.0, 0.0, 1.0]])
STRONG = np.array([-0.35, 0.12, 0.001, -0.001, -0.02])  # strong barrel distortion
HEIGHT_M = 1.65


def _project(K: np.ndarray, dist: np.ndarray, X: np.ndarray) -> np.ndarray:
    pts, _ = cv2.projectPoints(X.reshape(-1, 3), np.zeros(3), np.zeros(3), K, dist)
    return pts.reshape(-1, 2)


def _ideal(X: np.ndarray, f: float = 650.0) -> np.ndarray:
    return X[:, :2] / X[:, 2:] * f + [640.0, 360.0]


def test_points_match_the_ideal_projection_under_strong_distortion() -> None:
    rng = np.random.default_rng(0)
    X = np.c_[rng.uniform(-8, 8, 300), rng.uniform(-3, 3, 300), rng.uniform(8, 40, 300)]
    cam = Intrinsics(K, STRONG)
    mapped = cam.rectify_points(_project(K, STRONG, X))
    np.testing.assert_allclose(mapped, _ideal(X), atol=1e-4)
    ref = cv2.undistortPoints(
        _project(K, STRONG, X).reshape(-1, 1, 2),
        K,
        STRONG,
        R=np.eye(3),
        P=cam.ideal_K,
        criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12),
    )
    np.testing.assert_allclose(mapped, ref.reshape(-1, 2), atol=1e-6)


def test_fisheye_points() -> None:
    rng = np.random.default_rng(1)
    X = np.c_[rng.uniform(-5, 5, 100), rng.uniform(-2, 2, 100), rng.uniform(5, 30, 100)]
    D = np.array([0.05, -0.01, 0.002, -0.0005])
    distorted, _ = cv2.fisheye.projectPoints(X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, D)
    mapped = Intrinsics(K, D, fisheye=True).rectify_points(distorted.reshape(-1, 2))
    np.testing.assert_allclose(mapped, _ideal(X), atol=1e-4)


def _cuboid(x: float, z: float, w: float = 1.7, h: float = 1.5, length: float = 4.0) -> np.ndarray:
    """Corners of a car standing on a flat road ``HEIGHT_M`` below the camera (y down)."""
    xs, ys, zs = (x - w / 2, x + w / 2), (HEIGHT_M - h, HEIGHT_M), (z, z + length)
    return np.array([[a, b, c] for a in xs for b in ys for c in zs])


def _box(pts: np.ndarray) -> np.ndarray:
    return np.r_[pts.min(axis=0), pts.max(axis=0)]


@pytest.mark.parametrize("z", [10.0, 15.0, 20.0, 30.0, 40.0])  # at 8 m, a lane over: 1.1 %
@pytest.mark.parametrize("x", [-3.5, -1.75, 0.0, 1.75, 3.5])
def test_flat_road_distance_from_mapped_boxes_within_one_percent(x: float, z: float) -> None:
    corners = _cuboid(x, z)
    cam = Intrinsics(K, STRONG)
    distorted_box = _box(_project(K, STRONG, corners))
    mapped = cam.rectify_boxes(distorted_box[None])[0]
    reference = _box(_ideal(corners))
    f, cy = 650.0, 360.0
    distance = f * HEIGHT_M / (mapped[3] - cy)
    expected = f * HEIGHT_M / (reference[3] - cy)
    assert distance == pytest.approx(expected, rel=0.01)
    raw = f * HEIGHT_M / (distorted_box[3] - cy)  # without the mapping
    assert abs(raw / expected - 1) > abs(distance / expected - 1)


def test_non_square_pixels_rescale_columns_exactly() -> None:
    # KITTI 1226×370 stretched to 1920×1080: fx ≠ fy.
    sx, sy = 1920 / 1226, 1080 / 370
    stretched = Intrinsics.from_values(721.5 * sx, 721.5 * sy, 609.6 * sx, 172.9 * sy)
    box = np.array([[500.0, 150.0, 600.0, 250.0]]) * [sx, sy, sx, sy]
    mapped = stretched.rectify_boxes(box)
    f = 721.5 * sy
    expected_u = 609.6 * sx + f * (box[0, [0, 2]] - 609.6 * sx) / (721.5 * sx)
    np.testing.assert_allclose(mapped[0, [0, 2]], expected_u, rtol=1e-9)
    np.testing.assert_allclose(mapped[0, [1, 3]], box[0, [1, 3]], rtol=1e-9)
    cam = stretched.camera(HEIGHT_M)
    assert cam.f == pytest.approx(f) and cam.c_y == pytest.approx(172.9 * sy)
    # the flat-road distance equals that of the unstretched frames
    d_stretched = cam.f * HEIGHT_M / (mapped[0, 3] - cam.c_y)
    assert d_stretched == pytest.approx(721.5 * HEIGHT_M / (250 - 172.9), rel=1e-9)


def test_ideal_intrinsics_leave_boxes_alone_and_table_keeps_columns() -> None:
    cam = Intrinsics.from_values(700, 700, 640, 360)
    assert cam.is_ideal
    table = BoxTable.build([0], [[1, 2, 3, 4]], [5], [0.5], ["Van"], z=[10.0])
    assert cam.rectify_table(table) is table
    moved = Intrinsics(K, STRONG).rectify_table(table)
    assert moved.track_id.tolist() == [5] and list(moved.cls) == ["Van"]
    assert moved.extra["z"].tolist() == [10.0] and not np.allclose(moved.boxes, table.boxes)
    assert in_frame_pixels(moved).boxes.tolist() == [[1, 2, 3, 4]]  # as drawn on the frame
    assert in_frame_pixels(table) is table


@settings(max_examples=40, deadline=None)
@given(
    st.floats(100, 1200),
    st.floats(50, 650),
    st.floats(5, 200),
    st.floats(5, 200),
)
def test_mapped_box_is_valid_or_unmappable(u: float, v: float, w: float, h: float) -> None:
    box = np.array([[u, v, u + w, v + h]])
    mapped = Intrinsics(K, STRONG).rectify_boxes(box)[0]
    assert box_problems(mapped[None])[0] in ("", "non_finite_box")
    if np.all(np.isfinite(mapped)):
        assert mapped[0] < mapped[2] and mapped[1] < mapped[3]


def test_points_the_model_cannot_invert_are_nan() -> None:
    cam = Intrinsics(K, STRONG)
    corner = cam.rectify_points([[1188.5, 50.0], [1188.5, 55.0], [640.0, 360.0]])
    assert np.all(np.isnan(corner[:2])) and np.allclose(corner[2], [640.0, 360.0])
    box = cam.rectify_boxes([[1173.0, 50.0, 1204.0, 55.0]])
    assert box_problems(box)[0] == "non_finite_box"  # estimators record it as missing


@pytest.mark.parametrize(
    ("K_", "dist", "match"),
    [
        (np.eye(2), (), "3×3"),
        (np.diag([0.0, 1.0, 1.0]), (), "focal"),
        (K, (0.1, 0.2, 0.3), "distortion coefficients"),
        (K, (np.nan, 0, 0, 0), "distortion coefficients"),
    ],
)
def test_invalid_intrinsics(K_: np.ndarray, dist: tuple, match: str) -> None:
    with pytest.raises(ConfigurationError, match=match):
        Intrinsics(K_, np.asarray(dist, float))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"K": "abc"}, "camera matrix and distortion must be numbers"),
        ({"K": [[1.0, 2.0], [3.0]]}, "camera matrix and distortion must be numbers"),
        ({"dist": "abc"}, "camera matrix and distortion must be numbers"),
        ({"image_size": (0, -5)}, r"image size must be \(width, height\) in 1..1000000 px"),
        ({"image_size": (1242, 375, 3)}, r"image size must be \(width, height\)"),
        ({"image_size": (1242.5, 375)}, r"image size must be \(width, height\)"),
    ],
)
def test_intrinsics_that_are_not_numbers_or_sizes_are_configuration_errors(
    kwargs: dict[str, object], message: str
) -> None:
    """Text K and distortion failed with numpy's bare ValueError; a size of 0 × −5 px or of
    three values was accepted."""
    values: dict[str, object] = {"K": [[700.0, 0, 600], [0, 700.0, 180], [0, 0, 1]]} | kwargs
    with pytest.raises(ConfigurationError, match=message):
        Intrinsics(**values)  # type: ignore[arg-type]
