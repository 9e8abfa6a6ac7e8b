"""The paper's equations against hand-computed values and a synthetic scene."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from slopedist.core import geometry as geo
from slopedist.core.errors import ConfigurationError


def rot_x(angle_rad: float) -> np.ndarray:
    """Rotation about the camera x axis; positive = optical axis pitched up (towards −y)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def test_eq1_ground_contact_distance_hand_computed() -> None:
    # 700 px · 1.5 m / (250 − 180) px = 15 m
    assert geo.ground_contact_distance(700.0, 1.5, 250.0, 180.0) == pytest.approx(15.0)


@pytest.mark.parametrize("u", [180.0, 150.0])
def test_eq1_undefined_at_or_above_the_horizon(u: float) -> None:
    assert np.isnan(geo.ground_contact_distance(700.0, 1.5, u, 180.0))


def test_eq1_synthetic_flat_scene_is_exact() -> None:
    f, c_y, h = 721.5, 172.9, 1.65
    z = np.array([3.0, 7.5, 20.0, 55.0, 80.0])
    u = c_y + f * h / z  # contact points on a level road seen by a level camera
    np.testing.assert_allclose(geo.ground_contact_distance(f, h, u, c_y), z, rtol=1e-12)


def test_eq4_no_rotation_gives_zero_gradient() -> None:
    assert geo.ego_road_gradient(np.eye(3), np.eye(3)) == pytest.approx(0.0)


def test_eq4_pitch_up_over_the_interval_gives_that_angle() -> None:
    phi = math.radians(2.0)
    # d_ego = [0, −sin φ, cos φ], n = [0, −1, 0]: nᵀd = sin φ, θ = π/2 − arccos(sin φ) = φ
    assert geo.ego_road_gradient(np.eye(3), rot_x(phi)) == pytest.approx(phi, abs=1e-12)
    # only the relative rotation matters
    R0 = Rotation.from_euler("xyz", [0.3, -0.7, 0.2]).as_matrix()
    assert geo.ego_road_gradient(R0, R0 @ rot_x(phi)) == pytest.approx(phi, abs=1e-12)


def test_eq4_pure_yaw_has_no_gradient() -> None:
    yaw = Rotation.from_euler("y", 25, degrees=True).as_matrix()
    assert geo.ego_road_gradient(np.eye(3), yaw) == pytest.approx(0.0, abs=1e-12)


def test_eq4_mount_angle_at_rest() -> None:
    # n0 = [0, −cos θ0, −sin θ0], d0 = [0, 0, 1]: nᵀd = −sin θ0, θ = −θ0
    assert geo.ego_road_gradient(np.eye(3), np.eye(3), 0.1) == pytest.approx(-0.1)


def test_eq4_vectorised_over_frames() -> None:
    phis = np.radians([-3.0, -0.5, 0.0, 1.0, 4.0])
    R_curr = np.stack([rot_x(p) for p in phis])
    R_prev = np.broadcast_to(np.eye(3), R_curr.shape)
    np.testing.assert_allclose(geo.ego_road_gradient(R_prev, R_curr), phis, atol=1e-12)


def test_eq5_vanishing_line() -> None:
    # 180 − 700 · tan(atan 0.1) = 110
    assert geo.vanishing_line_row(math.atan(0.1), 700.0, 180.0) == pytest.approx(110.0)


def test_eq6_target_offset() -> None:
    assert geo.target_offset_px(120.0, 110.0) == pytest.approx(10.0)
    boxes = np.array([[0.0, 100.0, 10.0, 140.0]])
    assert geo.box_centre_row(boxes)[0] == 120.0
    assert geo.box_bottom_row(boxes)[0] == 140.0


@pytest.mark.parametrize(
    ("delta_y", "alpha_deg"),
    [
        (5.0, 0.0),
        (0.001, 0.0),
        (0.0, 3.0),
        (-5.0, 3.0),
        (-9.99, 3.0),
        (-10.0, 5.0),
        (-15.0, 5.0),
        (-20.0, 5.0),
        (-20.01, 6.0),
        (-300.0, 6.0),
    ],
)
def test_eq7_steps_read_from_the_most_severe_case(delta_y: float, alpha_deg: float) -> None:
    theta = math.radians(0.4)
    adjusted = geo.adjusted_gradient(theta, delta_y)
    assert adjusted == pytest.approx(theta + math.radians(alpha_deg), abs=1e-12)


def test_eq7_configurable() -> None:
    params = geo.GradientAdjustment.from_degrees((1.0, 2.0, 4.0), (5.0, -5.0, -30.0))
    out = geo.adjusted_gradient(0.0, np.array([6.0, 5.0, -5.0, -29.0, -31.0]), params)
    np.testing.assert_allclose(np.degrees(out), [0.0, 1.0, 2.0, 2.0, 4.0])


