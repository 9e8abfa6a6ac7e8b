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
from scipy import special

FloatArray = NDArray[np.float64]


def all_true(mask: NDArray[np.bool_]) -> bool:
    """``mask.all()`` for the small arrays of one frame (counting is cheaper than reducing)."""
    return bool(np.count_nonzero(mask) == mask.size)


def any_true(mask: NDArray[np.bool_]) -> bool:
    """``mask.any()`` for the small arrays of one frame."""
    return bool(np.count_nonzero(mask))


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
    if not any_true(roof_above):
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
    """

    mean: FloatArray
    lever: FloatArray
    var_white: FloatArray
    var_other: FloatArray


def height_cue_log(
    box_height_px: FloatArray,
    f: float,
    cam_height_m: float,
    sigma_px: float,
    cam_height_sigma_m: float,
    height_m: FloatArray,
    half_extent_m: FloatArray,
    half_extent_var_m2: FloatArray,
    roof_above: NDArray[np.bool_] | None = None,
) -> SizeCue:
    """:func:`height_cue` as a :class:`SizeCue` in closed form (the estimator's per-frame path).

    With ``d = D/f``, ``S = √(H² + 4d(d·e² + e(2h − H)))`` and ``Z = (H + S)/(2d)`` (roof below
    the camera): ``∂Z/∂H = (Z − e)/S``, ``∂Z/∂D = (e² − Z²)/(S·f)``, ``∂Z/∂e = (2de + 2h − H)/S``
    and ``∂Z/∂h = 2e/S``; where ``roof_above`` (``h < H``), ``Z = H/d + e``. The white variance
    is that of the two edges' noise ``σ`` (box height variance ``2σ²``), the other that of the
    half extent and the camera height.

    Args:
        box_height_px: ``(N, 1)`` box heights ``b − t`` (> 0), pixels.
        f, cam_height_m: focal length (px) and camera height (m).
        sigma_px, cam_height_sigma_m: box-edge noise (px) and camera-height uncertainty (m).
        height_m, half_extent_m, half_extent_var_m2: the class's height, the footprint's half
            depth extent and its variance per hypothesis, broadcastable to ``(N, K)``.
        roof_above: where the vehicle is taller than the camera height (None: nowhere).
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
    if roof_above is not None and any_true(roof_above):
        Zt = H / d + e
        inv_Zt = 1.0 / Zt
        rel_t = H / (d * d) * inv_Zt
        Z = np.where(roof_above, Zt, Z)
        lever = np.where(roof_above, H / d * inv_Zt, lever)
        white = np.where(roof_above, rel_t * rel_t * (2.0 * (sigma_px / f) ** 2), white)
        other = np.where(roof_above, half_extent_var_m2 * inv_Zt * inv_Zt, other)
    return SizeCue(np.log(Z), lever, white, other)


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
    gap = np.where(gap > 0, gap, np.nan)  # NaN propagates without a warning
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
    if any_true(roof_above):
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


def hidden_sides(
    boxes: ArrayLike, tol_px: float = 1.5
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Whether each box's width and height may be cut short by a nearer box.

    Box ``j`` is nearer than box ``i`` when its bottom is lower in the image (``b_j > b_i``:
    on a common road a nearer vehicle touches the ground lower). An edge of ``i`` that lies on
    a nearer box that overlaps it (or touches it, within ``tol_px``) may be where ``i``'s
    vehicle disappears behind the nearer one rather than where it ends: a box drawn around what
    is visible (an image detector's, a LiDAR cluster's) is then narrower or shorter than the
    vehicle. (A box drawn around the whole vehicle, as labels and LiDAR detectors' 3D boxes are,
    is not cut, but cannot be told apart from the box alone.)

    Args:
        boxes: ``(N, 4)`` (left, top, right, bottom), pixels.
        tol_px: how close an edge must come to a nearer box to count as on it, pixels.

    Returns:
        ``(width_cut, height_cut)``: ``(N,)`` flags, a left or right edge (resp. top or bottom
        edge) on a nearer box.
    """
    b = np.asarray(boxes, dtype=float).reshape(-1, 4)
    lo = b[:, :2] - tol_px  # each box's extent (columns, rows), widened by tol
    hi = b[:, 2:] + tol_px
    # pairs (i, j) whose boxes overlap or touch (both axes), with j nearer (its bottom lower)
    reach = np.minimum(b[:, None, 2:], hi[None]) > np.maximum(b[:, None, :2], lo[None])
    near = reach[..., 0] & reach[..., 1] & (b[None, :, 3] > b[:, None, 3])
    if not any_true(near):
        z = np.zeros(b.shape[0], dtype=bool)
        return z, z.copy()
    i, j = np.nonzero(near)  # few pairs: test their edges only
    lo_j, hi_j = lo[j], hi[j]
    bi = b[i]
    on = (
        ((bi[:, :2] >= lo_j) & (bi[:, :2] <= hi_j))  # left / top edge of i on j
        | ((bi[:, 2:] >= lo_j) & (bi[:, 2:] <= hi_j))
    )  # right / bottom edge of i on j
    cut = np.zeros((b.shape[0], 2), dtype=bool)
    np.logical_or.at(cut, i, on)
    return cut[:, 0], cut[:, 1]


def unexplained_excess(
    y_cue: ArrayLike,
    var_cue: ArrayLike,
    y_ref: ArrayLike,
    var_ref: ArrayLike,
    gate_sigma: float = 3.0,
) -> FloatArray:
    """How far a log-distance cue says farther than a reference beyond their own noise:
    ``max(y_cue − y_ref, 0)² − gate_sigma²·(var_cue + var_ref)`` (log², > 0 only for an
    outlier on the far side; NaN where either is missing)."""
    excess = np.maximum(np.asarray(y_cue) - np.asarray(y_ref), 0.0)
    return np.asarray(
        excess * excess - gate_sigma * gate_sigma * (np.asarray(var_cue) + np.asarray(var_ref))
    )


def occlusion_log_var(unexplained: ArrayLike, cut: ArrayLike) -> FloatArray:
    """Extra variance of a log-distance size cue whose dimension may be cut short by a nearer
    vehicle (:func:`hidden_sides`).

    Hiding part of a dimension only shrinks a box drawn around what is visible, which makes the
    cue's distance too large; so for a dimension that may be cut the cue is a censored
    measurement: what it says beyond an independent reference (the ground contact) may be
    hiding, by any amount. An excess the two cues' own noise explains, or a cue that says nearer
    than the reference (hiding cannot explain that), leaves the cue alone; beyond it the
    unexplained excess (:func:`unexplained_excess`) is taken as the cue's extra error variance.
    No parameter besides the outlier test's.

    Args:
        unexplained: :func:`unexplained_excess` of the cue against the reference (log²).
        cut: whether the cue's dimension may be cut short, broadcastable to ``unexplained``.
    """
    u = np.asarray(unexplained)
    return np.asarray(np.where(np.asarray(cut) & (u > 0.0), u, 0.0))


class LogCue(NamedTuple):
    """A log-distance estimate ``ℓ = log Z`` with its error split in two (a named tuple: built
    several times per frame, so cheap to make).

    Attributes:
        mean: ℓ (Z in metres).
        var: total variance of ℓ.
        var_white: the part independent from frame to frame (pixel noise, horizon jitter);
            the rest (``var − var_white``) stays with a vehicle over its track.
        loglik: log-likelihood of the cues' mutual consistency (compares heading hypotheses;
            0 where a single cue was available).
    """

    mean: FloatArray
    var: FloatArray
    var_white: FloatArray
    loglik: FloatArray


def fuse_size_cues(
    y_h: FloatArray,
    r_h_white: FloatArray | float,
    r_h_other: FloatArray | float,
    c_h: FloatArray,
    y_w: FloatArray,
    r_w_white: FloatArray | float,
    r_w_other: FloatArray | float,
    c_w: FloatArray,
    sigma_log_h: FloatArray | float,
    sigma_log_w: FloatArray | float,
    corr_hw: FloatArray | float,
) -> LogCue:
    """Fuse the height and width cues (log distances) under the class size prior.

    ``y_h = ℓ − c_h·ηH + n_h`` and ``y_w = ℓ − c_w·ηW + n_w``, with ``(ηH, ηW)`` the vehicle's
    log size deviations from its class (spreads ``sigma_log_h``, ``sigma_log_w``, correlation
    ``corr_hw``) and ``n`` measurement noise (white variances ``r_*_white`` plus other
    per-vehicle variances ``r_*_other``, e.g. from the length): the generalised least-squares
    estimate of ℓ. A non-finite width cue leaves the height cue alone.
    """
    yh, yw = np.asarray(y_h, dtype=float), np.asarray(y_w, dtype=float)
    sh = c_h * np.asarray(sigma_log_h)
    sw = c_w * np.asarray(sigma_log_w)
    C11 = sh * sh + r_h_white + r_h_other
    C22 = sw * sw + r_w_white + r_w_other
    C12 = corr_hw * sh * sw
    # den > 0 unless both cues are exact (C is a covariance); a missing width gives NaN
    den = C11 + C22 - C12 - C12
    inv_den = 1.0 / den
    a_h = (C22 - C12) * inv_den
    a_w = (C11 - C12) * inv_den
    diff = yh - yw
    mean = yw + a_h * diff
    var = (C11 * C22 - C12 * C12) * inv_den
    white = a_h * a_h * r_h_white + a_w * a_w * r_w_white
    loglik = (diff * diff * inv_den + np.log(den)) * -0.5 - _HALF_LOG_2PI
    both = np.isfinite(den)
    if all_true(both):
        return LogCue(mean, var, white, loglik)
    return LogCue(
        np.where(both, mean, yh),
        np.where(both, var, C11),
        np.where(both, white, np.broadcast_to(r_h_white, np.shape(yh))),
        np.where(both, loglik, 0.0),
    )


_HALF_LOG_2PI = 0.5 * float(np.log(2.0 * np.pi))


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
    bad = gap <= 0
    zn = fh / gap
    if any_true(bad):  # NaN, which then propagates
        zn = np.where(bad, np.nan, zn)
    z = zn + half_extent_m
    gain = zn * zn * (1.0 / fh)
    gain *= gain  # (σ_d/σ_row)², see ground_contact_sigma
    inv_z2 = 1.0 / (z * z)
    white = gain * row_var_white * inv_z2
    zh = zn * (np.asarray(height_sigma_m) * f / fh)
    other = (gain * row_var_other + zh * zh + np.square(half_extent_sigma_m)) * inv_z2
    return LogCue(np.log(z), white + other, white, np.zeros(z.shape))


def fuse_log_cues(a: LogCue, b: LogCue) -> LogCue:
    """Inverse-variance fusion of two independent log-distance cues.

    The white variance is propagated with the same weights; ``loglik`` adds the consistency of
    the two cues to ``a``'s. Where ``b`` is missing (NaN) the result is ``a``.
    """
    ok = np.isfinite(b.mean + b.var) & (b.var > 0)
    every = all_true(ok)
    vb = b.var if every else np.where(ok, b.var, 1.0)
    mb = b.mean if every else np.where(ok, b.mean, 0.0)
    wb_white = b.var_white if every else np.where(ok, b.var_white, 0.0)
    tot = a.var + vb  # > 0: vb > 0 and a.var ≥ 0
    inv_tot = 1.0 / tot
    wa = vb * inv_tot
    wb = a.var * inv_tot
    diff = a.mean - mb
    mean = mb + wa * diff
    var = a.var * wa
    white = wa * wa * a.var_white + wb * wb * wb_white
    ll = (diff * diff * inv_tot + np.log(tot)) * -0.5 - _HALF_LOG_2PI
    if every:
        return LogCue(mean, var, white, a.loglik + ll)
    return LogCue(
        np.where(ok, mean, a.mean),
        np.where(ok, var, a.var),
        np.where(ok, white, a.var_white),
        a.loglik + np.where(ok, ll, 0.0),
    )


def censor_upper(cue: LogCue, bound: ArrayLike, bound_var: ArrayLike, where: ArrayLike) -> LogCue:
    """Condition a log-distance cue on an upper bound ``ℓ ≤ bound`` known up to noise of
    variance ``bound_var`` (a censored measurement), where ``where`` is true and the bound finite.

    A box cut by the image border shows less than its vehicle: the size cue of a cut dimension
    says *at least this far*, so the vehicle is at most that far, and a box whose bottom is cut
    has its ground contact below the image, so at most as far as the cut row says. With the
    Gaussian ``cue`` ``N(μ, v)`` and the bound's likelihood ``Φ((bound − ℓ)/s)``, the posterior's
    moments are those of a truncated normal: with ``a = (bound − μ)/√(v + s²)`` and
    ``λ = φ(a)/Φ(a)``, ``μ' = μ − v·λ/√(v + s²)``, ``v' = v·(1 − v·λ(λ + a)/(v + s²))``; the
    white part shrinks in the same ratio and ``log Φ(a)`` is added to ``loglik`` (it weighs the
    heading hypotheses). A bound far above the estimate changes nothing.
    """
    mu, var = cue.mean, cue.var
    tot = var + np.asarray(bound_var, dtype=float)
    root = np.sqrt(tot)
    a = (np.asarray(bound, dtype=float) - mu) / root
    log_cdf = special.log_ndtr(a)
    lam = np.exp(-0.5 * a * a - log_cdf) * _INV_SQRT_2PI
    factor = 1.0 - var / tot * lam * (lam + a)
    use = np.asarray(where, dtype=bool) & np.isfinite(a)
    return LogCue(
        np.where(use, mu - var / root * lam, mu),
        np.where(use, var * factor, var),
        np.where(use, cue.var_white * factor, cue.var_white),
        np.where(use, cue.loglik + log_cdf, cue.loglik),
    )


_INV_SQRT_2PI = 1.0 / np.sqrt(2.0 * np.pi)


def collapse_hypotheses(cue: LogCue, log_weight: ArrayLike) -> tuple[LogCue, FloatArray]:
    """Moment-match a mixture over the last axis (heading hypotheses) into one log cue.

    The spread of the hypotheses' means counts as per-vehicle variance. Returns the cue and the
    normalised weights.
    """
    lw = np.asarray(log_weight, dtype=float)
    w = np.exp(lw - np.maximum.reduce(lw, axis=-1, keepdims=True))
    w /= np.add.reduce(w, axis=-1, keepdims=True)
    return mix_hypotheses(cue, w), w


def mix_hypotheses(cue: LogCue, weight: FloatArray) -> LogCue:
    """:func:`collapse_hypotheses` with normalised weights (summing to 1 over the last axis)."""
    mean = np.add.reduce(weight * cue.mean, axis=-1)
    dev = cue.mean - mean[..., None]
    var = np.add.reduce(weight * (cue.var + dev * dev), axis=-1)
    white = np.add.reduce(weight * cue.var_white, axis=-1)
    return LogCue(mean, var, np.minimum(white, var), np.zeros(mean.shape))
