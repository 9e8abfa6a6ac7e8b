"""Box faces: outward normals, the corners where the box is, and the same faces whether a box is
given by its pose and size or by its 8 corners."""

from __future__ import annotations

import numpy as np

from slopedist.synthetic.polygons import (
    Boxes,
    Layer,
    Material,
    box_polygons,
    vehicle_polygons,
)
from slopedist.synthetic.vehicles import BOX_CORNERS_UNIT


def _box(yaw: float) -> Boxes:
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]])  # forward, left, up columns
    return Boxes(
        np.array([[10.0, 2.0, 0.5]]),
        R,
        np.array([[4.0, 2.0, 1.5]]),
        np.array([[0.2, 0.3, 0.4]]),
        np.array([8.0]),
        np.array([12.0]),
    )


def test_faces_point_outwards_and_lie_on_the_box() -> None:
    box = _box(0.3)
    polys = box_polygons(box, int(Material.OBJECT), Layer.OBJECT, with_bottom=True)
    assert len(polys) == 6
    centre = box.bottom_centre[0] + 0.75 * box.R_world_box[0][:, 2]  # half the height up
    face_centres = polys.verts.mean(axis=1)
    np.testing.assert_allclose(np.linalg.norm(polys.normal, axis=1), 1.0)
    # each face's centre is half the box's size along its normal from the box's centre
    half = np.array([2.0, 2.0, 1.0, 1.0, 0.75, 0.75])
    np.testing.assert_allclose(np.einsum("pi,pi->p", face_centres - centre, polys.normal), half)
    # every corner of a face lies in its plane
    d = np.einsum("pki,pi->pk", polys.verts - face_centres[:, None], polys.normal)
    np.testing.assert_allclose(d, 0.0, atol=1e-12)
    assert np.all(polys.key == 8.0) and np.all(polys.owner == -1)
    assert np.all(polys.layer == int(Layer.OBJECT))


def test_vehicle_faces_from_corners_match_the_box_faces() -> None:
    box = _box(-0.2)
    local = BOX_CORNERS_UNIT * box.size_lwh[0]
    corners = box.bottom_centre[0] + local @ box.R_world_box[0].T
    owners = np.array([3])
    v = vehicle_polygons(corners[None], box.colour, box.s_near, box.s_far, owners)
    b = box_polygons(box, int(Material.VEHICLE), Layer.VEHICLE, owner=owners)
    np.testing.assert_allclose(v.verts, b.verts, atol=1e-12)
    np.testing.assert_allclose(v.normal, b.normal, atol=1e-12)
    assert np.array_equal(v.owner, b.owner) and np.array_equal(v.material, b.material)
