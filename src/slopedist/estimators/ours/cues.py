"""The distance cues of ``ours`` as pure, vectorised functions (no state, no I/O).

Convention:
    Camera frame x right, y down, z forward; image rows grow downwards. A target is a 3D box
    standing on its road: ``Z`` is the depth (camera z) of its centre, which is what KITTI labels
    give as ``z``; its heading ψ is the angle of its length axis from the camera's z axis,
    positive towards +x (ψ and ψ + π look the same in a box). Distances in metres, rows and
    columns in pixels, angles in radians. Every function broadcasts over leading dimensions
    (targets × heading hypotheses).

The 2D box of a 3D box seen by a level pinhole camera at height ``h`` over the target's road:

* its bottom row is the nearest bottom corner, ``b = v + f·h/(Z − e)``,
* its top row is the farthest top corner when the roof is below the camera
  (``t = v + f·(h − H)/(Z + e)``) and the nearest one otherwise,
* its left and right columns are the extreme corners in x/z,

where ``v`` is the row of the target road's horizon and ``e`` the box's half extent in depth.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.estimators.ours.fusion import LogCue

FloatArray = NDArray[np.float64]

_CORNER_L = np.array([0.5, 0.5, -0.5, -0.5])
_CORNER_W = np.array([0.5, -0.5, -0.5, 0.5])


def depth_half_extent(yaw_rad: ArrayLike, width_m: ArrayLike, length_m: ArrayLike) -> FloatArray:
    """Half the depth extent ``e`` of a box footprint at heading ψ: ``(L|cos ψ| + W|sin ψ|)/2``."""
    psi = np.asarray(yaw_rad, dtype=float)
    return np.asarray(
        0.5
        * (np.asarray(length_m) * np.abs(np.cos(psi)) + np.asarray(width_m) * np.abs(np.sin(psi)))
    )


def footprint_corners(
    yaw_rad: ArrayLike, width_m: ArrayLike, length_m: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Offsets ``(dx, dz)`` of the four footprint corners from the box centre, shape ``(..., 4)``.

    The length axis points along ``(sin ψ, cos ψ)`` in (x, z), the width axis along
    ``(cos ψ, −sin ψ)``.
    """
    psi = np.asarray(yaw_rad, dtype=float)[..., None]
    half_l = np.asarray(length_m, dtype=float)[..., None] * _CORNER_L
    half_w = np.asarray(width_m, dtype=float)[..., None] * _CORNER_W
    s, c = np.sin(psi), np.cos(psi)
    return half_l * s + half_w * c, half_l * c - half_w * s


def project_box(
    f: float,
    c_x: float,
    v: ArrayLike,
    cam_height_m: ArrayLike,
    x_m: ArrayLike,
    z_m: ArrayLike,
    yaw_rad: ArrayLike,
    dims_hwl_m: ArrayLike,
) -> FloatArray:
    """2D box ``(left, top, right, bottom)`` of a 3D box standing on a flat road (pixels).

    The forward model the cues invert (and the tests check them against).

    Args:
        f, c_x: focal length and principal-point column, pixels.
        v: horizon row of the road the target stands on, pixels.
        cam_height_m: camera height above that road, metres.
        x_m, z_m: lateral position and depth of the box centre, metres.
        yaw_rad: heading ψ.
        dims_hwl_m: ``(..., 3)`` height, width, length, metres.
    """
    dims = np.asarray(dims_hwl_m, dtype=float)
    dx, dz = footprint_corners(yaw_rad, dims[..., 1], dims[..., 2])
    xc = np.asarray(x_m, dtype=float)[..., None] + dx
    zc = np.asarray(z_m, dtype=float)[..., None] + dz
    h = np.asarray(cam_height_m, dtype=float)[..., None]
    cols = c_x + f * xc / zc
    v_ = np.asarray(v, dtype=float)
    bottom = v_ + f * np.max(h / zc, axis=-1)
    top = v_ + f * np.min((h - dims[..., 0:1]) / zc, axis=-1)
    return np.stack([cols.min(axis=-1), top, cols.max(axis=-1), bottom], axis=-1)


