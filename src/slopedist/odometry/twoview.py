"""Two-view relative rotation from point correspondences: numpy (and OpenCV's small SVD), no I/O,
no state.

Convention:
    Points are given as normalised image coordinates ``x = K⁻¹ [u, v, 1]ᵀ``, shape ``(N, 3)``
    with last column 1 (camera frame x right, y down, z forward). The relative pose maps the
    coordinates of view 1 into view 2: ``X₂ = R·X₁ + t`` (so ``R = R_world_cam2ᵀ · R_world_cam1``
    for camera-to-world rotations), essential matrix ``E = [t]ₓ R`` with ``x₂ᵀ E x₁ = 0``.
    ``t`` is a unit vector (monocular scale is unobservable). Residuals and thresholds are in
    pixels: normalised residuals times the focal length ``f_px``. Angles in radians.

Two models are fitted, both by iteratively reweighted least squares (Cauchy weights) from an
initial rotation, so a good prediction (constant angular velocity) replaces random sampling:

- :func:`fit_rotation_only`: ``x₂ ∝ R x₁`` (no parallax: a standing car, or only far points),
  closed form per iteration (weighted Kabsch on bearing vectors);
- :func:`fit_relative_pose`: the essential matrix with its 5 degrees of freedom, Gauss–Newton on
  the Sampson distance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


_I3 = np.eye(3)
_I3.flags.writeable = False
_RIDGE5 = 1e-12 * np.eye(5)
_RIDGE5.flags.writeable = False


def skew(v: FloatArray) -> FloatArray:
    """Cross-product matrix ``[v]ₓ`` of a 3-vector (``[v]ₓ w = v × w``)."""
    x, y, z = np.asarray(v, dtype=float).tolist()
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def so3_exp(w: FloatArray) -> FloatArray:
    """Rotation matrix of the rotation vector ``w`` (axis × angle, radians), Rodrigues' formula
    ``I + a [w]ₓ + b [w]ₓ²`` with ``[w]ₓ² = w wᵀ − θ² I`` (scalar arithmetic: a 3×3 result
    costs less than numpy calls)."""
    x, y, z = np.asarray(w, dtype=float).tolist()
    angle2 = x * x + y * y + z * z
    angle = math.sqrt(angle2)
    if angle < 1e-8:
        a, b = 1.0, 0.5
    else:
        a, b = math.sin(angle) / angle, (1.0 - math.cos(angle)) / angle2
    bx, by, bz = b * x, b * y, b * z
    ax, ay, az = a * x, a * y, a * z
    return np.array(
        [
            [1.0 + bx * x - b * angle2, bx * y - az, bx * z + ay],
            [bx * y + az, 1.0 + by * y - b * angle2, by * z - ax],
            [bx * z - ay, by * z + ax, 1.0 + bz * z - b * angle2],
        ]
    )


def so3_log(R: FloatArray) -> FloatArray:
    """Rotation vector (axis × angle, radians) of a rotation matrix; inverse of :func:`so3_exp`."""
    R = np.asarray(R, dtype=float)
    cos_angle = float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))
    angle = float(np.arccos(cos_angle))
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-6:
        return 0.5 * v
    if np.pi - angle < 1e-4:  # near π: v is tiny, the axis comes from the symmetric part
        angle = math.atan2(0.5 * float(np.linalg.norm(v)), cos_angle)  # arccos is flat here
        S = 0.5 * (R + R.T) - math.cos(angle) * np.eye(3)  # (1 − cos θ)·a·aᵀ, exactly
        k = int(np.argmax(np.diag(S)))
        axis = S[k] / np.linalg.norm(S[k])
        if axis @ v < 0:
            axis = -axis
        return angle * axis
    return angle / (2.0 * np.sin(angle)) * v


def project_to_rotation(M: FloatArray) -> FloatArray:
    """Nearest rotation matrix (Frobenius norm) to a 3×3 matrix."""
    _, svd_u, svd_vt = cv2.SVDecomp(np.asarray(M, dtype=np.float64))  # 2 against 8 µs (numpy)
    U, Vt = np.asarray(svd_u, dtype=np.float64), np.asarray(svd_vt, dtype=np.float64)
    R = U @ Vt
    if _det3(R) >= 0.0:  # (U · diag(1, 1, 1)) · Vt is U · Vt exactly
        return R
    U[:, 2] = -U[:, 2]  # U · diag(1, 1, −1)
    return U @ Vt


def _det3(M: FloatArray) -> float:
    """Determinant of a 3×3 matrix (cofactor expansion; here only its sign is used)."""
    (a, b, c), (d, e, f), (g, h, i) = M.tolist()
    return float(a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g))


def normalise_pixels(uv: NDArray[np.floating], K: FloatArray) -> FloatArray:
    """Pixels ``(N, 2)`` → normalised homogeneous coordinates ``(N, 3)`` (last column 1)."""
    uv = np.asarray(uv, dtype=float)
    x = np.empty((uv.shape[0], 3))
    x[:, 0] = (uv[:, 0] - K[0, 2]) / K[0, 0]
    x[:, 1] = (uv[:, 1] - K[1, 2]) / K[1, 1]
    x[:, 2] = 1.0
    return x


def cauchy_weights(r: FloatArray, scale: float) -> FloatArray:
    """IRLS weights of the Cauchy loss with the given scale (same unit as ``r``)."""
    w = np.divide(r, scale)
    np.square(w, out=w)
    w += 1.0
    return np.divide(1.0, w, out=w)


def tukey_weights(r: FloatArray, cutoff: float) -> FloatArray:
    """IRLS weights of Tukey's biweight: ``(1 − (r/c)²)²`` inside ``|r| < c``, zero outside."""
    u = np.clip(1.0 - (r / cutoff) ** 2, 0.0, None)
    return u * u


