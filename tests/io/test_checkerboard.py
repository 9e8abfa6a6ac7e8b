"""Checkerboard calibration on views rendered through a known distorted camera."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import cv2
import numpy as np
import pytest

from slopedist.core.errors import ConfigurationError, DataMismatchError
from slopedist.io.calibration import read_intrinsics
from slopedist.io.checkerboard import calibrate_checkerboard, write_opencv_yaml
from slopedist.io.intrinsics import Intrinsics

W, H = 640, 480
K_TRUE = np.array([[500.0, 0.0, 324.0], [0.0, 484.0, 236.0], [0.0, 0.0, 1.0]])
DIST_TRUE = np.array([-0.28, 0.09, 0.0008, -0.0006, -0.01])
PATTERN, SQUARE_M = (9, 6), 0.05
SUPER = 2  # render at twice the resolution, then average down (anti-aliasing)


@cache
def _rays() -> np.ndarray:
    """Normalised ray (x, y) of every supersampled pixel centre of the distorted camera."""
    u, v = np.meshgrid(np.arange(W * SUPER), np.arange(H * SUPER))
    pix = np.c_[(u.ravel() + 0.5) / SUPER - 0.5, (v.ravel() + 0.5) / SUPER - 0.5]
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    rays = cv2.undistortPoints(pix.reshape(-1, 1, 2), K_TRUE, DIST_TRUE, R=np.eye(3), criteria=crit)
    return np.ascontiguousarray(rays.reshape(-1, 2))


def render(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    """The board (1 square of white margin) seen from pose (rvec, tvec): board → camera."""
    R = cv2.Rodrigues(np.asarray(rvec, float))[0]
    x, y = _rays()[:, 0], _rays()[:, 1]
    s = (R[:, 2] @ tvec) / (x * R[0, 2] + y * R[1, 2] + R[2, 2])  # ray length to the plane
    local = np.empty((len(x), 2))  # board coordinates of the hit, metres: Rᵀ (s·d − t)
    for k in range(2):
        local[:, k] = s * (x * R[0, k] + y * R[1, k] + R[2, k]) - R[:, k] @ tvec
    cell = np.floor(local / SQUARE_M).astype(int)
    cols, rows = PATTERN  # squares -1 … cols-1 (cols+1 of them), a white square of margin
    inside = (cell[:, 0] >= -2) & (cell[:, 0] <= cols) & (cell[:, 1] >= -2)
    inside &= (cell[:, 1] <= rows) & (s > 0)
    margin = (cell[:, 0] == -2) | (cell[:, 0] == cols) | (cell[:, 1] == -2) | (cell[:, 1] == rows)
    white = ((cell[:, 0] + cell[:, 1]) % 2 == 1) | margin
    img = np.where(inside, np.where(white, 230, 20), 120).astype(np.float32)
    img = img.reshape(H * SUPER, W * SUPER)
    small = cv2.resize(img, (W, H), interpolation=cv2.INTER_AREA)
    return np.clip(small, 0, 255).astype(np.uint8)


def _poses(
    n: int, tilt: float = 0.5, seed: int = 3, spread: float = 1.0
) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    centre = np.array([(PATTERN[0] - 1) * SQUARE_M / 2, (PATTERN[1] - 1) * SQUARE_M / 2, 0.0])
    poses = []
    for _ in range(n):
        rvec = np.array(
            [rng.uniform(-tilt, tilt), rng.uniform(-tilt, tilt), rng.uniform(-0.3, 0.3)]
        )
        R = cv2.Rodrigues(rvec)[0]
        z = rng.uniform(0.45, 0.8)
        target = np.array([rng.uniform(-0.5, 0.5) * z, rng.uniform(-0.4, 0.4) * z, z]) * [
            spread,
            spread,
            1,
        ]
        poses.append((rvec, target - R @ centre))
    return poses


def test_recovers_a_known_camera(tmp_path: Path) -> None:
    images = [render(r, t) for r, t in _poses(20)]
    fit = calibrate_checkerboard(images, PATTERN, SQUARE_M)
    assert fit.n_views >= 12 and fit.rms_px < 0.3
    K = fit.intrinsics.K
    for i, j in [(0, 0), (1, 1), (0, 2), (1, 2)]:
        assert K[i, j] == pytest.approx(K_TRUE[i, j], rel=0.005)
    # where the board was seen, undistorted points (each camera's own ideal pinhole) agree
    hull = cv2.convexHull(np.concatenate(fit.corners))
    u, v = np.meshgrid(np.linspace(0, W, 33), np.linspace(0, H, 25))
    pts = [
        (a, b)
        for a, b in zip(u.ravel(), v.ravel())
        if cv2.pointPolygonTest(hull, (a, b), False) >= 0
    ]
    assert len(pts) > 0.6 * u.size
    truth = Intrinsics(K_TRUE, DIST_TRUE).rectify_points(pts)
    assert np.abs(fit.intrinsics.rectify_points(pts) - truth).max() < 0.3
    back = read_intrinsics(write_opencv_yaml(fit, tmp_path / "cam.yaml"))
    np.testing.assert_allclose(back.K, K) and np.testing.assert_allclose(
        back.dist, fit.intrinsics.dist
    )
    assert back.image_size == (W, H)


def test_few_similar_views_warn() -> None:
    images = [render(r, t) for r, t in _poses(4, tilt=0.05, seed=5, spread=0.2)]
    fit = calibrate_checkerboard(images, PATTERN, SQUARE_M)
    text = " ".join(fit.warnings)
    assert "only 4 views" in text and "too similar" in text


def test_views_found_and_views_fitted_are_told_apart() -> None:
    """``max_views`` below the views found: the fit says how many were found and how many it
    fitted, and the warning names the cap, not too few views with the board."""
    images = [render(r, t) for r, t in _poses(20)]
    fit = calibrate_checkerboard(images, PATTERN, SQUARE_M, max_views=5)
    assert fit.n_found >= 12 and fit.n_views == 5
    text = " ".join(fit.warnings)
    assert f"only 5 of the {fit.n_found} views fitted" in text
    assert "with the board found" not in text


def test_errors() -> None:
    blank = np.full((H, W), 128, np.uint8)
    with pytest.raises(DataMismatchError, match="found in 0 of 2 frames"):
        calibrate_checkerboard([blank, blank], PATTERN, SQUARE_M)
    with pytest.raises(DataMismatchError, match="is 10×10"):
        calibrate_checkerboard([blank, np.zeros((10, 10), np.uint8)], PATTERN, SQUARE_M)
    with pytest.raises(ConfigurationError, match="inner corners"):
        calibrate_checkerboard([blank], (1, 5), SQUARE_M)


def test_camera_calibrate_command(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from slopedist.cli import main
    from slopedist.io.calibration import read_calibration

    folder = tmp_path / "frames"
    folder.mkdir()
    for i, (r, t) in enumerate(_poses(6, seed=7, spread=0.5)):
        cv2.imwrite(str(folder / f"{i:04d}.png"), render(r, t))
    out = tmp_path / "cam.yaml"
    code = main(["camera", "calibrate", str(folder), "--pattern", "9x6", "--out", str(out)])
    assert code == 0
    captured = capsys.readouterr()
    assert "RMS reprojection error" in captured.out and "only" in captured.err
    cal = read_calibration(out)
    assert cal.intrinsics.image_size == (W, H)
    assert cal.camera.f == pytest.approx(K_TRUE[1, 1], rel=0.03)
    assert main(["camera", "calibrate", str(folder), "--pattern", "9", "--out", str(out)]) == 2


def test_one_board_pose_does_not_determine_the_focal_length() -> None:
    """A video of the board held still: every view the same pose. It fitted fx = 493 px (truth
    500) with an RMS of 0.03 px and only warned; the focal length is not determined."""
    rvec, tvec = _poses(3, seed=2)[0]
    with pytest.raises(DataMismatchError, match="focal length is not determined"):
        calibrate_checkerboard([render(rvec, tvec)] * 12, PATTERN, SQUARE_M)
