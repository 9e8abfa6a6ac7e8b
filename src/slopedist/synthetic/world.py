"""The static world around the road, as planar polygons the renderer draws.

Convention: world frame of :mod:`~slopedist.synthetic.road` (X forward at ``s = 0``,
Y left, Z up, metres); polygons and their texture frames as in
:mod:`~slopedist.synthetic.polygons`.

Content:

- the ground: the road surface extended across the verge to the roadside structures, as strips
  between consecutive cross-sections (``GROUND_STEP_M`` apart); its texture frame is the road's
  (``u`` = distance driven along the centreline, ``v`` = lateral offset ``w``), so the renderer
  can draw the lane markings and tell asphalt from verge per pixel;
- roadside structures on both sides (building fronts and tree lines of random height), vertical
  walls at the corridor's edge (``u`` along the road, ``v`` height above the segment's base);
- delineator posts on both edges of the carriageway and random roadside objects (bushes,
  cabinets, sign boxes), as boxes standing on the ground.

Everything random comes from ``numpy.random.default_rng(seed)`` and depends only on the seed.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slopedist.synthetic.polygons import (
    GROUND_SURFACE,
    Boxes,
    Layer,
    Material,
    Polygons,
    box_polygons,
)
from slopedist.synthetic.road import Road

FloatArray = NDArray[np.float64]

GROUND_STEP_M = 0.5
"""Length of the ground strips along the road, metres."""
WALL_PIECE_M = 2.0
"""Longest piece of a roadside wall along the road, metres."""
COARSE_GROUND_M = 4.0
"""Length of the ground strips drawn far from the camera (coarse level of detail), metres."""
COARSE_WALL_PIECE_M = 8.0
"""Longest piece of a roadside wall far from the camera (coarse level of detail), metres."""
WALL_FOOT_M = 0.3
"""Depth to which the roadside walls reach below the ground (no gap under them), metres."""


def ground_polygons(
    road: Road, half_width_m: float, step_m: float = GROUND_STEP_M, lod: int = 0
) -> Polygons:
    """Ground strips across ``±half_width_m`` between cross-sections ``step_m`` apart, on a
    grid that starts 1 m into the road (level of detail ``lod``; groups of
    ``COARSE_GROUND_M``)."""
    origin = road.s[0] + 1.0
    s = np.arange(origin, road.s[-1] - 1.0, step_m)
    a, b = s[:-1], s[1:]
    n = a.shape[0]
    w = np.full(n, half_width_m)
    verts = np.stack(
        [road.point(a, -w), road.point(a, w), road.point(b, w), road.point(b, -w)], axis=1
    )
    mid = 0.5 * (a + b)
    t = road.tangent(mid)
    lft = road.left(mid)
    normal = np.cross(t, lft)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    grey = np.ones((n, 3))
    return Polygons(
        verts=verts,
        normal=normal,
        origin=road.centre(mid),
        axis_u=t,
        axis_v=lft,
        u0=road.driven_distance(mid),
        key=b.copy(),
        layer=np.full(n, int(Layer.GROUND)),
        s_lo=a.copy(),
        s_hi=b.copy(),
        material=np.full(n, int(Material.GROUND)),
        colour=grey,
        owner=np.full(n, -1),
        two_sided=np.ones(n, bool),
        lod=np.full(n, lod, np.int8),
        lod_key=origin + np.floor((a - origin) / COARSE_GROUND_M + 1e-9) * COARSE_GROUND_M,
        surface=np.full(n, GROUND_SURFACE, np.int64),
    )


BUILDING_COLOURS = np.array(
    [
        [0.62, 0.70, 0.78],
        [0.55, 0.60, 0.72],
        [0.70, 0.72, 0.70],
        [0.45, 0.50, 0.62],
        [0.60, 0.62, 0.55],
        [0.75, 0.78, 0.82],
        [0.50, 0.55, 0.60],
    ]
)
"""BGR colours of building fronts (light plaster, brick, concrete)."""
TREE_COLOURS = np.array([[0.20, 0.42, 0.28], [0.18, 0.36, 0.30], [0.25, 0.45, 0.35]])
OBJECT_COLOURS = np.array(
    [
        [0.18, 0.45, 0.25],
        [0.22, 0.38, 0.30],
        [0.55, 0.55, 0.55],
        [0.30, 0.40, 0.55],
        [0.65, 0.60, 0.30],
        [0.20, 0.30, 0.50],
    ]
)


def structure_polygons(
    road: Road,
    half_width_m: float,
    height_range: tuple[float, float],
    length_range: tuple[float, float],
    rng: np.random.Generator,
) -> Polygons:
    """Walls of buildings and tree lines at lateral offsets ``±half_width_m``; each wall
    segment is one surface (ids from ``GROUND_SURFACE + 1``)."""
    parts = []
    next_surface = GROUND_SURFACE + 1
    for side in (-1.0, 1.0):
        edges = [road.s[0] + 1.0]
        while edges[-1] < road.s[-1] - 1.0:
            edges.append(edges[-1] + rng.uniform(*length_range))
        e = np.minimum(np.asarray(edges), road.s[-1] - 1.0)
        a, b = e[:-1], e[1:]
        keep = b > a + 0.1
        a, b = a[keep], b[keep]
        height = rng.uniform(*height_range, a.shape[0])
        trees = rng.random(a.shape[0]) < 0.35
        colour_index = rng.integers(0, 1 << 30, a.shape[0])
        shade = rng.uniform(0.85, 1.15, a.shape[0])
        surface = next_surface + np.arange(a.shape[0])
        next_surface += a.shape[0]
        segments = _WallSegments(a, b, height, trees, colour_index, shade, surface)
        for lod, piece_m in ((0, WALL_PIECE_M), (1, COARSE_WALL_PIECE_M)):
            parts.append(_wall_pieces(road, side, half_width_m, segments, piece_m, lod))
    return Polygons.concat(parts)


class _WallSegments(NamedTuple):
    """The wall segments of one side of the road (``(S,)`` each).

    Attributes:
        a, b: plan-distance extent of each segment, metres.
        height: height above the ground at the segment's start, metres.
        trees: a tree line (else a building front).
        colour_index: random index into the colour tables; shade: brightness factor.
        surface: surface id of each segment (:attr:`Polygons.surface`).
    """

    a: FloatArray
    b: FloatArray
    height: FloatArray
    trees: NDArray[np.bool_]
    colour_index: NDArray[np.int64]
    shade: FloatArray
    surface: NDArray[np.int64]


def _wall_pieces(
    road: Road,
    side: float,
    half_width_m: float,
    segments: _WallSegments,
    piece_m: float,
    lod: int,
) -> Polygons:
    """The wall segments ``[a, b]`` of one side cut into pieces of at most ``piece_m``.

    Texture frame of every piece of a segment: ``u`` = distance driven along the centreline
    at the piece's start plus the distance along the piece, ``v`` = height above the ground at
    the segment's start (level rows of windows, continuous from piece to piece)."""
    a, b, height, trees, colour_index, shade, surface = segments
    # pieces of at most piece_m, so the wall's foot follows the ground through
    # vertical and horizontal curves (a long chord would leave a gap under it)
    pieces = np.maximum(np.ceil((b - a) / piece_m), 1).astype(int)
    seg = np.repeat(np.arange(a.shape[0]), pieces)
    j = np.arange(seg.shape[0]) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    step = (b - a) / pieces
    group = a[seg]
    w_seg = np.full(a.shape[0], side * half_width_m)
    base_z = road.point(a, w_seg)[:, 2][seg]
    a, b = a[seg] + j * step[seg], a[seg] + (j + 1) * step[seg]
    height, trees = height[seg], trees[seg]
    colour_index, shade, surface = colour_index[seg], shade[seg], surface[seg]
    n = a.shape[0]
    w = np.full(n, side * half_width_m)
    pa, pb = road.point(a, w), road.point(b, w)
    up = np.array([0.0, 0.0, 1.0])
    top_a, top_b = pa + height[:, None] * up, pb + height[:, None] * up
    # the foot reaches WALL_FOOT_M below the ground; the ground strips in front, drawn
    # after the wall (painter key = the piece's far end), cover it
    foot = WALL_FOOT_M * up
    verts = np.stack([pa - foot, pb - foot, top_b, top_a], axis=1)
    along = pb - pa
    along /= np.linalg.norm(along, axis=1, keepdims=True)
    normal = -side * road.left(0.5 * (a + b))  # inward: from the wall to the road
    colour = np.where(
        trees[:, None],
        TREE_COLOURS[colour_index % len(TREE_COLOURS)],
        BUILDING_COLOURS[colour_index % len(BUILDING_COLOURS)],
    )
    colour = colour * shade[:, None]
    origin = pa.copy()
    origin[:, 2] = base_z  # v = height above the segment's start
    # u at the piece's start stays the driven distance there
    u0 = road.driven_distance(a) - (pa[:, 2] - base_z) * along[:, 2]
    return Polygons(
        verts=verts,
        normal=normal,
        origin=origin,
        axis_u=along,
        axis_v=np.broadcast_to(up, (n, 3)).copy(),
        u0=u0,
        key=b.copy(),
        layer=np.full(n, int(Layer.STRUCTURE)),
        s_lo=a.copy(),
        s_hi=b.copy(),
        material=np.where(trees, int(Material.TREES), int(Material.BUILDING)),
        colour=np.clip(colour, 0, 1),
        owner=np.full(n, -1),
        two_sided=np.zeros(n, bool),
        lod=np.full(n, lod, np.int8),
        lod_key=group,
        surface=surface.astype(np.int64),
    )