TUKEY_SCALES = 3.0
"""Cut-off of the final Tukey polish, in units of the inlier threshold."""

TUKEY_ITERATIONS = 2
"""Maximum number of Tukey steps after the Cauchy iterations converged."""


@dataclass(frozen=True)
class TwoViewFit:
    """Result of a two-view fit.

    Attributes:
        R: rotation ``(3, 3)`` with ``X₂ = R X₁ + t``.
        t: unit translation direction ``(3,)``; zeros for the rotation-only model.
        inliers: ``(N,)`` bool, correspondences with residual below the inlier threshold.
        residuals_px: ``(N,)`` absolute residuals in pixels (Sampson distance, or the angular
            reprojection error of the rotation-only model, times ``f_px``).
        rotation_only: True for the no-parallax model.
        information: ``(3, 3)`` inverse covariance of the rotation, rad⁻², in the coordinates of
            a right perturbation ``R·exp(ω)`` (translation marginalised; noise level estimated
            from the robustly weighted residuals).
    """

    R: FloatArray
    t: FloatArray
    inliers: BoolArray
    residuals_px: FloatArray
    rotation_only: bool
    information: FloatArray

    @property
    def n_inliers(self) -> int:
        """Number of inlier correspondences."""
        return int(np.count_nonzero(self.inliers))


def _bearings(x: FloatArray) -> FloatArray:
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def rotation_residuals_px(R: FloatArray, b1: FloatArray, b2: FloatArray, f_px: float) -> FloatArray:
    """Chordal distance ``‖b₂ − R b₁‖`` of unit bearings ``(N, 3)``, times ``f_px`` (≈ pixels)."""
    d = b2 - b1 @ R.T
    return np.sqrt(np.einsum("ij,ij->i", d, d)) * f_px


