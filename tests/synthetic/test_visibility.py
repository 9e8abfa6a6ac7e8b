"""The renderer's polygon stage: clipping by hand, and quads culled, kept or clipped as a camera
sees them."""

from __future__ import annotations

import numpy as np

from slopedist.synthetic.polygons import Polygons
from slopedist.synthetic.visibility import (
    NEAR_CLIP_M,
    clip_polygon_near,
    clip_polygon_rect,
    visible_polygons,
)

K = np.array([[100.0, 0.0, 50.0], [0.0, 100.0, 40.0], [0.0, 0.0, 1.0]])
SIZE = (100, 80)


def _quads(verts: np.ndarray, normal: np.ndarray) -> Polygons:
    """Polygons ``(P, 4, 3)`` with one normal each (one-sided), everything else neutral."""
    p = verts.shape[0]
    zeros, ones = np.zeros(p), np.ones(p)
    return Polygons(
        verts=verts,
        normal=normal,
        origin=verts[:, 0],
        axis_u=np.tile([1.0, 0.0, 0.0], (p, 1)),
        axis_v=np.tile([0.0, 1.0, 0.0], (p, 1)),
        u0=zeros,
        key=zeros,
        layer=np.zeros(p, np.int64),
        s_lo=zeros,
        s_hi=ones,
        material=np.ones(p, np.int64),
        colour=np.ones((p, 3)),
        owner=np.full(p, -1, np.int64),
        two_sided=np.zeros(p, bool),
        lod=np.full(p, -1, np.int8),
        lod_key=zeros,
        surface=np.full(p, -1, np.int64),
    )


def _square(z: float, half: float = 1.0) -> np.ndarray:
    return np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])


def test_clip_at_the_near_plane() -> None:
    poly = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 2.0], [0.0, 0.0, 2.0]])
    out = clip_polygon_near(poly)
    expected = [[1.0, 0.0, NEAR_CLIP_M], [1.0, 0.0, 2.0], [0.0, 0.0, 2.0], [0.0, 0.0, NEAR_CLIP_M]]
    np.testing.assert_allclose(out, expected)
    assert clip_polygon_near(poly - [0.0, 0.0, 5.0]).shape == (0, 3)  # all behind


def test_clip_to_a_rectangle() -> None:
    triangle = np.array([[-10.0, 5.0], [10.0, 5.0], [10.0, 25.0]])
    out = clip_polygon_rect(triangle, 0.0, 0.0, 20.0, 10.0)
    # x ≥ 0 cuts the hypotenuse (y = x + 15) at (0, 15), y ≤ 10 leaves a 10 × 5 rectangle
    np.testing.assert_allclose(out, [[0.0, 5.0], [10.0, 5.0], [10.0, 10.0], [0.0, 10.0]])
    assert clip_polygon_rect(triangle, 20.0, 0.0, 30.0, 10.0).shape == (0, 2)  # outside


def test_front_faces_are_projected_back_faces_and_hidden_ones_dropped() -> None:
    verts = np.stack(
        [_square(10.0), _square(10.0), _square(-10.0), _square(10.0) + np.array([500.0, 0, 0])]
    )
    normal = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    # 0: facing the camera; 1: its back; 2: behind the camera; 3: far off the image
    kept, outlines = visible_polygons(
        _quads(verts, normal), np.arange(4), np.eye(3), np.zeros(3), K, SIZE
    )
    assert kept.tolist() == [0]
    # ±1 m at 10 m: ±10 pixels around the principal point, in 1/16 pixel
    expected = np.array([[40, 30], [60, 30], [60, 50], [40, 50]]) * 16
    np.testing.assert_array_equal(outlines[0], expected)


def test_a_polygon_crossing_the_near_plane_is_clipped() -> None:
    # a floor 1 m below the camera from 1 m behind it to 20 m ahead
    verts = np.array([[[-2.0, 1.0, -1.0], [2.0, 1.0, -1.0], [2.0, 1.0, 20.0], [-2.0, 1.0, 20.0]]])
    kept, outlines = visible_polygons(
        _quads(verts, np.array([[0.0, -1.0, 0.0]])), np.arange(1), np.eye(3), np.zeros(3), K, SIZE
    )
    assert kept.tolist() == [0]
    q = outlines[0] / 16.0
    # the near edge where the floor crosses z = 0.3 m: 1/0.3 m → 333.3 px below the principal
    # point and ±2/0.3 m → ±666.7 px to the sides; the far edge at 20 m: 5 px below, ±10 px
    expected = [[716.6667, 373.3333], [60.0, 45.0], [40.0, 45.0], [-616.6667, 373.3333]]
    np.testing.assert_allclose(q, expected, atol=1 / 32)
