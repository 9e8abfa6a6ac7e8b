"""Affine refinement of Lucas–Kanade tracks: the patch may stretch, shear and turn between frames.

OpenCV's pyramidal Lucas–Kanade fits a pure translation of the patch. Ahead of a car driving
forward, the road near the camera grows by 10–30 % from one frame to the next and shears; the
translational fit then lands off the true position by up to a pixel or more, and not at random:
along the flow, so the errors do not average out and bias the rotation fitted to them (a roll
of about 0.01° per frame on a synthetic road, which the frame-to-frame chaining adds up).

:func:`refine_affine` takes each track from where the translational fit put it and fits the six
parameters of an affine warp of the patch of the previous frame, plus a grey-level offset, by
inverse-compositional Gauss–Newton (Baker & Matthews, "Lucas-Kanade 20 years on", 2004): the
template's gradients and Hessians are computed once per track, each iteration costs one bilinear
sampling of the new frame at every track's warped window. A track keeps its translational
position when the affine fit does not converge near it or explains the patch worse.

Convention: pixels ``(x, y)`` with integer coordinates at pixel centres (OpenCV's), float32.
"""

from __future__ import annotations

import functools
from typing import NamedTuple, cast

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]

HALF_WINDOW_PX = 5
"""Half side of the patch fitted (the patch is ``2·5 + 1 = 11`` pixels, Lucas–Kanade's window)."""
ITERATIONS = 3
"""Gauss–Newton iterations."""
MAX_SHIFT_PX = 2.0
"""A refined position farther than this from the translational one is refused, pixels."""
SCALE_RANGE = (0.5, 2.0)
"""Singular values of the fitted 2×2 warp outside this range are refused (a degenerate fit)."""


@functools.lru_cache(maxsize=4)
def _offsets(half: int) -> tuple[F32, F32]:
    """Column and row offsets ``(M,)`` of the pixels of a ``(2·half + 1)²`` window."""
    g = np.arange(-half, half + 1, dtype=np.float32)
    dy, dx = np.meshgrid(g, g, indexing="ij")
    return dx.ravel(), dy.ravel()


@functools.lru_cache(maxsize=4)
def _offset_rows(half: int) -> F32:
    """The window's column and row offsets stacked, ``(2, M)`` (read-only)."""
    rows = np.stack(_offsets(half))
    rows.flags.writeable = False
    return rows


def refine_affine(
    previous: NDArray[np.uint8] | F32,
    current: NDArray[np.uint8] | F32,
    p0: NDArray[np.floating],
    p1: NDArray[np.floating],
    half_window: int = HALF_WINDOW_PX,
    iterations: int = ITERATIONS,
) -> tuple[F32, NDArray[np.bool_]]:
    """Refine the positions ``p1`` in ``current`` of the points ``p0`` of ``previous``.

    Args:
        previous, current: grey frames of one size (uint8, or float32 to skip the conversion).
        p0: ``(N, 2)`` positions in ``previous``, pixels.
        p1: ``(N, 2)`` positions in ``current`` from a translational fit, pixels.
        half_window: half side of the square patch, pixels.
        iterations: Gauss–Newton iterations.

    Returns:
        The refined positions ``(N, 2)`` float32 (``p1`` where refused) and the mask of the
        points whose refinement was accepted.
    """
    p0 = np.asarray(p0, dtype=np.float32).reshape(-1, 2)
    p1 = np.asarray(p1, dtype=np.float32).reshape(-1, 2)
    if len(p0) == 0:
        return p1.copy(), np.zeros(0, dtype=bool)
    prev = np.asarray(previous, dtype=np.float32)
    cur = np.asarray(current, dtype=np.float32)
    template = _template(prev, p0, half_window)
    A, t, sq0 = _gauss_newton(cur, template, p1, iterations)
    e = _residuals(cur, A, t, template.offsets, template.T)
    sq = np.einsum("nm,nm->n", e, e)  # the patch's squared residuals (sq0: at the start)
    ok = (
        np.all(np.isfinite(t), axis=1)
        & np.isfinite(sq)
        & (sq <= sq0)
        & (np.linalg.norm(t - p1, axis=1) < MAX_SHIFT_PX)
        & _warp_in_range(A)
    )
    return np.where(ok[:, None], t, p1).astype(np.float32), ok


class _Template(NamedTuple):
    """The patches of the previous frame, fixed during the fit (``N`` tracks, ``M`` pixels).

    Attributes:
        T: ``(N, M)`` grey levels of each window.
        sd: ``(N, 6, M)`` steepest-descent images of the warp parameters, centred.
        H_inv: ``(N, 6, 6)`` inverse Gauss–Newton Hessians (slightly damped).
        offsets: ``(2, M)`` the window's column and row offsets.
    """

    T: F32
    sd: F32
    H_inv: F32
    offsets: F32


