"""Planar polygons, the renderer's primitive: their table, materials, layers, and the faces of
boxes (roadside objects, target vehicles).

Convention: world frame of :mod:`~slopedist.synthetic.road` (X forward at ``s = 0``,
Y left, Z up, metres). Every surface is a planar convex quadrilateral with a texture frame: a
point ``X`` of the polygon has texture coordinates ``u = u0 + (X − o)·a`` and
``v = (X − o)·b`` (metres), with ``a``, ``b`` unit axes in its plane.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


class Material(IntEnum):
    """How a polygon is shaded (the renderer's per-pixel rules)."""

    SKY = 0
    GROUND = 1
    BUILDING = 2
    TREES = 3
    POST = 4
    OBJECT = 5
    VEHICLE = 6


GROUND_SURFACE = 0
"""Surface id of the ground strips (wall segments are numbered from 1)."""


class Layer(IntEnum):
    """Drawing priority among polygons with the same painter key (lower first)."""

    GROUND = 0
    STRUCTURE = 1
    OBJECT = 2
    VEHICLE = 3


@dataclass
class Polygons:
    """A set of planar quads with everything the renderer needs (``P`` polygons).

    Attributes:
        verts: ``(P, 4, 3)`` corners in order around the polygon, world frame.
        normal: ``(P, 3)`` unit normal on the visible side (faces with ``(C − X)·n ≤ 0`` are
            culled).
        origin, axis_u, axis_v: ``(P, 3)`` texture frame; u0: ``(P,)`` offset of ``u``.
        key: ``(P,)`` painter key, the plan distance ``s`` that orders drawing (larger first);
            layer: ``(P,)`` :class:`Layer` among equal keys.
        s_lo, s_hi: ``(P,)`` plan-distance extent, to select what is near the camera.
        material: ``(P,)`` :class:`Material`; colour: ``(P, 3)`` BGR in [0, 1].
        owner: ``(P,)`` index of the target vehicle the polygon belongs to, −1 for the world.
        two_sided: ``(P,)`` bool: never culled.
        lod: ``(P,)`` level of detail: −1 always drawn, 0 fine, 1 coarse; fine and coarse
            polygons cover the same surface, grouped by ``lod_key`` (plan distance, metres):
            a group is drawn fine when its key is nearer than the renderer's boundary.
        surface: ``(P,)`` smooth surface the polygon is a piece of (−1: a surface of its own):
            pieces of one surface (:data:`GROUND_SURFACE` for all ground strips, one id per
            roadside wall segment) share one material and one continuous texture frame, so
            the renderer may interpolate across their common edges.
    """

    verts: FloatArray
    normal: FloatArray
    origin: FloatArray
    axis_u: FloatArray
    axis_v: FloatArray
    u0: FloatArray
    key: FloatArray
    layer: NDArray[np.int64]
    s_lo: FloatArray
    s_hi: FloatArray
    material: NDArray[np.int64]
    colour: FloatArray
    owner: NDArray[np.int64]
    two_sided: NDArray[np.bool_]
    lod: NDArray[np.int8]
    lod_key: FloatArray
    surface: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.verts.shape[0])

    @classmethod
    def concat(cls, parts: list[Polygons]) -> Polygons:
        """Concatenate polygon sets."""
        names = list(cls.__dataclass_fields__)
        return cls(**{n: np.concatenate([getattr(p, n) for p in parts]) for n in names})

    def select(self, idx: NDArray) -> Polygons:
        """A subset (mask or indices)."""
        return Polygons(**{n: getattr(self, n)[idx] for n in self.__dataclass_fields__})


class Boxes(NamedTuple):
    """``N`` boxes standing in the world.

    Attributes:
        bottom_centre: ``(N, 3)`` centre of each box's bottom face, world frame.
        R_world_box: ``(N, 3, 3)`` columns = the box's forward, left, up axes.
        size_lwh: ``(N, 3)`` length, width, height, metres.
        colour: ``(N, 3)`` BGR in [0, 1].
        s_near, s_far: ``(N,)`` plan-distance extent (painter key = ``s_near``).
    """

    bottom_centre: FloatArray
    R_world_box: FloatArray
    size_lwh: FloatArray
    colour: FloatArray
    s_near: FloatArray
    s_far: FloatArray