@given(
    theta=st.floats(-0.2, 0.2),
    delta_y=st.floats(-1e4, 1e4, allow_nan=False),
)
def test_eq7_never_lowers_the_gradient_and_is_bounded(theta: float, delta_y: float) -> None:
    out = float(geo.adjusted_gradient(theta, delta_y))
    assert theta <= out <= theta + math.radians(6.0) + 1e-15


@given(
    u=st.floats(-1e5, 1e5, allow_nan=False),
    v=st.floats(-1e5, 1e5, allow_nan=False),
)
def test_eq1_is_positive_or_missing(u: float, v: float) -> None:
    d = float(geo.ground_contact_distance(721.0, 1.65, u, v))
    assert (math.isnan(d) and u <= v) or (d > 0 and u > v)


@given(st.lists(st.floats(-math.pi, math.pi), min_size=3, max_size=3))
def test_rotation_angle_matches_scipy(angles: list[float]) -> None:
    R = Rotation.from_euler("xyz", angles)
    assert geo.rotation_angle_rad(R.as_matrix()) == pytest.approx(R.magnitude(), abs=1e-6)


@pytest.mark.parametrize("angle", [1e-9, 1e-6])
def test_rotation_angle_of_a_tiny_turn_is_exact(angle: float) -> None:
    """A turn by a about z: R − Rᵀ has axial part (0, 0, 2 sin a) and tr R − 1 = 2 cos a, so
    atan2 gives a to rounding. The cosine form loses it: at 1e-9 rad, cos a = 1 − 5e-19 rounds
    to 1 and arccos reads 0; at 1e-6 it is off by ~4e-5 relative."""
    c, s = math.cos(angle), math.sin(angle)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    assert float(geo.rotation_angle_rad(R)) == pytest.approx(angle, rel=1e-12)
    arccos_form = math.acos(min(1.0, (np.trace(R) - 1.0) / 2.0))
    assert abs(arccos_form - angle) > 1e-6 * angle  # what the atan2 form is guarding against


def test_rotation_angle_of_exact_turns() -> None:
    quarter = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # about y
    assert float(geo.rotation_angle_rad(quarter)) == pytest.approx(math.pi / 2, rel=1e-15)
    assert float(geo.rotation_angle_rad(np.diag([1.0, -1.0, -1.0]))) == pytest.approx(math.pi)
    assert geo.rotation_angle_rad(np.eye(3)) == 0.0
    stacked = geo.rotation_angle_rad(np.stack([np.eye(3), quarter]))
    assert stacked.shape == (2,) and stacked[1] == pytest.approx(math.pi / 2)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"alphas_rad": (math.nan, 0.1, 0.1)}, "alphas_rad must be three finite numbers"),
        ({"alphas_rad": (0.1, 0.1)}, "alphas_rad must be three finite numbers"),
        ({"thresholds_px": ("a", -10.0, -20.0)}, "thresholds_px must be three finite"),
        ({"thresholds_px": (0.0, 0.0, -20.0)}, "thresholds must decrease"),
    ],
)
def test_gradient_adjustment_checks_its_parameters(kwargs: dict, message: str) -> None:
    """A NaN step was accepted (NaN distances), two steps failed later with a bare
    IndexError, thresholds that do not decrease were only refused by EstimatorConfig."""
    with pytest.raises(ConfigurationError, match=message):
        geo.GradientAdjustment(**kwargs)


def test_gradient_adjustment_from_degrees_refuses_two_thresholds() -> None:
    """It failed with a bare IndexError."""
    with pytest.raises(ConfigurationError, match="thresholds_px must be three finite"):
        geo.GradientAdjustment.from_degrees((3.0, 5.0, 6.0), (0.0, -10.0))  # type: ignore[arg-type]


@pytest.mark.parametrize("mount_angle_rad", [0.0, 0.02, -0.035])
def test_rest_gradient_is_minus_the_mount_angle(mount_angle_rad: float) -> None:
    """By hand: n0 = [0, −cos θ0, −sin θ0], d0 = [0, 0, 1], so n0ᵀd0 = −sin θ0 and
    θ = π/2 − arccos(−sin θ0) = −θ0."""
    assert geo.rest_gradient(mount_angle_rad) == pytest.approx(-mount_angle_rad, abs=1e-12)


def test_a_matrix_of_huge_entries_is_no_rotation_and_warns_of_nothing() -> None:
    """A pose of 1e308 read from a file was refused only after a numpy overflow warning."""
    import warnings

    R = np.eye(3)
    R[0, 0] = 1e308
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        assert geo.not_rotations(R) and geo.not_rotations(np.full((3, 3), np.nan))
        assert not geo.not_rotations(np.eye(3))
