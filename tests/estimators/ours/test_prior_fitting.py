"""Fitting the priors of ``ours`` (heading mixture, box-edge noise, KITTI 3D-box projection)
against synthetic samples and scenes with known truth."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist.core.errors import ConfigurationError
from slopedist.estimators.ours import cues
from slopedist.estimators.ours.prior_fitting import (
    box_edge_noise_px,
    fit_yaw_prior,
    kitti_heading,
    project_kitti_boxes,
)
from slopedist.estimators.ours.priors import YawPrior, yaw_grid, yaw_prior_weights

F, CX, CY, H_CAM = 721.5, 609.6, 172.9, 1.65
P2 = np.array([[F, 0.0, CX, 0.0], [0.0, F, CY, 0.0], [0.0, 0.0, 1.0, 0.0]])


def test_fit_yaw_prior_recovers_a_known_mixture() -> None:
    rng = np.random.default_rng(3)
    n = 20000
    psi = np.r_[
        rng.normal(0.0, math.radians(1.5), int(0.55 * n)),
        rng.normal(0.0, math.radians(7.0), int(0.20 * n)),
        rng.uniform(-0.5 * np.pi, 0.5 * np.pi, int(0.25 * n)),
    ]
    psi = psi + np.pi * rng.integers(-2, 3, psi.size)  # headings are taken modulo π
    p = fit_yaw_prior(psi)
    assert p.aligned_weight == pytest.approx(0.55, abs=0.03)
    assert math.degrees(p.aligned_sigma_rad) == pytest.approx(1.5, rel=0.08)
    assert p.broad_weight == pytest.approx(0.20, abs=0.04)
    assert math.degrees(p.broad_sigma_rad) == pytest.approx(7.0, rel=0.15)
    assert p.uniform_weight == pytest.approx(0.25, abs=0.03)


def test_fit_yaw_prior_needs_data() -> None:
    with pytest.raises(ConfigurationError, match="at least 10"):
        fit_yaw_prior([0.0, np.nan, 0.1])


def test_yaw_prior_density_and_grid_weights() -> None:
    p = YawPrior()
    x = np.linspace(-0.5 * np.pi, 0.5 * np.pi, 20001)
    dens = p.density(x)
    assert np.trapezoid(dens, x) == pytest.approx(1.0, rel=1e-3)  # a density over π
    w = yaw_prior_weights(yaw_grid(), p)
    assert w.sum() == pytest.approx(1.0)
    # the grid cell of ψ = 0 gets the aligned mass within ±1.75° plus its share of the rest
    assert w[int(np.argmin(np.abs(yaw_grid())))] > p.aligned_weight * 0.7
    uniform = yaw_prior_weights(yaw_grid(), YawPrior(0.0, 0.1, 0.0, 0.1))
    g = np.sort(yaw_grid())
    cells = np.diff(np.r_[g[-1] - np.pi, g, g[0] + np.pi])
    assert uniform == pytest.approx(0.5 * (cells[:-1] + cells[1:]) / np.pi)


def test_yaw_prior_rejects_bad_weights() -> None:
    with pytest.raises(ConfigurationError, match="<= 1"):
        YawPrior(0.8, 0.02, 0.3, 0.1)
    with pytest.raises(ConfigurationError, match="broad_sigma_rad"):
        YawPrior(0.5, 0.02, 0.2, -1.0)


@pytest.mark.parametrize(
    "ry,psi",
    [
        (-0.5 * np.pi, 0.0),
        (0.0, -0.5 * np.pi),
        (0.5 * np.pi, 0.0),
        (-0.5 * np.pi + 0.1, 0.1),
        (0.5 * np.pi - 0.2, -0.2),
    ],
)
def test_kitti_heading_convention(ry: float, psi: float) -> None:
    assert float(kitti_heading(ry)) == pytest.approx(psi, abs=1e-12)


@settings(max_examples=40, deadline=None)
@given(
    x=st.floats(-8.0, 8.0),
    z=st.floats(6.0, 70.0),
    psi_deg=st.floats(-89.0, 89.0),
    h=st.floats(1.3, 2.5),
    w=st.floats(1.5, 2.1),
    ln=st.floats(3.5, 6.0),
)
def test_project_kitti_boxes_agrees_with_the_cues_forward_model(
    x: float, z: float, psi_deg: float, h: float, w: float, ln: float
) -> None:
    # a KITTI label standing on a flat road H_CAM below a level camera: its location is the
    # bottom centre (y = H_CAM), its rotation_y = ψ − π/2 (kitti_heading inverted)
    psi = math.radians(psi_deg)
    dims = np.array([h, w, ln])
    expected = cues.project_box(F, CX, CY, H_CAM, x, z, psi, dims)
    got = project_kitti_boxes(P2, [[x, H_CAM, z]], [dims], [psi - 0.5 * np.pi])[0]
    assert got == pytest.approx(expected, abs=1e-6)
    assert float(kitti_heading(psi - 0.5 * np.pi)) == pytest.approx(
        (psi + 0.5 * np.pi) % np.pi - 0.5 * np.pi, abs=1e-12
    )


def test_project_kitti_boxes_checks_its_input() -> None:
    with pytest.raises(ConfigurationError, match="3x4"):
        project_kitti_boxes(np.eye(3), [[0.0, 1.65, 10.0]], [[1.5, 1.6, 3.9]], [0.0])
    with pytest.raises(ConfigurationError, match="behind the camera"):
        project_kitti_boxes(P2, [[0.0, 1.65, 1.0]], [[1.5, 1.6, 3.9]], [-0.5 * np.pi])


def test_box_edge_noise_is_robust_to_outliers_and_offsets() -> None:
    rng = np.random.default_rng(1)
    ref = rng.uniform(0.0, 1000.0, (5000, 4))
    boxes = ref + rng.normal(0.0, 0.4, ref.shape) + np.array([0.4, 0.0, -0.2, 0.3])
    boxes[:250, 0] += rng.uniform(5.0, 60.0, 250)  # cut by the image border
    assert box_edge_noise_px(boxes, ref) == pytest.approx(0.4, rel=0.06)
    with pytest.raises(ConfigurationError, match="at least 10"):
        box_edge_noise_px(boxes[:5], ref[:5])
    with pytest.raises(ConfigurationError, match=r"\(N, 4\)"):
        box_edge_noise_px(boxes, ref[:, :3])


def test_shipped_defaults_are_the_fit_on_all_shared_sequences(kitti_tracking_dir: Path) -> None:
    from slopedist.estimators.ours import OursAblation, OursConfig
    from slopedist.estimators.ours.prior_fitting import fit_parameters, kitti_tracking_fit_inputs
    from slopedist.io.kitti.tracking import list_sequences

    inputs = [
        kitti_tracking_fit_inputs(kitti_tracking_dir, s) for s in list_sequences(kitti_tracking_dir)
    ]
    assert len(inputs) == 13
    fitted = fit_parameters(inputs)
    cfg = OursConfig()
    assert fitted["yaw_prior"] == OursAblation().yaw_prior
    assert fitted["box_sigma_px"] == cfg.box_sigma_px
    # the labels' 2D boxes are their 3D boxes' projections, to a fraction of a pixel
    assert 0.1 < cfg.box_sigma_px < 1.0