def fit_rotation_only(
    x1: FloatArray,
    x2: FloatArray,
    f_px: float,
    threshold_px: float = 1.0,
    R_init: FloatArray | None = None,
    iterations: int = 6,
) -> TwoViewFit:
    """Rotation ``R`` with ``x₂ ∝ R x₁`` by weighted Kabsch, reweighted with a Cauchy loss.

    Args:
        x1, x2: normalised homogeneous coordinates ``(N, 3)`` of the same points in views 1, 2.
        f_px: focal length, pixels (converts residuals to pixels).
        threshold_px: inlier threshold and Cauchy scale, pixels.
        R_init: optional starting rotation; without it the first iteration weighs all points
            equally.
        iterations: number of reweighting steps.
    """
    b1, b2 = _bearings(x1), _bearings(x2)
    # b₂ᵢ b₁ⱼ per bearing pair: Σ w b₂ b₁ᵀ and b₂ᵀ R b₁ are products with it
    pairs = (b2[:, :, None] * b1[:, None, :]).reshape(len(b1), 9)
    if R_init is None:
        w = np.ones(len(b1))
    else:
        w = cauchy_weights(rotation_residuals_px(R_init, b1, b2, f_px), threshold_px)
    R = np.eye(3) if R_init is None else np.asarray(R_init, dtype=float)
    r = rotation_residuals_px(R, b1, b2, f_px) if iterations < 1 else np.empty(0)
    for _ in range(iterations):
        R = project_to_rotation((w @ pairs).reshape(3, 3))  # R maximises tr(Rᵀ Σ w b₂ b₁ᵀ)
        # ‖b₂ − R b₁‖² = 2 − 2 b₂ᵀ R b₁ for unit bearings
        chord2 = pairs @ R.ravel()
        np.multiply(chord2, -2.0, out=chord2)
        chord2 += 2.0
        r = np.sqrt(np.maximum(chord2, 0.0, out=chord2), out=chord2)
        r *= f_px
        w = cauchy_weights(r, threshold_px)
    # information: Jᵢ = R[b₁]ₓ per bearing, so Σ w JᵀJ = Σ w (I − b₁b₁ᵀ); 2 residual dof per point
    A = np.sum(w) * np.eye(3) - (b1 * w[:, None]).T @ b1
    sigma2 = np.sum(w * (r / f_px) ** 2) / max(2.0 * np.sum(w) - 3.0, 1.0)
    return TwoViewFit(R, np.zeros(3), r < threshold_px, r, True, A / max(sigma2, 1e-16))


