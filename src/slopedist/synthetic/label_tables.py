"""Per-label tables of one rendered frame: for every polygon seen, the closed-form functionals
of its plane (depth and texture coordinates as functions of the pixel), its tint and mip-level
terms, and how far its surface's normal has turned (see
:mod:`~slopedist.synthetic.render`, step 2).

Convention: camera frame x right, y down, z forward; pixel ``p = (x, y, 1)`` homogeneous;
``R_wc`` camera-to-world; metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slopedist.synthetic.atlas import MIP_BIAS, Atlas
from slopedist.synthetic.polygons import Material, Polygons
from slopedist.synthetic.textures import MATERIAL_TEXTURE, TEX_SIZE, Tex

FloatArray = NDArray[np.float64]

SUN_DIRECTION = np.array([0.35, -0.45, 0.82]) / np.linalg.norm([0.35, -0.45, 0.82])
"""Unit vector towards the sun, world frame (for face shading)."""
ROAD_FORESHORTENING_FREE = 16.0
"""The road's mip level counts only its foreshortening beyond this factor: seen ahead at a
grazing angle, its lane markings and texture stay sharp across the road (somewhat aliased along
it); beyond a crest, at the most grazing angles, it blurs."""


def _material_texture_index() -> NDArray[np.intp]:
    out = np.zeros(len(Material), np.intp)
    for material, texture in MATERIAL_TEXTURE.items():
        out[int(material)] = texture
    return out


MATERIAL_TEXTURE_INDEX = _material_texture_index()
"""The texture of each :class:`~slopedist.synthetic.polygons.Material` (indexed by it)."""


@dataclass(frozen=True)
class LabelTables:
    """Per-label tables of one frame (label 0 = sky).

    Attributes:
        per_label: ``(11, n + 1)`` float32, one row per quantity (gathered together): rows 0–8
            the pixel functionals ``(h_x, h_y, h_w)``: ``1/z = h_w·p``, texel coordinates
            ``t_x = TEX_SIZE (h_x·p)/(h_w·p)`` (``h_x`` in periods of the tiles),
            ``t_y = (h_y·p)/(h_w·p)`` (level 0, ``t_y`` from the atlas's first row); row 9
            ``log2`` of the texture's texels per metre along ``v`` minus ``MIP_BIAS``; row 10
            ``log2`` of the plane's distance from the camera centre (m) times the
            foreshortening that does not raise the mip level (see ``Renderer._level``).
        tint: ``(n + 1, 4)`` float32, the BGR colour × sun shading in [0, 1] and a 0.
        tex: ``(n + 1,)`` texture.
        surface: ``(n + 1,)`` surface of each label (equal for pieces of one surface).
        turn: ``(n + 1,)`` angle the surface's normal has turned through from its first label's
            piece to each label's (radians, summed piece to piece): between labels ``a < b`` of
            one surface every piece's normal is within ``turn[b] − turn[a]`` of the others'.
    """

    per_label: NDArray[np.float32]
    tint: NDArray[np.float32]
    tex: NDArray[np.intp]
    surface: NDArray[np.int64]
    turn: FloatArray


def label_tables(
    polys: Polygons,
    surface: NDArray[np.int64],
    R_wc: FloatArray,
    C_w: FloatArray,
    K_inv: FloatArray,
    atlas: Atlas,
    u_base: float,
) -> LabelTables:
    """The per-label tables of ``polys`` (in label order, label = index + 1; ``surface``: the
    surface of each) seen by a camera at ``C_w`` (world frame) with rotation ``R_wc`` (camera to
    world) and inverse intrinsics ``K_inv``; textures in ``atlas``, the ground's and walls' ``u``
    relative to ``u_base`` (metres along the road)."""
    n = len(polys)
    n_c = polys.normal @ R_wc  # rows: (R_wcᵀ n)ᵀ, the normals in the camera frame
    x0_c = (polys.verts[:, 0] - C_w) @ R_wc
    o_c = (polys.origin - C_w) @ R_wc
    c = np.einsum("pi,pi->p", n_c, x0_c)  # plane: n_c · X = c
    c = np.where(np.abs(c) < 1e-9, 1e-9, c)
    h_w = (n_c @ K_inv) / c[:, None]  # 1/z = h_w · p
    tex = MATERIAL_TEXTURE_INDEX[polys.material]
    tpm_u = Tex.TEXELS_PER_M[tex]
    tpm_v = atlas.tpm_v[tex]
    a_u, a_v = polys.axis_u @ R_wc, polys.axis_v @ R_wc
    along_road = polys.surface >= 0  # u = distance along the road: rebased
    k_u = polys.u0 - np.where(along_road, u_base, 0.0) - np.einsum("pi,pi->p", a_u, o_c)
    k_v = -np.einsum("pi,pi->p", a_v, o_c) - atlas.v_min[tex]
    k_v += atlas.y0[tex] / tpm_v  # rows from the atlas's first
    h_x = (tpm_u / TEX_SIZE)[:, None] * (a_u @ K_inv + k_u[:, None] * h_w)
    h_y = tpm_v[:, None] * (a_v @ K_inv + k_v[:, None] * h_w)
    fn = np.zeros((n + 1, 9), np.float32)
    fn[1:] = np.concatenate([h_x, h_y, h_w], axis=1)
    plane_c = np.ones(n + 1, np.float32)
    plane_c[1:] = np.abs(c)
    shade = 0.62 + 0.38 * np.clip(polys.normal @ SUN_DIRECTION, 0.0, 1.0)
    tint = np.zeros((n + 1, 4), np.float32)
    tint[1:, :3] = polys.colour * shade[:, None]
    tint[1:, :3][tex == Tex.ROAD] = 1.0  # the road's colours are in its texture
    tex_l = np.full(n + 1, Tex.SKY, np.intp)
    tex_l[1:] = tex
    tpm = np.ones(n + 1, np.float32)
    tpm[1:] = tpm_v
    surf = np.full(n + 1, -1, np.int64)
    surf[1:] = surface
    cos = np.einsum("pi,pi->p", polys.normal[1:], polys.normal[:-1])
    step = np.where(surface[1:] == surface[:-1], np.arccos(np.clip(cos, -1.0, 1.0)), 0.0)
    turn = np.zeros(n + 1)
    turn[2:] = np.cumsum(step)
    free = np.where(tex_l == Tex.ROAD, ROAD_FORESHORTENING_FREE, 1.0).astype(np.float32)
    log_tpm = np.log2(tpm) - np.float32(MIP_BIAS)
    log_c = np.log2(np.maximum(plane_c * free, np.float32(1e-3)))
    per_label = np.concatenate([fn.T, log_tpm[None], log_c[None]])
    return LabelTables(np.ascontiguousarray(per_label, dtype=np.float32), tint, tex_l, surf, turn)
