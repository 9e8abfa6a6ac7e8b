"""The polygon stage of the renderer: back-face culling, clipping at the near plane and the
image's border, projection to the integer outlines ``cv2.fillConvexPoly`` draws.

Convention: camera frame x right, y down, z forward; ``R_wc`` camera-to-world, ``C_w`` the
camera centre in the world frame of :mod:`~slopedist.synthetic.road`; pixel
coordinates ``(x = column, y = row)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slopedist.synthetic.polygons import Polygons

FloatArray = NDArray[np.float64]

NEAR_CLIP_M = 0.3
"""Polygons are clipped at this camera depth, metres."""


def _clip_halfplane(poly: FloatArray, axis: int, bound: float, keep_above: bool) -> FloatArray:
    """Sutherland–Hodgman: keep the part of polygon ``(n, d)`` with ``x[axis] ≥ bound``
    (``keep_above``) or ``≤ bound``."""
    out = []
    n = poly.shape[0]
    sign = 1.0 if keep_above else -1.0
    for i in range(n):
        a, b = poly[i], poly[(i + 1) % n]
        da, db = sign * (a[axis] - bound), sign * (b[axis] - bound)
        if da >= 0:
            out.append(a)
        if (da >= 0) != (db >= 0):
            out.append(a + (da / (da - db)) * (b - a))
    return np.asarray(out).reshape(-1, poly.shape[1])


def clip_polygon_near(poly_cam: FloatArray, near: float = NEAR_CLIP_M) -> FloatArray:
    """Clip one polygon ``(n, 3)`` (camera frame) to ``z ≥ near``."""
    return _clip_halfplane(poly_cam, 2, near, True)


def clip_polygon_rect(
    poly_px: FloatArray, x0: float, y0: float, x1: float, y1: float
) -> FloatArray:
    """Clip one polygon ``(n, 2)`` (pixels) to the rectangle ``[x0, x1] × [y0, y1]``."""
    for axis, bound, above in ((0, x0, True), (0, x1, False), (1, y0, True), (1, y1, False)):
        if poly_px.shape[0] < 3:
            break
        poly_px = _clip_halfplane(poly_px, axis, bound, above)
    return poly_px


FILL_LIMIT_PX = 8000.0
"""Outlines reaching farther than this from the image are clipped to it before filling
(``cv2.fillConvexPoly`` works in 16.16 fixed point and overflows beyond ±32768 pixels)."""


def visible_polygons(
    polys: Polygons,
    painter: NDArray[np.intp],
    R_wc: FloatArray,
    C_w: FloatArray,
    K: FloatArray,
    image_size: tuple[int, int],
) -> tuple[NDArray[np.intp], list[NDArray[np.int32]]]:
    """Cull, clip and project the polygons ``polys[painter]`` (painter order) seen by a camera
    at ``C_w`` (world frame) with rotation ``R_wc`` (camera to world) and intrinsics ``K`` on an
    image of ``image_size = (width, height)`` pixels; returns the indices (into ``painter``) of
    the kept ones and their integer pixel outlines (``cv2.fillConvexPoly`` coordinates, 4
    fractional bits)."""
    verts = polys.verts[painter]
    facing = polys.two_sided[painter] | (
        np.einsum("pi,pi->p", C_w - verts[:, 0], polys.normal[painter]) > 1e-9
    )
    idx = np.flatnonzero(facing)
    vc = (verts[idx] - C_w) @ R_wc  # (p, k, 3): camera frame
    x, y, z = np.ascontiguousarray(vc.transpose(2, 1, 0))  # (k, p) each
    all_in = np.logical_and.reduce(z >= NEAR_CLIP_M, axis=0)
    any_in = np.logical_or.reduce(z >= NEAR_CLIP_M, axis=0)
    zz = np.where(all_in, z, 1.0)
    px_x = K[0, 0] * x / zz + K[0, 2]
    px_y = K[1, 1] * y / zz + K[1, 2]
    w, h = image_size
    lo_x, hi_x = px_x.min(axis=0), px_x.max(axis=0)
    lo_y, hi_y = px_y.min(axis=0), px_y.max(axis=0)
    onscreen = (hi_x >= -1) & (lo_x <= w) & (hi_y >= -1) & (lo_y <= h)
    lim = FILL_LIMIT_PX
    huge = (lo_x < -lim) | (lo_y < -lim) | (hi_x > w + lim) | (hi_y > h + lim)
    direct = np.flatnonzero(all_in & onscreen & ~huge)
    px = np.stack([px_x, px_y], axis=-1).transpose(1, 0, 2)  # (p, k, 2)
    outlines: dict[int, NDArray[np.int32]] = dict(
        zip(direct.tolist(), np.round(px[direct] * 16.0).astype(np.int32), strict=True)
    )
    # crossing the near plane, or reaching beyond fillConvexPoly's range: clipped
    for p in np.flatnonzero((any_in & ~all_in) | (all_in & onscreen & huge)).tolist():
        if all_in[p]:
            q = px[p]
        else:
            poly = clip_polygon_near(vc[p])
            if poly.shape[0] < 3:
                continue
            q = np.stack(
                [
                    K[0, 0] * poly[:, 0] / poly[:, 2] + K[0, 2],
                    K[1, 1] * poly[:, 1] / poly[:, 2] + K[1, 2],
                ],
                axis=-1,
            )
        if np.any(q < -lim) or np.any(q > (w + lim, h + lim)):
            q = clip_polygon_rect(q, -4.0, -4.0, w + 4.0, h + 4.0)
            if q.shape[0] < 3:
                continue
        outlines[p] = np.round(q * 16.0).astype(np.int32)
    keep = sorted(outlines)  # painter order is index order
    return idx[np.asarray(keep, dtype=np.intp)], [outlines[p] for p in keep]