def height_cue(
    top: ArrayLike,
    bottom: ArrayLike,
    f: float,
    cam_height_m: ArrayLike,
    height_m: ArrayLike,
    half_extent_m: ArrayLike,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Distance from the box height ``D = b − t`` and the target's height H (size cue, eq. S1).

    Independent of the horizon: with ``d = D/f``, a roof below the camera (h ≥ H) gives
    ``d·(Z² − e²) = H·Z + e·(2h − H)``, solved for the positive root; a roof above it gives
    ``Z = H/d + e``.

    Returns:
        ``(Z, dZ/dD, dZ/dH, dZ/de, dZ/dh)``: the centre depth (m) and its partial derivatives
        with respect to the box height (m/px), the target height, the half extent and the camera
        height (m/m). ``Z`` is NaN where ``D ≤ 0``.
    """
    D = np.asarray(bottom, dtype=float) - np.asarray(top, dtype=float)
    H = np.asarray(height_m, dtype=float)
    e = np.asarray(half_extent_m, dtype=float)
    h = np.asarray(cam_height_m, dtype=float)
    d = np.where(D > 0, D, np.nan) * (1.0 / f)  # NaN propagates to every output
    d2 = 2.0 * d
    two_h_minus_H = 2.0 * h - H
    ee = e * e
    # root of d·Z² − H·Z − (d·e² + e·(2h − H)) = 0; S = 2d·Z − H is the square root
    S = np.sqrt(H * H + 2.0 * d2 * (d * ee + e * two_h_minus_H))
    Zq = (H + S) / d2
    inv_S = 1.0 / S
    outs = (
        Zq,
        (ee - Zq * Zq) * (inv_S * (1.0 / f)),
        (Zq - e) * inv_S,
        (d2 * e + two_h_minus_H) * inv_S,
        (2.0 * e) * inv_S,
    )
    roof_above = h < H
    if not roof_above.any():
        return outs
    Zt = H / d + e
    return (
        np.where(roof_above, Zt, outs[0]),
        np.where(roof_above, -H / (d * d) / f, outs[1]),
        np.where(roof_above, 1.0 / d, outs[2]),
        np.where(roof_above, 1.0, outs[3]),
        np.where(roof_above, 0.0 * d, outs[4]),
    )


class SizeCue(NamedTuple):
    """A size cue as a log distance, as :func:`height_cue_log` and :func:`width_cue_log` give it.

    Attributes:
        mean: ``ℓ = log Z`` (Z, the centre depth, in metres).
        lever: ``∂ℓ/∂log(dimension)``, how much of a relative error of the vehicle's dimension
            (against the class prior) goes into ℓ: ``∂log Z/∂log H`` for the height cue, the
            width's share ``∂log Z/∂log W`` for the width cue.
        var_white: variance of ℓ from the box edges' pixel noise (independent per frame).
        var_other: other per-vehicle variance of ℓ (the footprint's depth, the camera height;
            for the width cue, the length's share of the size prior).
        camera_lever: ``∂ℓ/∂h`` (1/m), the cue's change per metre of camera height above the
            target's road (the height cue's; None for a cue that does not depend on it).
    """

    mean: FloatArray
    lever: FloatArray
    var_white: FloatArray
    var_other: FloatArray
    camera_lever: FloatArray | None = None


def height_cue_log(
    box_height_px: FloatArray,
    f: float,
    cam_height_m: float,
    sigma_px: float,
    cam_height_sigma_m: float,
    height_m: FloatArray,
    half_extent_m: FloatArray,
    half_extent_var_m2: FloatArray,
) -> SizeCue:
    """:func:`height_cue` as a :class:`SizeCue` in closed form (the estimator's per-frame path).

    With ``d = D/f``, ``S = √(H² + 4d(d·e² + e(2h − H)))`` and ``Z = (H + S)/(2d)`` (roof below
    the camera): ``∂Z/∂H = (Z − e)/S``, ``∂Z/∂D = (e² − Z²)/(S·f)``, ``∂Z/∂e = (2de + 2h − H)/S``
    and ``∂Z/∂h = 2e/S``; where the roof is above the camera (``h < H``), ``Z = H/d + e``. The
    white variance is that of the two edges' noise ``σ`` (box height variance ``2σ²``), the
    other that of the half extent and the camera height.

    Args:
        box_height_px: ``(N, 1)`` box heights ``b − t`` (> 0), pixels.
        f, cam_height_m: focal length (px) and camera height (m).
        sigma_px, cam_height_sigma_m: box-edge noise (px) and camera-height uncertainty (m).
        height_m, half_extent_m, half_extent_var_m2: the class's height, the footprint's half
            depth extent and its variance per hypothesis, broadcastable to ``(N, K)``.
    """
    H = height_m
    e = half_extent_m
    d = box_height_px * (1.0 / f)
    ee = e * e
    tw = 2.0 * cam_height_m - H
    S = np.sqrt(H * H + (4.0 * d) * (d * ee + e * tw))
    inv_S = 1.0 / S
    Z = (H + S) * (0.5 / d)
    inv_Z = 1.0 / Z
    sz = inv_S * inv_Z
    lever = (Z - e) * sz * H
    rel_D = (ee - Z * Z) * sz
    white = (rel_D * rel_D) * (2.0 * (sigma_px / f) ** 2)
    de = (2.0 * d) * e + tw
    other = (de * de * half_extent_var_m2 + ee * (2.0 * cam_height_sigma_m) ** 2) * (sz * sz)
    camera = (2.0 * e) * sz  # ∂ℓ/∂h = (∂Z/∂h)/Z
    roof_above = np.asarray(H > cam_height_m)  # noqa: SIM300 (H is the array)
    if roof_above.any():  # the box spans the near face alone: Z = H/d + e
        Zt = H / d + e
        inv_Zt = 1.0 / Zt
        rel_t = H / (d * d) * inv_Zt
        Z = np.where(roof_above, Zt, Z)
        lever = np.where(roof_above, H / d * inv_Zt, lever)
        white = np.where(roof_above, rel_t * rel_t * (2.0 * (sigma_px / f) ** 2), white)
        other = np.where(roof_above, half_extent_var_m2 * inv_Zt * inv_Zt, other)
        camera = np.where(roof_above, 0.0, camera)
    return SizeCue(np.log(Z), lever, white, other, camera)


def _width_terms(
    left: FloatArray,
    right: FloatArray,
    f: float,
    c_x: float,
    half_w_cos: FloatArray,
    half_w_sin: FloatArray,
    half_l_cos: FloatArray,
    half_l_sin: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """The width cue's depth, the width's share and the two extreme corners' depth offsets,
    with the box width (see :func:`width_cue`)."""
    inv_f = 1.0 / f
    al = (left - c_x) * inv_f
    ar = (right - c_x) * inv_f
    # x − a·z of the corner with signs (s_l, s_w) is s_l·(L sinψ − a L cosψ)/2 + s_w·(W cosψ +
    # a W sinψ)/2: the left edge's corner minimises it at a_l, the right edge's maximises it
    # at a_r
    u_l = half_l_sin - al * half_l_cos
    v_l = half_w_cos + al * half_w_sin
    u_r = half_l_sin - ar * half_l_cos
    v_r = half_w_cos + ar * half_w_sin
    v_sum = np.abs(v_l) + np.abs(v_r)
    num = np.abs(u_l) + np.abs(u_r) + v_sum
    width_px = right - left
    Z = num * (f / width_px)
    # the corners' depth offsets s_l·L cosψ/2 − s_w·W sinψ/2 with the signs chosen
    dz_l = np.sign(v_l) * half_w_sin - np.sign(u_l) * half_l_cos
    dz_r = np.sign(u_r) * half_l_cos - np.sign(v_r) * half_w_sin
    return Z, v_sum / num, dz_l, dz_r, width_px


def width_cue(
    left: ArrayLike,
    right: ArrayLike,
    f: float,
    c_x: float,
    yaw_rad: ArrayLike,
    width_m: ArrayLike,
    length_m: ArrayLike,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Distance from the box's left and right columns, a heading ψ and the footprint (size cue).

    With the extreme corners l (left) and r (right) of the footprint, ``X + dx_l = a_l (Z +
    dz_l)`` and ``X + dx_r = a_r (Z + dz_r)`` (``a = (column − c_x)/f``) are linear in the
    centre ``(X, Z)``. Every other corner lies right of the left edge's ray, so the left corner
    is the one that minimises ``dx − a_l·dz`` (whatever X and Z), and the right one maximises
    ``dx − a_r·dz``; over the rectangle these extremes are ``∓(|L(sin ψ − a cos ψ)| + |W(cos ψ
    + a sin ψ)|)/2``, so ``Z = (|L(sin ψ − a_l cos ψ)| + |W(cos ψ + a_l sin ψ)| + |L(sin ψ −
    a_r cos ψ)| + |W(cos ψ + a_r sin ψ)|)/(2 (a_r − a_l))``: exact for any box of the footprint
    model, near or far.

    Returns:
        ``(Z, dZ/dcolumn_rms, share_w)``: centre depth (m); the depth change per pixel of edge
        noise (root-sum-square over both edges, m/px); and the share of the solution owed to the
        width, ``∂log Z/∂log W`` (the rest, ``1 − share_w``, is owed to the length). ``Z`` is NaN
        where the columns are not ordered.
    """
    psi = np.asarray(yaw_rad, dtype=float)
    W = np.asarray(width_m, dtype=float)
    L = np.asarray(length_m, dtype=float)
    c, s = np.cos(psi), np.sin(psi)
    lft = np.asarray(left, dtype=float)
    rgt = np.asarray(right, dtype=float)
    rgt = np.where(rgt > lft, rgt, np.nan)  # NaN (every output) where not ordered
    Z, share, dz_l, dz_r, width_px = _width_terms(
        lft, rgt, f, c_x, 0.5 * W * c, 0.5 * W * s, 0.5 * L * c, 0.5 * L * s
    )
    return Z, np.hypot(Z + dz_l, Z + dz_r) / width_px, share


def width_cue_log(
    left: FloatArray,
    right: FloatArray,
    f: float,
    c_x: float,
    sigma_px: float,
    half_w_cos: FloatArray,
    half_w_sin: FloatArray,
    half_l_cos: FloatArray,
    half_l_sin: FloatArray,
    min_depth_m: FloatArray,
) -> SizeCue:
    """:func:`width_cue` as a :class:`SizeCue` (the estimator's per-frame path): its lever is
    the width's share, its ``var_other`` 0 (the caller adds the length's share); the depth is
    clipped at ``min_depth_m`` before its logarithm.

    Args:
        left, right: ``(N, K)`` box columns (the same for every hypothesis), pixels.
        f, c_x, sigma_px: focal length, principal-point column and box-edge noise, pixels.
        half_w_cos, half_w_sin, half_l_cos, half_l_sin: ``W cos ψ/2``, ``W sin ψ/2``,
            ``L cos ψ/2``, ``L sin ψ/2`` of the class and hypotheses, ``(N, K)``, metres.
        min_depth_m: ``(N, K)`` the smallest centre depth accepted.
    """
    Z, share, dz_l, dz_r, width_px = _width_terms(
        left, right, f, c_x, half_w_cos, half_w_sin, half_l_cos, half_l_sin
    )
    Zm = np.maximum(Z, min_depth_m)
    zl, zr = Z + dz_l, Z + dz_r  # the extreme corners' depths
    white = (zl * zl + zr * zr) / (Zm * Zm) * ((sigma_px * sigma_px) / (width_px * width_px))
    return SizeCue(np.log(Zm), share, white, np.zeros(Zm.shape))


def ground_contact_cue(
    bottom: ArrayLike,
    v: ArrayLike,
    f: float,
    cam_height_m: ArrayLike,
    half_extent_m: ArrayLike,
) -> FloatArray:
    """Gradient-aware ground-contact distance to the target's centre (eq. 1 plus the half extent).

    ``Z = f·h/(b − v) + e`` with ``v`` the horizon row of eq. 5 for the gradient in use; NaN where
    ``b ≤ v`` (the contact point is at or above the horizon).
    """
    gap = np.asarray(bottom, dtype=float) - np.asarray(v, dtype=float)
    gap = np.where(gap > 0.0, gap, np.nan)  # NaN propagates without a warning
    return np.asarray(f * np.asarray(cam_height_m, dtype=float) / gap + np.asarray(half_extent_m))


def ground_contact_sigma(
    distance_near_m: ArrayLike,
    f: float,
    cam_height_m: ArrayLike,
    row_sigma_px: ArrayLike,
    theta_sigma_rad: ArrayLike,
    height_sigma_m: ArrayLike = 0.0,
) -> FloatArray:
    """Propagated 1σ of the ground-contact distance (m): it grows as ``d²/(f·h)``.

    ``σ_d² = (d²/(f h))²·(σ_row² + f²σ_θ²) + (d σ_h / h)²`` where ``d`` is the distance to the
    contact point, ``σ_row`` the box-bottom pixel noise, ``σ_θ`` the gradient's uncertainty and
    ``σ_h`` the camera height's.
    """
    d = np.asarray(distance_near_m, dtype=float)
    h = np.asarray(cam_height_m, dtype=float)
    gain = d * d / (f * h)
    return np.asarray(
        np.sqrt(
            (gain**2) * (np.square(row_sigma_px) + (f * np.asarray(theta_sigma_rad)) ** 2)
            + (d * np.asarray(height_sigma_m) / h) ** 2
        )
    )


def expected_centre_offset_px(
    distance_m: ArrayLike,
    f: float,
    cam_height_m: ArrayLike,
    height_m: ArrayLike,
    half_extent_m: ArrayLike,
) -> FloatArray:
    """Δy of eq. 6 (box centre row minus horizon row, px) of a target on the ego's road plane."""
    Z = np.asarray(distance_m, dtype=float)
    e = np.asarray(half_extent_m, dtype=float)
    h = np.asarray(cam_height_m, dtype=float)
    H = np.asarray(height_m, dtype=float)
    near = Z - e  # > 0 for the box of a real target
    top_depth = Z + e  # the far roof edge is the top of the box, unless the roof is above
    roof_above = h < H
    top_depth = np.where(roof_above, near, top_depth)
    return np.asarray((h / near + (h - H) / top_depth) * (0.5 * f))


def target_gradient(
    delta_y_px: ArrayLike,
    distance_m: ArrayLike,
    f: float,
    cam_height_m: ArrayLike,
    height_m: ArrayLike,
    half_extent_m: ArrayLike,
) -> FloatArray:
    """Continuous road gradient of a target relative to the ego gradient θ (radians).

    A target at distance Z on the ego's road plane has its box centre ``Δy_flat(Z)`` rows below
    the horizon (:func:`expected_centre_offset_px`); a target on a road climbing by α relative
    to θ sits ``f·tan α`` rows higher. So ``α = atan((Δy_flat(Z) − Δy)/f)``, positive when the
    target climbs; ``θ + α`` replaces the paper's three-step eq. 7.
    """
    flat = expected_centre_offset_px(distance_m, f, cam_height_m, height_m, half_extent_m)
    return np.asarray(np.arctan((flat - np.asarray(delta_y_px, dtype=float)) / f))


def ground_contact_log_cue(
    bottom: FloatArray,
    v: FloatArray | float,
    f: float,
    cam_height_m: FloatArray | float,
    half_extent_m: FloatArray | float,
    row_var_white: FloatArray | float,
    row_var_other: FloatArray | float,
    height_sigma_m: FloatArray | float = 0.0,
    half_extent_sigma_m: FloatArray | float = 0.0,
) -> LogCue:
    """:func:`ground_contact_cue` as a log distance with its propagated variance.

    Row noise (variances in px², white and per-vehicle, e.g. the target gradient's uncertainty
    times f²) maps through ``∂ℓ/∂b = −(Z_n/Z)/(b − v)``: in metres the error grows as
    ``d²/(f·h)``. The camera height and the half extent add per-vehicle variance. NaN where
    ``b ≤ v``.
    """
    gap = bottom - np.asarray(v, dtype=float)
    fh = f * np.asarray(cam_height_m, dtype=float)
    gap = np.where(gap > 0.0, gap, np.nan)  # NaN propagates (no division by a zero gap)
    zn = fh / gap
    z = zn + half_extent_m
    gain = zn * zn * (1.0 / fh)
    gain *= gain  # (σ_d/σ_row)², see ground_contact_sigma
    inv_z2 = 1.0 / (z * z)
    white = gain * row_var_white * inv_z2
    zh = zn * (np.asarray(height_sigma_m) * f / fh)
    other = (gain * row_var_other + zh * zh + np.square(half_extent_sigma_m)) * inv_z2
    return LogCue(np.log(z), white + other, white, np.zeros(z.shape))
