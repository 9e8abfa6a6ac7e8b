"""Affine refinement of Lucas–Kanade tracks against images warped by known affine maps."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from slopedist.odometry.affine_refine import refine_affine

W, H = 480, 320


def _texture(seed: int = 0) -> NDArray[np.uint8]:
    """Smooth random texture (blurred noise, grey levels 0–255)."""
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal((H, W)).astype(np.float32)
    tex = cv2.GaussianBlur(noise, (0, 0), 2.0)
    tex = (tex - tex.mean()) / tex.std()
    return np.clip(128 + 45 * tex, 0, 255).astype(np.uint8)


def _warped(image: NDArray[np.uint8], M: NDArray[np.float64]) -> NDArray[np.uint8]:
    """``image`` moved by the affine map ``x' = M[:, :2] x + M[:, 2]`` (x shows at x')."""
    return np.asarray(
        cv2.warpAffine(image, M, (W, H), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
    )


def _points() -> NDArray[np.float32]:
    g = np.stack(np.meshgrid(np.arange(120, 361, 40), np.arange(100, 221, 40)), axis=-1)
    return g.reshape(-1, 2).astype(np.float32)


def _klt(
    a: NDArray[np.uint8], b: NDArray[np.uint8], p0: NDArray[np.float32], guess: NDArray[np.float32]
) -> NDArray[np.float32]:
    p1, status, _ = cv2.calcOpticalFlowPyrLK(
        a,
        b,
        p0.reshape(-1, 1, 2),
        guess.reshape(-1, 1, 2),
        winSize=(11, 11),
        maxLevel=3,
        flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
    )
    assert status.all()
    return np.asarray(p1, np.float32).reshape(-1, 2)


@pytest.mark.parametrize("scale,shear", [(1.15, 0.0), (1.25, 0.08), (0.9, -0.05)])
def test_refinement_finds_the_points_of_a_stretched_and_sheared_image(
    scale: float, shear: float
) -> None:
    # the road ahead of a car: the next frame enlarges and shears the patch around each track
    a = _texture()
    c = np.array([W / 2, H / 2])
    L = np.array([[scale, shear], [0.0, scale]])
    M = np.hstack([L, (c - L @ c + np.array([3.3, -1.7]))[:, None]])
    b = _warped(a, M)
    p0 = _points()
    truth = (p0 @ L.T + M[:, 2]).astype(np.float32)
    klt = _klt(a, b, p0, truth + 0.8)
    refined, ok = refine_affine(a, b, p0, klt)
    err_klt = np.linalg.norm(klt - truth, axis=1)
    err = np.linalg.norm(refined - truth, axis=1)
    assert ok.mean() > 0.9
    assert np.median(err) < 0.05
    assert np.median(err) < 0.5 * np.median(err_klt)


def test_a_pure_shift_stays_where_lucas_kanade_put_it() -> None:
    a = _texture(1)
    M = np.array([[1.0, 0.0, 4.25], [0.0, 1.0, -2.5]])
    b = _warped(a, M)
    p0 = _points()
    truth = p0 + np.array([4.25, -2.5], np.float32)
    klt = _klt(a, b, p0, truth + np.float32(0.8))
    refined, _ = refine_affine(a, b, p0, klt)
    err_klt = np.linalg.norm(klt - truth, axis=1)
    err = np.linalg.norm(refined - truth, axis=1)
    assert err_klt.max() < 0.1  # the translational model is right here
    assert err.max() < 0.1 and np.median(err) <= np.median(err_klt) + 0.01


def test_a_refinement_that_does_not_converge_near_the_track_is_refused() -> None:
    # flat patches (no texture): nothing to fit, the translational positions are kept
    a = np.full((H, W), 120, np.uint8)
    b = a.copy()
    p0 = _points()
    p1 = p0 + np.float32(1.0)
    refined, ok = refine_affine(a, b, p0, p1)
    np.testing.assert_array_equal(refined[~ok], p1[~ok])
    assert np.all(np.linalg.norm(refined - p1, axis=1) < 2.0)


def test_no_points() -> None:
    a = _texture()
    refined, ok = refine_affine(a, a, np.empty((0, 2)), np.empty((0, 2)))
    assert refined.shape == (0, 2) and ok.shape == (0,)


def test_many_tracks_refined_at_once_are_refined_as_one_by_one() -> None:
    """The windows of all tracks are sampled and solved together: each track's result does
    not depend on the others."""
    image = _texture(5)
    M = np.array([[1.1, 0.03, -6.0], [-0.02, 1.05, 4.0]])
    moved = _warped(image, M)
    p0 = _points()
    p1 = _klt(image, moved, p0, (p0 @ M[:, :2].T + M[:, 2]).astype(np.float32))
    together, ok = refine_affine(image, moved, p0, p1)
    for i in range(len(p0)):
        alone, ok_i = refine_affine(image, moved, p0[i : i + 1], p1[i : i + 1])
        assert ok_i[0] == ok[i]
        np.testing.assert_allclose(alone[0], together[i], atol=1e-3)