def box_polygons(
    boxes: Boxes,
    material: NDArray[np.int64] | int,
    layer: Layer,
    owner: NDArray[np.int64] | int = -1,
    with_bottom: bool = False,
) -> Polygons:
    """The faces of ``N`` boxes (rear, front, right, left, top; bottom optional) of
    ``material`` in drawing ``layer``, belonging to target ``owner`` (−1: the world)."""
    c, R_world_box, size_lwh, colour, s_near, s_far = boxes
    n = c.shape[0]
    f, lft, up = R_world_box[:, :, 0], R_world_box[:, :, 1], R_world_box[:, :, 2]
    hl, hw, h = (
        (0.5 * size_lwh[:, 0])[:, None],
        (0.5 * size_lwh[:, 1])[:, None],
        size_lwh[:, 2][:, None],
    )

    def corner(sx: float, sy: float, sz: float) -> FloatArray:
        return c + sx * hl * f + sy * hw * lft + sz * h * up

    # face: (corners, outward normal, u axis)
    faces = [
        ([corner(-1, -1, 0), corner(-1, 1, 0), corner(-1, 1, 1), corner(-1, -1, 1)], -f, lft),
        ([corner(1, 1, 0), corner(1, -1, 0), corner(1, -1, 1), corner(1, 1, 1)], f, -lft),
        ([corner(1, -1, 0), corner(-1, -1, 0), corner(-1, -1, 1), corner(1, -1, 1)], -lft, -f),
        ([corner(-1, 1, 0), corner(1, 1, 0), corner(1, 1, 1), corner(-1, 1, 1)], lft, f),
        ([corner(-1, -1, 1), corner(-1, 1, 1), corner(1, 1, 1), corner(1, -1, 1)], up, lft),
    ]
    if with_bottom:
        faces.append(
            ([corner(-1, -1, 0), corner(1, -1, 0), corner(1, 1, 0), corner(-1, 1, 0)], -up, lft)
        )
    parts = []
    mat = np.broadcast_to(np.asarray(material, dtype=np.int64), (n,))
    own = np.broadcast_to(np.asarray(owner, dtype=np.int64), (n,))
    for verts, normal, axis_u in faces:
        v = np.stack(verts, axis=1)
        parts.append(
            Polygons(
                verts=v,
                normal=normal.copy(),
                origin=v[:, 0].copy(),
                axis_u=axis_u.copy(),
                axis_v=up.copy(),
                u0=np.zeros(n),
                key=s_near.copy(),
                layer=np.full(n, int(layer), np.int64),
                s_lo=s_near.copy(),
                s_hi=s_far.copy(),
                material=mat.copy(),
                colour=colour.copy(),
                owner=own.copy(),
                two_sided=np.zeros(n, bool),
                lod=np.full(n, -1, np.int8),
                lod_key=np.zeros(n),
                surface=np.full(n, -1, np.int64),
            )
        )
    return Polygons.concat(parts)


def vehicle_polygons(
    corners_world: FloatArray,
    colours_bgr: FloatArray,
    s_rear: FloatArray,
    s_front: FloatArray,
    owners: NDArray[np.int64],
) -> Polygons:
    """Faces of target boxes from their 8 corners ``(M, 8, 3)`` (order of
    :data:`~slopedist.synthetic.vehicles.BOX_CORNERS_UNIT`); colours BGR in [0, 1]."""
    c = corners_world
    fwd = c[:, 2] - c[:, 0]
    lft = c[:, 1] - c[:, 0]
    up = c[:, 4] - c[:, 0]
    fwd, lft, up = (a / np.linalg.norm(a, axis=1, keepdims=True) for a in (fwd, lft, up))
    faces = [
        ((0, 1, 5, 4), -fwd, lft),
        ((3, 2, 6, 7), fwd, -lft),
        ((2, 0, 4, 6), -lft, -fwd),
        ((1, 3, 7, 5), lft, fwd),
        ((4, 5, 7, 6), up, lft),
    ]
    m = c.shape[0]
    parts = []
    for idx, normal, axis_u in faces:
        v = c[:, list(idx)]
        parts.append(
            Polygons(
                verts=v,
                normal=normal,
                origin=v[:, 0],
                axis_u=axis_u,
                axis_v=up,
                u0=np.zeros(m),
                key=s_rear.copy(),
                layer=np.full(m, int(Layer.VEHICLE)),
                s_lo=s_rear.copy(),
                s_hi=s_front.copy(),
                material=np.full(m, int(Material.VEHICLE)),
                colour=colours_bgr.copy(),
                owner=owners.astype(np.int64),
                two_sided=np.zeros(m, bool),
                lod=np.full(m, -1, np.int8),
                lod_key=np.zeros(m),
                surface=np.full(m, -1, np.int64),
            )
        )
    return Polygons.concat(parts)