def _level_boxes_on_road(road: Road, s: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Bottom centres and level, road-aligned orientations of boxes standing at ``(s, w)``."""
    psi = road.heading_at(s)
    f = np.stack([np.cos(psi), np.sin(psi), np.zeros_like(psi)], axis=1)
    lft = np.stack([-np.sin(psi), np.cos(psi), np.zeros_like(psi)], axis=1)
    up = np.broadcast_to(np.array([0.0, 0.0, 1.0]), f.shape)
    return road.point(s, w), np.stack([f, lft, up], axis=2)


def roadside_polygons(
    road: Road,
    carriageway_half_m: float,
    corridor_half_m: float,
    post_spacing_m: float,
    object_spacing_m: float,
    rng: np.random.Generator,
) -> Polygons:
    """Delineator posts on both edges and random objects in the verges."""
    s0, s1 = road.s[0] + 2.0, road.s[-1] - 2.0
    # posts
    sp = np.arange(s0 + rng.uniform(0, post_spacing_m), s1, post_spacing_m)
    s_post = np.concatenate([sp, sp])
    w_post = np.concatenate(
        [
            np.full(sp.shape, carriageway_half_m + 0.8),
            np.full(sp.shape, -(carriageway_half_m + 0.8)),
        ]
    )
    c, R = _level_boxes_on_road(road, s_post, w_post)
    n = s_post.shape[0]
    size = np.tile([0.12, 0.12, 1.0], (n, 1))
    post_colour = np.tile([0.92, 0.92, 0.92], (n, 1))
    posts = box_polygons(
        Boxes(c, R, size, post_colour, s_post - 0.06, s_post + 0.06),
        int(Material.POST),
        Layer.OBJECT,
    )
    # objects
    count = int((s1 - s0) / object_spacing_m * 2)
    s_obj = rng.uniform(s0, s1, count)
    side = np.where(rng.random(count) < 0.5, -1.0, 1.0)
    lo, hi = carriageway_half_m + 1.6, corridor_half_m - 0.8
    size = np.stack(
        [rng.uniform(0.4, 2.5, count), rng.uniform(0.4, 1.5, count), rng.uniform(0.4, 2.8, count)],
        axis=1,
    )
    w_obj = side * np.clip(rng.uniform(lo, hi, count), lo + 0.5 * size[:, 1], hi - 0.5 * size[:, 1])
    c, R = _level_boxes_on_road(road, s_obj, w_obj)
    colour = OBJECT_COLOURS[rng.integers(0, len(OBJECT_COLOURS), count)] * rng.uniform(
        0.8, 1.2, (count, 1)
    )
    objects = box_polygons(
        Boxes(
            c, R, size, np.clip(colour, 0, 1), s_obj - 0.5 * size[:, 0], s_obj + 0.5 * size[:, 0]
        ),
        int(Material.OBJECT),
        Layer.OBJECT,
    )
    return Polygons.concat([posts, objects])


def static_world(
    road: Road,
    corridor_half_m: float,
    carriageway_half_m: float,
    structure_height_m: tuple[float, float],
    structure_segment_m: tuple[float, float],
    post_spacing_m: float,
    object_spacing_m: float,
    seed: int,
) -> Polygons:
    """All static polygons of the world, in painter order (far to near, ground first)."""
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x5EED])
    polys = Polygons.concat(
        [
            ground_polygons(road, corridor_half_m, GROUND_STEP_M, 0),
            ground_polygons(road, corridor_half_m, COARSE_GROUND_M, 1),
            structure_polygons(road, corridor_half_m, structure_height_m, structure_segment_m, rng),
            roadside_polygons(
                road, carriageway_half_m, corridor_half_m, post_spacing_m, object_spacing_m, rng
            ),
        ]
    )
    order = np.lexsort((polys.layer, -polys.key))
    return polys.select(order)
