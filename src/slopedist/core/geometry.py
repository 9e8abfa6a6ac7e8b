"""The paper's equations as pure, vectorised numpy functions (no I/O, no state).

Convention:
    Camera frame x right, y down, z forward. Image rows grow downwards (origin top-left).
    Rotations are 3×3 camera-to-world matrices relative to the first frame, stacked as
    ``(..., 3, 3)``. Angles in radians, rows and focal lengths in pixels, distances in metres.
    Every function broadcasts over leading dimensions (many targets and frames at once).

Equation numbers refer to Back et al., "Improved and efficient inter-vehicle distance estimation
using road gradients of both ego and target vehicles".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.core.errors import ConfigurationError

FloatArray = NDArray[np.float64]

D0_CAM = np.array([0.0, 0.0, 1.0])
"""Driving direction in the camera frame at the reference time, d0 of eq. 3."""


def ground_normal_cam(mount_angle_rad: ArrayLike = 0.0) -> FloatArray:
    """Road-plane normal n0 in the camera frame, eq. 2: ``[0, −cos θ0, −sin θ0]``.

    Points up (−y) for a level camera. Shape ``(..., 3)`` for a mount angle of shape ``(...)``.
    """
    theta0 = np.asarray(mount_angle_rad, dtype=float)
    zero = np.zeros_like(theta0)
    return np.stack([zero, -np.cos(theta0), -np.sin(theta0)], axis=-1)


def relative_rotation(R_prev: ArrayLike, R_curr: ArrayLike) -> FloatArray:
    """Rotation of the current camera frame expressed in the previous one: ``R_prevᵀ · R_curr``.

    Args:
        R_prev, R_curr: camera-to-world rotations ``(..., 3, 3)``.
    """
    R_prev = np.asarray(R_prev, dtype=float)
    R_curr = np.asarray(R_curr, dtype=float)
    return np.swapaxes(R_prev, -1, -2) @ R_curr


def ego_road_gradient(
    R_prev: ArrayLike, R_curr: ArrayLike, mount_angle_rad: ArrayLike = 0.0
) -> FloatArray:
    """Ego road gradient θ from the camera rotations of eq. 2–4, radians.

    ``n = ΔR_prev·n0`` (eq. 2), ``d_ego = ΔR_curr·d0`` (eq. 3), ``θ = π/2 − arccos(nᵀ d_ego)``
    (eq. 4), where ``ΔR_prev`` is the camera-to-world rotation of the frame one look-back
    (1 s) before the current one and ``ΔR_curr`` that of the current frame. Only the relative
    rotation over that interval matters: ``nᵀd = n0ᵀ (ΔR_prevᵀ ΔR_curr) d0``.

    Args:
        R_prev: camera-to-world rotation ``(..., 3, 3)`` at the look-back frame.
        R_curr: camera-to-world rotation ``(..., 3, 3)`` at the current frame.
        mount_angle_rad: θ0, radians, broadcastable to ``(...)``.

    Returns:
        θ in radians, shape ``(...)``; positive when the camera pitched up (nose up) over the
        interval.
    """
    R_prev = np.asarray(R_prev, dtype=float)
    R_curr = np.asarray(R_curr, dtype=float)
    n = np.einsum("...ij,...j->...i", R_prev, ground_normal_cam(mount_angle_rad))
    d_ego = R_curr @ D0_CAM
    cos_angle = np.clip(np.einsum("...i,...i->...", n, d_ego), -1.0, 1.0)
    return np.pi / 2 - np.arccos(cos_angle)


def rest_gradient(mount_angle_rad: ArrayLike = 0.0) -> FloatArray:
    """θ of a camera at rest (no rotation over the look-back), radians: eq. 4 with
    ``ΔR_prev = ΔR_curr = I``, the θ that the mount angle θ0 alone gives (its vanishing line is
    the flat-ground horizon)."""
    return ego_road_gradient(np.eye(3), np.eye(3), mount_angle_rad)


def vanishing_line_row(theta_rad: ArrayLike, f: ArrayLike, c_y: ArrayLike) -> FloatArray:
    """Row of the vanishing line, eq. 5: ``v = c_y − f·tan θ`` (pixels)."""
    return np.asarray(c_y, dtype=float) - np.asarray(f, dtype=float) * np.tan(theta_rad)


def ground_contact_distance(
    f: ArrayLike, height_m: ArrayLike, u: ArrayLike, v: ArrayLike
) -> FloatArray:
    """Ground-contact (pinhole) distance, eq. 1: ``d = f·h / (u − v)``, metres.

    Args:
        f: focal length, pixels.
        height_m: camera height h above the road, metres.
        u: bottom row of the target's 2D box (its ground-contact row), pixels.
        v: row of the vanishing line, pixels.

    Returns:
        Distance in metres; NaN where ``u ≤ v`` (contact at or above the horizon: undefined);
        ``+inf`` where the gap is so small (below ~1e-300 px) that the distance overflows.
    """
    u = np.asarray(u, dtype=float)
    v = np.asarray(v, dtype=float)
    gap = u - v
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        d = np.asarray(f, dtype=float) * np.asarray(height_m, dtype=float) / gap
    return np.where(gap > 0, d, np.nan)


def target_offset_px(b_y: ArrayLike, v: ArrayLike) -> FloatArray:
    """Target gradient test, eq. 6: ``Δy = b_y − v`` (pixels).

    ``b_y`` is the vertical centre of the target's box. Positive when ego and target share a
    plane; shrinks and turns negative as the target climbs.
    """
    return np.asarray(b_y, dtype=float) - np.asarray(v, dtype=float)


@dataclass(frozen=True)
class GradientAdjustment:
    """Parameters of eq. 7: angle steps α1 < α2 < α3 (radians) at row thresholds t1 > t2 > t3 (px).

    Read from the most severe case down: ``Δy < t3 → θ+α3``, ``t3 ≤ Δy ≤ t2 → θ+α2``,
    ``t2 < Δy ≤ t1 → θ+α1``, otherwise θ unchanged. Paper values: 3°, 5°, 6° at 0, −10, −20 px.
    """

    alphas_rad: tuple[float, float, float] = (
        float(np.radians(3.0)),
        float(np.radians(5.0)),
        float(np.radians(6.0)),
    )
    thresholds_px: tuple[float, float, float] = (0.0, -10.0, -20.0)

    def __post_init__(self) -> None:
        """Raises ConfigurationError: not three finite angles and three finite thresholds
        that decrease (a NaN step gave a NaN distance for every box it applied to)."""
        for name in ("alphas_rad", "thresholds_px"):
            values = _three_numbers(name, getattr(self, name))
            object.__setattr__(self, name, values)
        t = self.thresholds_px
        if not (t[0] > t[1] > t[2]):
            raise ConfigurationError(f"eq. 7 thresholds must decrease (t1 > t2 > t3), got {t}")

    @classmethod
    def from_degrees(
        cls,
        alphas_deg: tuple[float, float, float] = (3.0, 5.0, 6.0),
        thresholds_px: tuple[float, float, float] = (0.0, -10.0, -20.0),
    ) -> GradientAdjustment:
        """Build from angles in degrees (the unit of the paper and the command line)."""
        a1, a2, a3 = np.radians(_three_numbers("alphas_deg", alphas_deg)).tolist()
        return cls((a1, a2, a3), thresholds_px)


def _three_numbers(name: str, values: object) -> tuple[float, float, float]:
    """``values`` as three finite floats (:class:`GradientAdjustment`).

    Raises:
        ConfigurationError: anything else.
    """
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        arr = np.empty(0)
    if arr.shape != (3,) or not np.isfinite(arr).all():
        raise ConfigurationError(f"eq. 7 {name} must be three finite numbers, got {values!r}")
    return float(arr[0]), float(arr[1]), float(arr[2])


def adjusted_gradient(
    theta_rad: ArrayLike, delta_y_px: ArrayLike, params: GradientAdjustment = GradientAdjustment()
) -> FloatArray:
    """Per-target adjusted road gradient, eq. 7 (radians).

    Args:
        theta_rad: ego road gradient θ, radians, broadcastable with ``delta_y_px``.
        delta_y_px: Δy of eq. 6 per target, pixels.
        params: α steps and thresholds.
    """
    dy = np.asarray(delta_y_px, dtype=float)
    a1, a2, a3 = params.alphas_rad
    t1, t2, t3 = params.thresholds_px
    alpha = np.select([dy < t3, dy <= t2, dy <= t1], [a3, a2, a1], default=0.0)
    return np.asarray(theta_rad, dtype=float) + alpha


def box_bottom_row(boxes: ArrayLike) -> FloatArray:
    """Ground-contact row u of boxes ``(..., 4)`` given as (left, top, right, bottom) pixels."""
    return np.asarray(boxes, dtype=float)[..., 3]


def box_centre_row(boxes: ArrayLike) -> FloatArray:
    """Vertical centre b_y of boxes ``(..., 4)`` given as (left, top, right, bottom) pixels."""
    b = np.asarray(boxes, dtype=float)
    return 0.5 * (b[..., 1] + b[..., 3])


def rotation_angle_rad(R: ArrayLike) -> FloatArray:
    """Angle of rotation matrices ``(..., 3, 3)``, radians in [0, π], accurate near zero.

    ``atan2(‖axial part‖, tr R − 1)`` rather than ``arccos((tr R − 1) / 2)``: near zero the
    cosine is flat, so ``arccos`` loses about half the significant digits (a 1e-9 rad rotation
    has ``(tr R − 1)/2 = 1 − 5e-19``, which rounds to 1, and reads 0), and it turns a trace error
    δ of a rounded matrix into an angle error δ / sin(angle) (ground-truth files round their
    matrices: KITTI poses keep 7 significant digits, so ``RᵀR`` is off the identity by up to
    ~4e-7, about +0.003° on a 0.2° error), while the axial part ``R − Rᵀ`` is hardly affected.
    """
    R = np.asarray(R, dtype=float)
    axial = np.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]],
        axis=-1,
    )
    return np.asarray(
        np.arctan2(np.linalg.norm(axial, axis=-1), np.trace(R, axis1=-2, axis2=-1) - 1.0)
    )


ROTATION_TOLERANCE = 1e-3
"""How far ``RᵀR`` of a rotation read from a file or given by a caller may be from the identity
(any entry): rounding in written poses, never a scaled or sheared matrix."""


def not_rotations(R: ArrayLike, tol: float = ROTATION_TOLERANCE) -> NDArray[np.bool_]:
    """Which of the matrices ``(..., 3, 3)`` are not rotations: an entry beyond ``1 + tol`` in
    size or not a number, ``RᵀR`` off the identity by more than ``tol`` in some entry, or a
    reflection (``det R < 0``)."""
    R = np.asarray(R, dtype=float)
    beyond = ~(np.abs(R) <= 1.0 + tol).all(axis=(-2, -1))  # no rotation has such entries
    R = np.where(beyond[..., None, None], 0.0, R)  # (NaN, 1e308: no overflow in RᵀR)
    err = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max(axis=(-2, -1))
    return np.asarray(beyond | (err > tol) | (np.linalg.det(R) < 0))
