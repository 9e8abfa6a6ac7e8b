"""The cues of ``ours`` against synthetic scenes: project a known 3D box, recover its distance."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from slopedist.estimators.ours import cues, fusion, occlusion
from slopedist.estimators.ours.priors import (
    CLASS_PRIORS,
    UNKNOWN_CLASS_PRIOR,
    YawPrior,
    prior_for,
    priors_for,
    yaw_grid,
    yaw_prior_weights,
)

F, CX, CY, H_CAM = 721.5, 609.6, 172.9, 1.65
CAR = np.array([1.53, 1.63, 3.88])
VAN_TALL = np.array([2.4, 1.9, 5.0])  # roof above the camera


def _box(
    x: float, z: float, yaw_deg: float, dims: np.ndarray, v: float = CY, h: float = H_CAM
) -> np.ndarray:
    return cues.project_box(F, CX, v, h, x, z, math.radians(yaw_deg), dims)


def test_project_box_centre_on_axis_is_symmetric_and_bottom_is_eq1() -> None:
    b = _box(0.0, 20.0, 0.0, CAR)
    assert b[0] - CX == pytest.approx(CX - b[2])
    # bottom row = nearest bottom edge: f·h/(Z − L/2) below the horizon (eq. 1 inverted)
    assert b[3] == pytest.approx(CY + F * H_CAM / (20.0 - CAR[2] / 2))
    # top row = farthest roof edge (roof below the camera)
    assert b[1] == pytest.approx(CY + F * (H_CAM - CAR[0]) / (20.0 + CAR[2] / 2))


@pytest.mark.parametrize("dims", [CAR, VAN_TALL])
@pytest.mark.parametrize(
    "x,z,yaw", [(0.0, 8.0, 0.0), (-4.5, 20.0, -31.0), (6.0, 45.0, 12.0), (2.0, 70.0, 90.0)]
)
def test_height_cue_recovers_the_centre_distance(
    dims: np.ndarray, x: float, z: float, yaw: float
) -> None:
    b = _box(x, z, yaw, dims)
    e = cues.depth_half_extent(math.radians(yaw), dims[1], dims[2])
    z_hat, dz_dD, dz_dH, _, _ = cues.height_cue(b[1], b[3], F, H_CAM, dims[0], e)
    assert z_hat == pytest.approx(z, rel=1e-9)
    # a taller vehicle of the same box is farther; a taller box is nearer
    assert dz_dH > 0 and dz_dD < 0


def test_height_cue_derivatives_match_finite_differences() -> None:
    b = _box(1.0, 25.0, 5.0, CAR)
    e = cues.depth_half_extent(math.radians(5.0), CAR[1], CAR[2])
    z0, dD, dH, de, dh = cues.height_cue(b[1], b[3], F, H_CAM, CAR[0], e)
    eps = 1e-6
    assert (cues.height_cue(b[1], b[3] + eps, F, H_CAM, CAR[0], e)[0] - z0) / eps == pytest.approx(
        dD, rel=1e-4
    )
    assert (cues.height_cue(b[1], b[3], F, H_CAM, CAR[0] + eps, e)[0] - z0) / eps == pytest.approx(
        dH, rel=1e-4
    )
    assert (cues.height_cue(b[1], b[3], F, H_CAM, CAR[0], e + eps)[0] - z0) / eps == pytest.approx(
        de, rel=1e-4
    )
    assert (cues.height_cue(b[1], b[3], F, H_CAM + eps, CAR[0], e)[0] - z0) / eps == pytest.approx(
        dh, rel=1e-4
    )


def test_height_cue_of_a_degenerate_box_is_nan() -> None:
    z = cues.height_cue(100.0, 100.0, F, H_CAM, 1.5, 2.0)[0]
    assert np.isnan(z)


@pytest.mark.parametrize(
    "x,z,yaw",
    [
        (0.0, 10.0, 0.0),
        (-4.5, 20.0, -31.0),
        (8.0, 30.0, 7.0),
        (-3.0, 60.0, 60.0),
        (5.0, 15.0, 90.0),
    ],
)
def test_width_cue_recovers_the_distance_at_the_true_heading(
    x: float, z: float, yaw: float
) -> None:
    b = _box(x, z, yaw, CAR)
    z_hat, dz_dcol, share_w = cues.width_cue(b[0], b[2], F, CX, math.radians(yaw), CAR[1], CAR[2])
    assert z_hat == pytest.approx(z, rel=1e-12)
    assert dz_dcol > 0 and 0.0 <= share_w <= 1.0


def test_width_cue_share_and_scaling() -> None:
    """Z is linear in (W, L) for given extreme corners: scaling both scales Z."""
    b = _box(-3.0, 25.0, 20.0, CAR)
    z1, _, share = cues.width_cue(b[0], b[2], F, CX, math.radians(20.0), CAR[1], CAR[2])
    z2 = cues.width_cue(b[0], b[2], F, CX, math.radians(20.0), 1.1 * CAR[1], 1.1 * CAR[2])[0]
    assert z2 == pytest.approx(1.1 * z1, rel=1e-9)
    z3 = cues.width_cue(b[0], b[2], F, CX, math.radians(20.0), 1.001 * CAR[1], CAR[2])[0]
    assert math.log(z3 / z1) / math.log(1.001) == pytest.approx(share, rel=1e-3)


def test_width_cue_at_a_wrong_heading_misses() -> None:
    b = _box(0.0, 30.0, 25.0, CAR)
    z0 = cues.width_cue(b[0], b[2], F, CX, 0.0, CAR[1], CAR[2])[0]
    assert z0 < 0.8 * 30.0  # the side of a turned car makes the box wider: looks nearer


@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(-10, 10),
    z=st.floats(6, 80),
    yaw=st.floats(-89, 89),
    h=st.floats(1.0, 2.5),
    w=st.floats(1.4, 2.2),
    length=st.floats(3.0, 6.0),
)
def test_height_cue_inverts_the_projection(
    x: float, z: float, yaw: float, h: float, w: float, length: float
) -> None:
    dims = np.array([h, w, length])
    e = cues.depth_half_extent(math.radians(yaw), w, length)
    if z - e < 1.0:
        return
    b = _box(x, z, yaw, dims)
    assert cues.height_cue(b[1], b[3], F, H_CAM, h, e)[0] == pytest.approx(z, rel=1e-7)


def test_ground_contact_cue_recovers_distance_with_the_right_horizon() -> None:
    theta = math.radians(1.5)  # the target's road, 1.5° above the ego's
    v = CY - F * math.tan(theta)
    b = _box(2.0, 30.0, 0.0, CAR, v=v)
    assert cues.ground_contact_cue(b[3], v, F, H_CAM, CAR[2] / 2) == pytest.approx(30.0)
    flat = cues.ground_contact_cue(b[3], CY, F, H_CAM, CAR[2] / 2)
    assert flat > 30.0  # ignoring the climb overestimates, as the paper says
    assert np.isnan(cues.ground_contact_cue(CY - 1.0, CY, F, H_CAM, 2.0))


def test_ground_contact_sigma_grows_with_the_square_of_distance() -> None:
    s10 = cues.ground_contact_sigma(10.0, F, H_CAM, 1.0, 0.0)
    s40 = cues.ground_contact_sigma(40.0, F, H_CAM, 1.0, 0.0)
    assert s40 / s10 == pytest.approx(16.0)
    assert s10 == pytest.approx(100.0 / (F * H_CAM))
    # an angle error of σθ moves the contact row by f·σθ
    assert cues.ground_contact_sigma(10.0, F, H_CAM, 0.0, 0.01) == pytest.approx(
        100.0 / (F * H_CAM) * F * 0.01
    )


def test_ground_contact_log_cue_variance_matches_the_metric_sigma() -> None:
    b = _box(0.0, 25.0, 0.0, CAR)
    e = CAR[2] / 2
    cue = cues.ground_contact_log_cue(b[3], CY, F, H_CAM, e, 4.0, 0.0)
    near = 25.0 - e
    sigma_m = cues.ground_contact_sigma(near, F, H_CAM, 2.0, 0.0)
    assert math.exp(cue.mean) == pytest.approx(25.0)
    assert math.sqrt(cue.var) == pytest.approx(sigma_m / 25.0, rel=1e-6)
    assert cue.var_white == pytest.approx(cue.var)


def test_size_fusion_is_exact_for_a_vehicle_of_prior_size() -> None:
    x, z, yaw = -2.0, 35.0, 0.0
    b = _box(x, z, yaw, CAR)
    e = CAR[2] / 2
    zh, _, dH, _, _ = cues.height_cue(b[1], b[3], F, H_CAM, CAR[0], e)
    zw, _, share = cues.width_cue(b[0], b[2], F, CX, 0.0, CAR[1], CAR[2])
    c_h = dH * CAR[0] / zh
    out = fusion.fuse_size_cues(
        cues.SizeCue(math.log(zh), c_h, 1e-4, 0.0),
        cues.SizeCue(math.log(zw), share, 1e-4, 0.0),
        0.085,
        0.06,
        0.3,
    )
    assert math.exp(out.mean) == pytest.approx(z, rel=1e-6)
    # no width: the height cue alone, with the prior's spread
    alone = fusion.fuse_size_cues(
        cues.SizeCue(math.log(zh), c_h, 1e-4, 0.0),
        cues.SizeCue(np.nan, np.nan, np.nan, np.nan),
        0.085,
        0.06,
        0.3,
    )
    assert alone.mean == pytest.approx(math.log(zh))
    assert alone.var == pytest.approx((c_h * 0.085) ** 2 + 1e-4)
    assert out.var < alone.var


def test_size_fusion_splits_a_size_surprise_between_the_cues() -> None:
    """A low car (height 1.3 m, prior 1.53 m) seen from behind: the height cue says far, the
    width cue is right; the fused distance lies between, nearer the better-known width."""
    dims = np.array([1.30, 1.63, 3.88])
    b = _box(0.0, 40.0, 0.0, dims)
    e = CAR[2] / 2
    zh, _, dH, _, _ = cues.height_cue(b[1], b[3], F, H_CAM, CAR[0], e)
    zw, _, share = cues.width_cue(b[0], b[2], F, CX, 0.0, CAR[1], CAR[2])
    out = fusion.fuse_size_cues(
        cues.SizeCue(math.log(zh), dH * CAR[0] / zh, 1e-4, 0.0),
        cues.SizeCue(math.log(zw), share, 1e-4, 0.0),
        0.085,
        0.06,
        0.3,
    )
    assert zw < math.exp(out.mean) < zh
    assert abs(math.exp(out.mean) - 40.0) < abs(zh - 40.0)


def test_target_gradient_recovers_a_climbing_target() -> None:
    for alpha_deg in (-2.0, 0.0, 3.0, 6.0):
        alpha = math.radians(alpha_deg)
        v_target = CY - F * math.tan(alpha)
        z = 30.0
        b = _box(0.0, z, 0.0, CAR, v=v_target)
        delta_y = 0.5 * (b[1] + b[3]) - CY  # eq. 6 against the ego's horizon (θ = 0)
        est = cues.target_gradient(delta_y, z, F, H_CAM, CAR[0], CAR[2] / 2)
        assert est == pytest.approx(alpha, abs=1e-3)


def test_priors_lookup_and_yaw_prior() -> None:
    assert prior_for("Car") is CLASS_PRIORS["Car"]
    assert prior_for("van") is CLASS_PRIORS["Van"]
    assert prior_for("Misc") is UNKNOWN_CLASS_PRIOR
    arr = priors_for(np.array(["Car", "Pedestrian", "Whatever"], dtype=object))
    assert arr.height_m.tolist() == [1.53, 1.76, UNKNOWN_CLASS_PRIOR.height_m]
    g = yaw_grid()
    w = yaw_prior_weights(g, YawPrior(0.75, math.radians(3.0)))
    assert w.sum() == pytest.approx(1.0)
    assert int(np.argmax(w)) == int(np.argmin(np.abs(g)))
    uniform = yaw_prior_weights(g, YawPrior(0.0, math.radians(3.0)))
    # uniform prior: each hypothesis gets the share of the circle its cell covers
    assert uniform.sum() == pytest.approx(1.0) and np.all(uniform > 0)


@settings(max_examples=40, deadline=None)
@given(
    x=st.floats(-10, 10),
    z=st.floats(6, 80),
    yaw=st.floats(-89, 89),
    h=st.floats(1.3, 2.6),
    sigma=st.floats(0.1, 2.0),
)
def test_height_cue_log_is_height_cue_in_log_form(
    x: float, z: float, yaw: float, h: float, sigma: float
) -> None:
    dims = np.array([h, 1.7, 4.2])
    b = _box(x, z, yaw, dims)
    e = float(cues.depth_half_extent(math.radians(yaw), dims[1], dims[2]))
    var_e = 0.02
    z_ref, dD, dH, de, dh = cues.height_cue(b[1], b[3], F, H_CAM, h, e)
    got = cues.height_cue_log(
        np.array([[b[3] - b[1]]]),
        F,
        H_CAM,
        sigma,
        0.05,
        np.array([[h]]),
        np.array([[e]]),
        np.array([[var_e]]),
    )
    assert got.mean[0, 0] == pytest.approx(math.log(z), abs=1e-9)
    assert got.lever[0, 0] == pytest.approx(dH * h / z_ref, rel=1e-9)
    assert got.var_white[0, 0] == pytest.approx(2 * (dD * sigma / z_ref) ** 2, rel=1e-9)
    assert got.var_other[0, 0] == pytest.approx(
        (de**2 * var_e + (dh * 0.05) ** 2) / z_ref**2, rel=1e-9
    )


@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(-12, 12),
    z=st.floats(3, 80),
    yaw=st.floats(-89.9, 89.9),
    w=st.floats(1.4, 2.5),
    ln=st.floats(3.0, 12.0),
)
def test_width_cue_inverts_the_projection_near_and_far(
    x: float, z: float, yaw: float, w: float, ln: float
) -> None:
    dims = np.array([1.5, w, ln])
    assume(z - 0.5 * math.hypot(w, ln) > 1.0)  # every corner at least 1 m in front
    b = _box(x, z, yaw, dims)
    z_hat, dz_dcol, share = cues.width_cue(b[0], b[2], F, CX, math.radians(yaw), w, ln)
    assert z_hat == pytest.approx(z, rel=1e-9)
    # the noise gain against a finite difference of both edges
    eps = 1e-4
    zl = cues.width_cue(b[0] + eps, b[2], F, CX, math.radians(yaw), w, ln)[0]
    zr = cues.width_cue(b[0], b[2] + eps, F, CX, math.radians(yaw), w, ln)[0]
    assert dz_dcol == pytest.approx(math.hypot(zl - z_hat, zr - z_hat) / eps, rel=1e-3)
    assert 0.0 <= share <= 1.0


def test_width_cue_log_is_the_width_cue_in_log_form() -> None:
    rng = np.random.default_rng(4)
    n = 40
    grid = yaw_grid()
    x, z = rng.uniform(-10, 10, n), rng.uniform(5, 70, n)
    b = cues.project_box(F, CX, CY, H_CAM, x, z, rng.uniform(-0.3, 0.3, n), CAR)
    left, right = (np.repeat(b[:, k : k + 1], grid.size, axis=1) for k in (0, 2))
    z_ref, dcol, share = cues.width_cue(left, right, F, CX, grid, CAR[1], CAR[2])
    min_depth = np.full((n, grid.size), 2.4)
    z_ref = np.maximum(z_ref, min_depth)
    half = [
        np.broadcast_to(0.5 * d * fn(grid), (n, grid.size))
        for d, fn in ((CAR[1], np.cos), (CAR[1], np.sin), (CAR[2], np.cos), (CAR[2], np.sin))
    ]
    got = cues.width_cue_log(left, right, F, CX, 0.7, *half, min_depth)
    np.testing.assert_allclose(got.mean, np.log(z_ref), atol=1e-12)
    np.testing.assert_allclose(got.lever, share, atol=1e-12)
    np.testing.assert_allclose(got.var_white, (dcol * 0.7 / z_ref) ** 2, rtol=1e-9)


def test_hidden_sides_flags_the_sides_on_a_nearer_box() -> None:
    far = [600.0, 170.0, 660.0, 200.0]  # behind: its right side and bottom on the near box
    near = [650.0, 165.0, 760.0, 240.0]  # bottom lower: nearer
    alone = [100.0, 170.0, 150.0, 200.0]
    width_cut, height_cut = occlusion.hidden_sides(np.array([far, near, alone]), tol_px=1.0)
    assert width_cut.tolist() == [True, False, False]
    assert height_cut.tolist() == [True, False, False]
    beside = [500.0, 170.0, 649.5, 200.0]  # its right edge 0.5 px from the near box: touching
    width_cut, _ = occlusion.hidden_sides(np.array([beside, near]), tol_px=1.0)
    assert width_cut.tolist() == [True, False]
    width_cut, _ = occlusion.hidden_sides(np.array([beside, near]), tol_px=0.1)
    assert width_cut.tolist() == [False, False]
    top_on = [700.0, 200.0, 740.0, 230.0]  # its top edge inside the near box, bottom below
    _, height_cut = occlusion.hidden_sides(np.array([top_on, [690.0, 150.0, 760.0, 235.0]]))
    assert height_cut.tolist() == [True, False]


def test_a_box_bottom_exactly_on_the_horizon_gives_nan_without_a_warning() -> None:
    """A bottom row exactly on the vanishing line divided by a zero gap: NaN as intended, but
    with numpy's "divide by zero" RuntimeWarning on every such frame (an error under
    ``python -W error``)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cue = cues.ground_contact_log_cue(
            np.array([CY, CY + 20.0, CY - 3.0]), CY, F, H_CAM, 2.0, 1.0, 0.0
        )
    assert np.isnan(cue.mean[[0, 2]]).all() and np.isfinite(cue.mean[1])