def cross3(a: FloatArray, b: FloatArray) -> FloatArray:
    """Row-wise cross product of ``(N, 3)`` arrays (or an ``(N, 3)`` array and a 3-vector)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def _sampson_terms(
    R: FloatArray, t: FloatArray, x1: FloatArray, x2: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """``(R x₁, Eᵀ x₂ = Rᵀ (x₂ × t), algebraic error e, Sampson denominator D)`` per
    correspondence."""
    a = x1 @ R.T  # R x₁
    S = skew(t)
    m = x2 @ S  # x₂ × t (row form: x₂ᵀ [t]ₓ)
    e = np.einsum("ij,ij->i", a, m)  # x₂ᵀ [t]ₓ R x₁ = (R x₁)·(x₂ × t)
    Ex1 = a @ S.T  # E x₁ = t × R x₁ (first two components used)
    Etx2 = m @ R  # Eᵀ x₂ = Rᵀ (x₂ × t)
    D = np.square(Ex1[:, 0])
    D += np.square(Ex1[:, 1])
    D += np.square(Etx2[:, 0])
    D += np.square(Etx2[:, 1])
    return a, Etx2, e, np.maximum(D, 1e-30, out=D)


def sampson_residuals(R: FloatArray, t: FloatArray, x1: FloatArray, x2: FloatArray) -> FloatArray:
    """Signed Sampson distance of ``x₂ᵀ [t]ₓ R x₁ = 0`` per correspondence (normalised units)."""
    _, _, e, D = _sampson_terms(R, t, x1, x2)
    return e / np.sqrt(D)


_SKEW_AXES = np.array(
    [
        [[0.0, 0, 0], [0, 0, -1], [0, 1, 0]],
        [[0, 0, 1], [0, 0, 0], [-1, 0, 0]],
        [[0, -1, 0], [1, 0, 0], [0, 0, 0]],
    ]
)
"""``[e_k]ₓ`` of the three axes ``(3, 3, 3)``: ``[v]ₓ = Σ v_k [e_k]ₓ``."""
_SKEW_AXES.flags.writeable = False

_EPIPOLE_GATHER = np.array(
    [
        [9, 9, 9, 9],
        [9, 9, 9, 9],
        [9, 9, 0, 1],  # x₂₀: (Eᵀ x₂)ₖ += x₂₀ E₀ₖ
        [9, 9, 9, 9],
        [9, 9, 9, 9],
        [9, 9, 3, 4],  # x₂₁
        [0, 3, 9, 9],  # x₁₀: (E x₁)ₖ += Eₖ₀ x₁₀
        [1, 4, 9, 9],  # x₁₁
        [2, 5, 6, 7],  # 1 = x₁₂ = x₂₂
    ]
)
"""Where the entries of ``E`` (flattened; 9: zero) go in the ``(9, 4)`` matrix that takes the
pair products (:func:`pair_products`) to ``((E x₁)₀, (E x₁)₁, (Eᵀ x₂)₀, (Eᵀ x₂)₁)``: the
columns ``6 + j`` of the products are ``x₁ⱼ`` and the columns ``3i + 2`` are ``x₂ᵢ``."""


def pair_products(x1: FloatArray, x2: FloatArray) -> FloatArray:
    """``(N, 9)`` products ``x₂ᵢ x₁ⱼ`` (column ``3i + j``) of homogeneous correspondences
    (last columns 1): a bilinear form ``x₂ᵀ M x₁`` of every correspondence is this times ``M``
    flattened (row-major)."""
    return (x2[:, :, None] * x1[:, None, :]).reshape(len(x1), 9)


def _sampson_system(
    R: FloatArray,
    t: FloatArray,
    products: FloatArray,
    scale: float,
    redescending: bool = False,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Residuals ``r = e/√D`` and Jacobian side by side (``(N, 6)``: ``r``, then the five
    derivatives), weights and the tangent basis of t, from the correspondences'
    :func:`pair_products`.

    Weights are Cauchy's, or with ``redescending`` Tukey's biweight (zero beyond
    ``TUKEY_SCALES × scale``).

    Gauss–Newton with D held fixed within a step (Sampson reweighting). The algebraic error
    ``e = x₂ᵀ E x₁`` (``E = [t]ₓ R``), its derivatives ``x₂ᵀ E [e_k]ₓ x₁`` for ``R ← R·exp(ω)``
    and ``x₂ᵀ [b_k]ₓ R x₁`` along the tangent basis ``b_k`` of t, and the four terms of D are
    all linear in the pair products: one matrix product for every correspondence.
    """
    B = _tangent_basis(t)
    SR = _skews(t, B) @ R  # E = [t]ₓ R, then ∂E/∂b_k = [b_k]ₓ R
    E = SR[0].ravel()
    M = np.empty((9, 10))
    M[:, 0] = E
    M[:, 1:4] = (SR[0] @ _SKEW_AXES).reshape(3, 9).T  # ∂E/∂ω_k = E [e_k]ₓ
    M[:, 4:6] = SR[1:].reshape(2, 9).T
    M[:, 6:] = np.concatenate((E, _ZERO))[_EPIPOLE_GATHER]
    P = products @ M
    D = np.einsum("ij,ij->i", P[:, 6:], P[:, 6:])
    sqrt_D = np.sqrt(np.maximum(D, 1e-30, out=D), out=D)
    rJ = np.divide(P[:, :6], sqrt_D[:, None])
    r = rJ[:, 0]
    w = tukey_weights(r, TUKEY_SCALES * scale) if redescending else cauchy_weights(r, scale)
    return rJ, w, B


_ZERO = np.zeros(1)
_ZERO.flags.writeable = False