def _template(prev: F32, p0: F32, half_window: int) -> _Template:
    """The windows of ``prev`` around ``p0`` with their steepest-descent images and Hessians."""
    n = len(p0)
    dx, dy = _offsets(half_window)
    # template and its central-difference gradients from one sampling of a window 1 px wider
    ex, ey = _offsets(half_window + 1)
    side = 2 * half_window + 3
    big = _sample(prev, p0[:, 0:1] + ex, p0[:, 1:2] + ey).reshape(n, side, side)
    T = big[:, 1:-1, 1:-1].reshape(n, -1)
    gx = (0.5 * (big[:, 1:-1, 2:] - big[:, 1:-1, :-2])).reshape(n, -1)
    gy = (0.5 * (big[:, 2:, 1:-1] - big[:, :-2, 1:-1])).reshape(n, -1)
    # steepest-descent images of the warp x' = (I + D) x + δ, D row-major, then δ; centred over
    # the window, which leaves a grey-level offset free
    sd = np.empty((n, 6, len(dx)), dtype=np.float32)  # (N, 6, M)
    np.multiply(gx, dx, out=sd[:, 0])
    np.multiply(gx, dy, out=sd[:, 1])
    np.multiply(gy, dx, out=sd[:, 2])
    np.multiply(gy, dy, out=sd[:, 3])
    sd[:, 4] = gx
    sd[:, 5] = gy
    sd -= sd.mean(axis=2, keepdims=True)
    H = np.matmul(sd, sd.transpose(0, 2, 1))
    H += (1e-6 * np.trace(H, axis1=1, axis2=2)[:, None, None] / 6.0 + 1e-9) * np.eye(
        6, dtype=np.float32
    )
    H_inv = cast(F32, np.linalg.inv(H))  # float32, as H
    return _Template(T, sd, H_inv, _offset_rows(half_window))


def _gauss_newton(
    cur: F32, template: _Template, p1: F32, iterations: int
) -> tuple[F32, F32, NDArray[np.float32]]:
    """Inverse-compositional Gauss–Newton from the translational positions ``p1``: the 2×2
    warps ``(N, 2, 2)``, the positions ``(N, 2)`` and the squared residuals at the start."""
    n = len(p1)
    sd, H_inv = template.sd, template.H_inv
    A = np.tile(np.eye(2, dtype=np.float32), (n, 1, 1))
    D_inv = np.empty((n, 2, 2), dtype=np.float32)
    t = p1.copy()
    sq0 = None
    for _ in range(iterations):
        e = _residuals(cur, A, t, template.offsets, template.T)
        if sq0 is None:
            sq0 = np.einsum("nm,nm->n", e, e)
        step = np.matmul(H_inv, np.matmul(sd, e[:, :, None]))[:, :, 0]
        # inverse composition: W ← W ∘ ΔW⁻¹, ΔW(x) = (I + D) x + δ
        D = step[:, :4].reshape(n, 2, 2) + np.eye(2, dtype=np.float32)
        det = D[:, 0, 0] * D[:, 1, 1] - D[:, 0, 1] * D[:, 1, 0]
        det = np.where(np.abs(det) < 1e-6, np.float32(1e-6), det)
        np.divide(D[:, 1, 1], det, out=D_inv[:, 0, 0])
        np.divide(-D[:, 0, 1], det, out=D_inv[:, 0, 1])
        np.divide(-D[:, 1, 0], det, out=D_inv[:, 1, 0])
        np.divide(D[:, 0, 0], det, out=D_inv[:, 1, 1])
        A = A @ D_inv
        t = t - np.matmul(A, step[:, 4:, None])[:, :, 0]
    assert sq0 is not None
    return A, t, sq0


def _warp_in_range(A: F32) -> NDArray[np.bool_]:
    """Whether both singular values of each 2×2 warp ``(N, 2, 2)`` lie within
    ``SCALE_RANGE`` (no degenerate fit)."""
    # s₁² + s₂² = ‖A‖², s₁ s₂ = |det A|
    frob = np.einsum("nij,nij->n", A, A)
    det = np.abs(A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0])
    root = np.sqrt(np.maximum(frob * frob - 4.0 * det * det, 0.0))
    s_max, s_min = np.sqrt(0.5 * (frob + root)), np.sqrt(np.maximum(0.5 * (frob - root), 0.0))
    return np.asarray((s_min > SCALE_RANGE[0]) & (s_max < SCALE_RANGE[1]))


def _sample(image: F32, x: F32, y: F32) -> F32:
    """Bilinear samples of ``image`` at ``(x, y)`` (same shape, 2-D), edges replicated."""
    return np.asarray(
        cv2.remap(image, x, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE), dtype=np.float32
    )


def _residuals(image: F32, A: F32, t: F32, offsets: F32, T: F32) -> F32:
    """``image(W(x)) − T(x)`` over the window (``offsets``: ``(2, M)`` the window's pixels
    ``x``), centred (the grey-level offset removed)."""
    pos = np.matmul(A, offsets)
    pos += t[:, :, None]
    e = _sample(image, pos[:, 0], pos[:, 1]) - T
    e -= e.mean(axis=1, keepdims=True)
    return e
