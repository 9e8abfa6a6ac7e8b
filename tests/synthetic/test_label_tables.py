"""Per-label tables: the plane functionals give the depth and texture coordinates of a known
plane, the road's colour is its texture's, and the turn of a surface adds up piece by piece."""

from __future__ import annotations

import math

import numpy as np

from slopedist.synthetic.atlas import texture_atlas
from slopedist.synthetic.label_tables import label_tables
from slopedist.synthetic.polygons import Material, Polygons
from slopedist.synthetic.textures import TEX_SIZE, LaneLayout, Tex

K = np.array([[700.0, 0.0, 600.0], [0.0, 700.0, 180.0], [0.0, 0.0, 1.0]])
HEIGHT_M = 1.65


def _ground(pitch: tuple[float, ...]) -> Polygons:
    """Pieces of one ground surface ``HEIGHT_M`` below a camera at the origin (camera frame =
    world frame), the i-th tilted by ``pitch[i]`` radians about the x axis; u along z, v along
    x."""
    p = len(pitch)
    a = np.asarray(pitch)
    normal = np.stack([np.zeros(p), -np.cos(a), -np.sin(a)], axis=1)
    axis_u = np.stack([np.zeros(p), -np.sin(a), np.cos(a)], axis=1)
    origin = np.tile([0.0, HEIGHT_M, 0.0], (p, 1))
    corners = np.array([[-5.0, 0.0], [5.0, 0.0], [5.0, 40.0], [-5.0, 40.0]])
    verts = (
        origin[:, None]
        + corners[None, :, :1] * [1.0, 0.0, 0.0]
        + corners[None, :, 1:] * (axis_u[:, None])
    )
    zeros = np.zeros(p)
    return Polygons(
        verts=verts,
        normal=normal,
        origin=origin,
        axis_u=axis_u,
        axis_v=np.tile([1.0, 0.0, 0.0], (p, 1)),
        u0=np.full(p, 100.0),
        key=zeros,
        layer=np.zeros(p, np.int64),
        s_lo=zeros,
        s_hi=zeros,
        material=np.full(p, int(Material.GROUND), np.int64),
        colour=np.full((p, 3), 0.5),
        owner=np.full(p, -1, np.int64),
        two_sided=np.ones(p, bool),
        lod=np.full(p, -1, np.int8),
        lod_key=zeros,
        surface=np.zeros(p, np.int64),
    )


def test_plane_functionals_give_depth_and_texture_coordinates() -> None:
    atlas = texture_atlas(LaneLayout(3.5, 2, 3.5), 10.5)
    polys = _ground((0.0,))
    tab = label_tables(polys, polys.surface, np.eye(3), np.zeros(3), np.linalg.inv(K), atlas, 96.0)
    f = tab.per_label[:, 1].astype(float)
    for x, y in ((600.0, 300.0), (200.0, 250.0), (1100.0, 190.0)):
        p = np.array([x, y, 1.0])
        ray = np.linalg.solve(K, p)
        z = HEIGHT_M / ray[1]  # where the ray meets the ground
        X = ray * z
        inv = f[6:9] @ p
        assert math.isclose(inv, 1.0 / z, rel_tol=1e-5)
        u = 100.0 - 96.0 + X[2]  # u0, rebased by u_base, plus the distance along u
        tx = TEX_SIZE * (f[0:3] @ p) / inv
        assert math.isclose(tx, u * Tex.TEXELS_PER_M[Tex.ROAD], rel_tol=1e-4)
        ty = (f[3:6] @ p) / inv
        tpm_v = atlas.tpm_v[Tex.ROAD]
        row = (X[0] - atlas.v_min[Tex.ROAD]) * tpm_v + atlas.y0[Tex.ROAD]
        assert math.isclose(ty, row, rel_tol=1e-5)  # float32 tables
    # the road's colours are in its texture; label 0 is the sky
    assert np.all(tab.tint[1, :3] == 1.0) and np.all(tab.tint[0] == 0.0)
    assert tab.tex.tolist() == [Tex.SKY, Tex.ROAD] and tab.surface.tolist() == [-1, 0]


def test_turn_adds_up_piece_to_piece() -> None:
    atlas = texture_atlas(LaneLayout(3.5, 2, 3.5), 10.5)
    polys = _ground((0.0, 0.02, 0.05))
    tab = label_tables(polys, polys.surface, np.eye(3), np.zeros(3), np.linalg.inv(K), atlas, 0.0)
    np.testing.assert_allclose(tab.turn, [0.0, 0.0, 0.02, 0.05], atol=1e-9)