def _skews(t: FloatArray, B: FloatArray) -> FloatArray:
    """``[t]ₓ`` and ``[b_k]ₓ`` of the tangent basis' columns, ``(3, 3, 3)``."""
    rows = []
    for x, y, z in (t.tolist(), *B.T.tolist()):
        rows.append([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.array(rows)


def _tangent_basis(t: FloatArray) -> FloatArray:
    """Two unit vectors ``(3, 2)`` orthogonal to the unit vector ``t`` and to each other."""
    x, y, z = np.asarray(t, dtype=float).tolist()
    if abs(x) < 0.9:  # b1 = t × (1, 0, 0)
        n = math.hypot(y, z)
        p, q, s = 0.0 / n, z / n, -y / n
    else:  # b1 = t × (0, 1, 0)
        n = math.hypot(x, z)
        p, q, s = -z / n, 0.0 / n, x / n
    return np.array([[p, y * s - z * q], [q, z * p - x * s], [s, x * q - y * p]])


def translation_given_rotation(
    R: FloatArray, x1: FloatArray, x2: FloatArray, weights: FloatArray | None = None
) -> FloatArray:
    """Unit ``t`` minimising ``Σ w (tᵀ (R x₁ × x₂))²`` (the epipolar constraint is linear in t)."""
    m = cross3(x1 @ R.T, x2)
    if weights is not None:
        m = m * np.sqrt(weights)[:, None]
    _, _, Vt = np.linalg.svd(m.T @ m)
    t = Vt[-1]
    return t if t[2] >= 0 else -t


def epipolar_residuals_px(
    R: FloatArray, x1: FloatArray, x2: FloatArray, f_px: float, scale_px: float = 1.0
) -> FloatArray:
    """Absolute Sampson residuals (pixels) given the rotation, with ``t`` solved robustly.

    The translation direction is the Cauchy-reweighted linear solution given ``R`` (two
    reweightings). Pure rotation gives small residuals for any ``t``, so this also works for a
    standing camera.
    """
    if len(x1) < 3:
        return np.zeros(len(x1))
    t = translation_given_rotation(R, x1, x2)
    for _ in range(2):
        w = cauchy_weights(sampson_residuals(R, t, x1, x2) * f_px, scale_px)
        t = translation_given_rotation(R, x1, x2, w)
    return np.abs(sampson_residuals(R, t, x1, x2)) * f_px


def fit_relative_pose(
    x1: FloatArray,
    x2: FloatArray,
    f_px: float,
    R_init: FloatArray,
    t_init: FloatArray | None = None,
    threshold_px: float = 1.0,
    iterations: int = 6,
    tolerance_rad: float = 5e-5,
) -> TwoViewFit:
    """Relative pose ``(R, t)`` minimising the Cauchy-weighted Sampson distance (Gauss–Newton).

    Local refinement: ``R_init`` must be within a few degrees of the truth (a prediction or the
    rotation-only fit) and ``t_init`` within some tens of degrees; ``t_init`` defaults to the
    weighted linear solution given ``R_init``. For a car, pass the direction of travel turned by
    half the rotation (the chord of the arc, ``R^½ d``): with short baselines or far points the
    Sampson cost is nearly flat along yaw/sideways translation, and the linear solution, pulled
    by outliers, can start the descent in a wrong basin.
    Rotation updates are applied on the right, ``R ← R·exp(ω)``; the translation stays a unit
    vector, updated in its tangent plane.

    Args:
        x1, x2: normalised homogeneous coordinates ``(N, 3)``.
        f_px: focal length, pixels.
        R_init: starting rotation ``(3, 3)``.
        t_init: starting translation direction ``(3,)``.
        threshold_px: inlier threshold and Cauchy scale, pixels.
        iterations: maximum number of Gauss–Newton steps.
        tolerance_rad: stop when no parameter moves more than this (radians).
    """
    R = np.asarray(R_init, dtype=float)
    scale = threshold_px / f_px
    if t_init is None:
        t = translation_given_rotation(R, x1, x2)
        w = cauchy_weights(sampson_residuals(R, t, x1, x2), scale)
        t = translation_given_rotation(R, x1, x2, w)
    else:
        t = np.asarray(t_init, dtype=float) / np.linalg.norm(t_init)
    products = pair_products(x1, x2)
    redescending = False
    for k in range(iterations + TUKEY_ITERATIONS):
        rJ, w, B = _sampson_system(R, t, products, scale, redescending)
        normal = (rJ[:, 1:] * w[:, None]).T @ rJ  # Jᵀ W r, then Jᵀ W J
        delta = -solve_small(normal[:, 1:] + _RIDGE5, normal[:, 0])
        R = R @ so3_exp(delta[:3])
        t = t + B @ delta[3:]
        t /= math.sqrt(float(t @ t))  # = np.linalg.norm(t), bit for bit
        step = float(np.max(np.abs(delta)))
        if not redescending and (step < tolerance_rad or k >= iterations - 1):
            redescending = True  # converged: polish with a loss that ignores gross outliers
        elif redescending and step < tolerance_rad:
            break
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
        return _failed_fit(np.asarray(R_init, dtype=float), len(x1))
    R = project_to_rotation(R)
    rJ, w, _ = _sampson_system(R, t, products, scale, True)
    r, J = rJ[:, 0], rJ[:, 1:]
    A = (J * w[:, None]).T @ J
    try:
        schur = A[:3, :3] - A[:3, 3:] @ np.linalg.solve(A[3:, 3:] + 1e-18 * np.eye(2), A[3:, :3])
    except np.linalg.LinAlgError:  # no weight left (every correspondence an outlier)
        return _failed_fit(R, len(x1))
    sigma2 = np.sum(w * r**2) / max(np.sum(w) - 5.0, 1.0)
    r = np.abs(r) * f_px
    return TwoViewFit(R, t, r < threshold_px, r, False, schur / max(sigma2, 1e-16))


def solve_small(A: FloatArray, b: FloatArray) -> FloatArray:
    """``x`` with ``A x = b`` for a small square ``A`` and a vector ``b`` by OpenCV's LU with
    partial pivoting (the call costs a fifth of ``np.linalg.solve``'s).

    Raises:
        np.linalg.LinAlgError: ``A`` is singular (as ``np.linalg.solve``).
    """
    ok, x = cv2.solve(A, np.asarray(b, dtype=np.float64).reshape(-1, 1), flags=cv2.DECOMP_LU)
    if not ok:
        raise np.linalg.LinAlgError("singular matrix")
    return np.asarray(x, dtype=np.float64).ravel()


def _failed_fit(R: FloatArray, n: int) -> TwoViewFit:
    """A fit that explains nothing: no inliers, infinite residuals, no information."""
    return TwoViewFit(
        R, np.zeros(3), np.zeros(n, dtype=bool), np.full(n, np.inf), False, np.zeros((3, 3))
    )


def rotation_covariance(information: FloatArray, Q: FloatArray) -> FloatArray:
    """Covariance (rad²) of ``R_world_cam`` from a fit's information on ``R_rel = Q``.

    ``R_world_cam = R_ref · R_relᵀ``; a right perturbation ``R_rel·exp(ω)`` is the perturbation
    ``R_world_cam·exp(−Q ω)`` of the output, hence ``Σ = Q Λ⁻¹ Qᵀ``.
    """
    return np.asarray(Q @ np.linalg.inv(information + 1e-12 * np.eye(3)) @ Q.T)


def fuse_rotations(
    R_a: FloatArray, cov_a: FloatArray, R_b: FloatArray, cov_b: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Information-weighted mean of two rotations with covariances of right perturbations."""
    info_a = np.linalg.inv(cov_a + 1e-14 * np.eye(3))
    info_b = np.linalg.inv(cov_b + 1e-14 * np.eye(3))
    info = info_a + info_b
    phi = np.asarray(np.linalg.solve(info, info_b @ so3_log(R_a.T @ R_b)), dtype=np.float64)
    return np.asarray(R_a @ so3_exp(phi)), np.asarray(np.linalg.inv(info))
