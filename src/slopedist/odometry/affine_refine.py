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
from typing import NamedTuple

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


@functools.lru_cache(maxsize=4)
def _offset_basis(half: int) -> tuple[F32, NDArray[np.float64]]:
    """The window's ``(M, 3)`` columns ``(dx, dy, 1)`` and ``(M, 6)`` their products
    ``(dx², dx·dy, dx, dy², dy, 1)`` (float64; read-only)."""
    dx, dy = _offsets(half)
    basis = np.stack([dx, dy, np.ones_like(dx)], axis=1)
    b64 = basis.astype(np.float64)
    products = np.stack([b64[:, i] * b64[:, j] for i, j in _BASIS_PAIRS], axis=1)
    basis.flags.writeable = products.flags.writeable = False
    return basis, products


_BASIS_PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
"""The products of the basis columns ``(dx, dy, 1)`` in :func:`_offset_basis`."""

_PARAMETERS = ((0, 0), (0, 1), (1, 0), (1, 1), (0, 2), (1, 2))
"""Each warp parameter's steepest-descent image as ``(gradient, basis column)``: the warp
``x' = (I + D) x + δ`` with ``D`` row-major, then ``δ``; e.g. ``∂/∂D₀₁ = g_x · dy``."""


PRODUCT_ROWS = 128
"""Rows per matrix product with the window's basis: OpenBLAS spreads a product of more than
about 2.6·10⁵ multiply-adds over its threads, which spin waiting for each other when the cores
are busy (with the decoding thread: twice the processor time); 128 rows × 121 pixels × 6
columns stay on one thread."""


def _rows_times(a: NDArray[np.floating], b: NDArray[np.floating]) -> NDArray[np.floating]:
    """``a @ b`` for ``(R, M)`` ``a`` and a small ``(M, K)`` ``b``, :data:`PRODUCT_ROWS` rows
    at a time."""
    if len(a) <= PRODUCT_ROWS:
        return np.asarray(a @ b)
    return np.concatenate([a[i : i + PRODUCT_ROWS] @ b for i in range(0, len(a), PRODUCT_ROWS)])


def _pair(i: int, j: int) -> int:
    return _BASIS_PAIRS.index((min(i, j), max(i, j)))


_HESSIAN_INDEX = np.array(
    [[6 * (ga + gb) + _pair(ba, bb) for gb, bb in _PARAMETERS] for ga, ba in _PARAMETERS]
)
"""Where each Hessian entry ``(6, 6)`` lies among the ``(3, 6)`` sums of gradient products
``(g_x², g_x·g_y, g_y²)`` times basis products (flattened)."""
_MEAN_INDEX = np.array([3 * g + b for g, b in _PARAMETERS])
"""Where each steepest-descent image's sum lies among the ``(2, 3)`` sums of gradients times
basis columns (flattened)."""


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
    e = _residuals(cur, A, t, template)
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
        grad: ``(N, 2, M)`` their x and y gradients; the steepest-descent image of each warp
            parameter is a gradient times a basis column (:data:`_PARAMETERS`).
        H_inv: ``(N, 6, 6)`` inverse Gauss–Newton Hessians of the centred steepest-descent
            images (slightly damped).
        half: half side of the window, pixels.
    """

    T: F32
    grad: F32
    H_inv: F32
    half: int


def _template(prev: F32, p0: F32, half_window: int) -> _Template:
    """The windows of ``prev`` around ``p0`` with their gradients and Hessians."""
    n = len(p0)
    # template and its central-difference gradients from one sampling of a window 1 px wider
    ex, ey = _offsets(half_window + 1)
    side = 2 * half_window + 3
    big = _sample(prev, p0[:, 0:1] + ex, p0[:, 1:2] + ey).reshape(n, side, side)
    T = big[:, 1:-1, 1:-1].reshape(n, -1)
    sides = np.empty((n, 2, side - 2, side - 2), dtype=np.float32)
    np.subtract(big[:, 1:-1, 2:], big[:, 1:-1, :-2], out=sides[:, 0])
    np.subtract(big[:, 2:, 1:-1], big[:, :-2, 1:-1], out=sides[:, 1])
    grad = sides.reshape(n, 2, -1)
    grad *= 0.5
    return _Template(T, grad, _inverse_hessians(grad, half_window), half_window)


def _inverse_hessians(grad: F32, half_window: int) -> F32:
    """``(N, 6, 6)`` inverse Hessians of the warp's steepest-descent images, centred over the
    window (which leaves a grey-level offset free), from the gradients ``(N, 2, M)``: every
    entry is a sum of a gradient product times a product of basis columns, so all of them
    come from one matrix product (float64)."""
    n, m = len(grad), grad.shape[2]
    basis, products = _offset_basis(half_window)
    g = grad.astype(np.float64)
    gg = np.empty((n, 3, m))
    np.multiply(g[:, 0], g[:, 0], out=gg[:, 0])
    np.multiply(g[:, 0], g[:, 1], out=gg[:, 1])
    np.multiply(g[:, 1], g[:, 1], out=gg[:, 2])
    sums = _rows_times(gg.reshape(-1, m), products).reshape(n, 18)
    H = sums[:, _HESSIAN_INDEX]  # Σ s_i s_j
    mean = _rows_times(g.reshape(-1, m), basis).reshape(n, 6)[:, _MEAN_INDEX] / m  # means
    H -= m * mean[:, :, None] * mean[:, None, :]  # centred: Σ (s_i − s̄_i)(s_j − s̄_j)
    H += (1e-6 * np.trace(H, axis1=1, axis2=2)[:, None, None] / 6.0 + 1e-9) * np.eye(6)
    return np.asarray(np.linalg.inv(H), dtype=np.float32)


def _gauss_newton(
    cur: F32, template: _Template, p1: F32, iterations: int
) -> tuple[F32, F32, NDArray[np.float32]]:
    """Inverse-compositional Gauss–Newton from the translational positions ``p1``: the 2×2
    warps ``(N, 2, 2)``, the positions ``(N, 2)`` and the squared residuals at the start."""
    n = len(p1)
    H_inv = template.H_inv
    basis = _offset_basis(template.half)[0]
    A = np.tile(np.eye(2, dtype=np.float32), (n, 1, 1))
    D_inv = np.empty((n, 2, 2), dtype=np.float32)
    t = p1.copy()
    sq0 = None
    for _ in range(iterations):
        e = _residuals(cur, A, t, template)
        if sq0 is None:
            sq0 = np.einsum("nm,nm->n", e, e)
        # the steepest-descent images times the residuals: Σ g e (dx, dy, 1) per gradient
        sd_e = _rows_times((template.grad * e[:, None, :]).reshape(2 * n, -1), basis).reshape(n, 6)
        step = np.matmul(H_inv, sd_e[:, _MEAN_INDEX, None])[:, :, 0]
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


def _residuals(image: F32, A: F32, t: F32, template: _Template) -> F32:
    """``image(W(x)) − T(x)`` over the window (``W(x) = A x + t`` at the window's pixels
    ``x``), centred (the grey-level offset removed)."""
    # positions (2, N, M): x and y of every window, each contiguous for OpenCV
    pos = np.matmul(A.transpose(1, 0, 2), _offset_rows(template.half))
    pos += t.T[:, :, None]
    e = _sample(image, pos[0], pos[1]) - template.T
    e -= e.mean(axis=1, keepdims=True)
    return e
