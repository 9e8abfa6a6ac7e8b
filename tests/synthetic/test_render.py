"""Renderer against the geometry: box bottoms where eq. 1 says, depth on the true surfaces,
silhouettes matching the exact boxes, occlusion, determinism.

OpenCV's polygon fill covers pixels up to half a pixel outside an edge, so occlusion
boundaries are exact to about one pixel; tolerances below are one and a half pixels (or the
surface footprint of one and a half pixels at the point's depth)."""

from __future__ import annotations

import numpy as np
import pytest

from slopedist.core import geometry as geo
from slopedist.synthetic.road import GradeChange, RoadSpec
from slopedist.synthetic.scenarios import load_scenario
from slopedist.synthetic.scene import CameraSpec, Scenario
from slopedist.synthetic.sequence import SyntheticSequence
from slopedist.synthetic.vehicles import CameraRig, VehicleSpec

H = 1.65


def _sequence(road: RoadSpec, targets: tuple[VehicleSpec, ...], seed: int = 3) -> SyntheticSequence:
    sc = Scenario(
        "test",
        "",
        road,
        CameraSpec(rig=CameraRig(height_m=H)),
        VehicleSpec(-1, -1.75, 0.0, 10.0),
        targets,
        duration_s=2.0,
        seed=seed,
    )
    return SyntheticSequence(sc)


PIXEL_TOL = 1.5


def _back_project(
    seq: SyntheticSequence, k: int, depth: np.ndarray, mask: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World points ``(N, 3)`` of the pixels in ``mask`` from the depth map, and their depth."""
    cam = seq.scenario.camera
    ii, jj = np.nonzero(mask)
    z = depth[ii, jj].astype(float)
    X_cam = np.stack([(jj - cam.c_x) / cam.f * z, (ii - cam.c_y) / cam.f * z, z], axis=-1)
    return X_cam @ seq.truth.R_world_cam[k].T + seq.truth.centre_world[k], z


@pytest.mark.parametrize("distance", [12.0, 25.0, 45.0])
def test_rendered_box_bottom_sits_where_eq1_says(distance: float) -> None:
    seq = _sequence(RoadSpec(s_max_m=300.0), (VehicleSpec(1, -1.75, distance, 10.0),))
    r = seq.render(0)
    rows = np.nonzero((r.owner == 0).any(axis=1))[0]
    cam = seq.camera
    z_rear = seq.truth.z_rear_m[0, 0]
    u_eq1 = cam.c_y + cam.f * H / z_rear  # eq. 1 solved for u, level camera: v = c_y
    assert abs(rows.max() - u_eq1) <= 1.0  # the bottom row of pixels covers u
    # and eq. 1 read back from the rendered bottom row lands within a pixel's worth of depth
    d = geo.ground_contact_distance(cam.f, H, rows.max() + 0.5, cam.c_y)
    assert abs(d - z_rear) < z_rear**2 / (cam.f * H)


@pytest.mark.parametrize(
    "name,frames",
    [("target_steep_uphill", (0, 60, 110)), ("ego_crest", (30, 90)), ("same_flat", (50,))],
)
def test_silhouettes_match_the_exact_boxes(name: str, frames: tuple[int, ...]) -> None:
    seq = SyntheticSequence(load_scenario(name))
    for k in frames:
        r = seq.render(k)
        share = seq.visible_share(k, r)
        for m in np.flatnonzero(seq.truth.in_view[k] & (share > 0.99)):
            ys, xs = np.nonzero(r.owner == m)
            box = seq.truth.box[k, m]
            assert abs(xs.min() - box[0]) <= PIXEL_TOL and abs(xs.max() - box[2]) <= PIXEL_TOL
            assert abs(ys.min() - box[1]) <= PIXEL_TOL and abs(ys.max() - box[3]) <= PIXEL_TOL


def test_depth_of_road_pixels_lies_on_the_road_surface() -> None:
    # a straight road over a sag and a crest: road pixels back-projected with the depth map
    # must land on the road's surface
    road = RoadSpec(
        start_grade_pct=-4.0,
        grade_changes=(GradeChange(40.0, 8.0, 40.0), GradeChange(120.0, -5.0, 60.0)),
        s_max_m=400.0,
    )
    seq = _sequence(road, (VehicleSpec(1, -1.75, 20.0, 10.0),))
    for k in (0, 15):
        r = seq.render(k)
        X, _ = _back_project(seq, k, r.depth_m, np.isfinite(r.depth_m) & (r.owner < 0))
        on_road = np.abs(X[:, 1]) < road.half_width_m - 0.3
        assert on_road.sum() > 0.1 * r.depth_m.size
        z_road = seq.road.elevation(X[on_road, 0])  # straight road: s = X
        np.testing.assert_allclose(X[on_road, 2], z_road, atol=0.02)


def test_depth_of_vehicle_pixels_lies_on_the_box_faces() -> None:
    road = RoadSpec(grade_changes=(GradeChange(30.0, 10.0, 20.0),), s_max_m=300.0)
    spec = VehicleSpec(1, 1.75, 28.0, 8.0)
    seq = _sequence(road, (spec,))
    k = 10
    r = seq.render(k)
    mask = r.owner == 0
    X, _ = _back_project(seq, k, r.depth_m, mask)
    c = seq.truth.corners_world[k, 0]
    origin = c[:4].mean(axis=0)
    axes = np.stack([c[2] - c[0], c[1] - c[0], c[4] - c[0]])
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    local = (X - origin) @ axes.T  # forward, left, up, metres
    lo = np.array([-spec.length_m / 2, -spec.width_m / 2, 0.0])
    hi = np.array([spec.length_m / 2, spec.width_m / 2, spec.height_m])
    assert len(local) > 100
    # every point is on the plane of a face (the depth comes from the face's own plane) ...
    gap = np.min(np.abs(np.concatenate([local - lo, local - hi], axis=1)), axis=1)
    assert np.all(gap < 1e-3)
    # ... and within the face up to the fill rule: the nearest point of the box projects
    # within 1.5 pixels of the pixel
    nearest = origin + np.clip(local, lo, hi) @ axes
    cam = seq.scenario.camera
    pc = (nearest - seq.truth.centre_world[k]) @ seq.truth.R_world_cam[k]
    px = pc[:, :2] / pc[:, 2:3] * cam.f + np.array([cam.c_x, cam.c_y])
    ii, jj = np.nonzero(mask)
    assert np.all(np.hypot(px[:, 0] - jj, px[:, 1] - ii) <= PIXEL_TOL)


def test_nearer_target_hides_the_farther_one() -> None:
    seq = _sequence(
        RoadSpec(s_max_m=300.0),
        (VehicleSpec(1, -1.75, 14.0, 10.0), VehicleSpec(2, -1.75, 30.0, 10.0)),
    )
    share = seq.visible_share(0, seq.render(0))
    assert share[0] == pytest.approx(1.0, abs=0.02)
    assert share[1] < 0.5


def test_rendering_is_deterministic_and_seeded() -> None:
    targets = (VehicleSpec(1, -1.75, 20.0, 10.0),)
    a = _sequence(RoadSpec(s_max_m=300.0), targets, seed=3)
    b = _sequence(RoadSpec(s_max_m=300.0), targets, seed=3)
    c = _sequence(RoadSpec(s_max_m=300.0), targets, seed=4)
    ra, rb, rc = a.render(5), b.render(5), c.render(5)
    assert np.array_equal(ra.image, rb.image) and np.array_equal(ra.depth_m, rb.depth_m)
    assert not np.array_equal(ra.image, rc.image)
    assert ra.image.shape == (375, 1242, 3) and ra.depth_m.dtype == np.float32


def test_texture_everywhere_below_the_horizon() -> None:
    # a tracker needs corners on the road and the roadside, not flat colours
    import cv2

    seq = SyntheticSequence(load_scenario("same_flat"))
    gray = cv2.cvtColor(seq.render(0).image, cv2.COLOR_BGR2GRAY)
    corners = cv2.goodFeaturesToTrack(gray, 3000, 0.003, 8).reshape(-1, 2)
    below = corners[corners[:, 1] > seq.camera.c_y + 20]
    thirds = np.digitize(below[:, 0], [414, 828])
    assert len(below) > 400
    assert np.bincount(thirds, minlength=3).min() > 100  # left roadside, road, right roadside


@pytest.mark.parametrize(
    "name,k",
    [("ego_crest", 60), ("bumps_and_curves", 30), ("target_steep_uphill", 80), ("curve_flat", 45)],
)
def test_interpolated_cells_match_the_exact_evaluation(name: str, k: int) -> None:
    # the renderer draws most cells from a coarse grid; the same frame evaluated pixel by pixel
    # from each polygon's own plane is the reference: depth equal to float32 rounding on single
    # planes and to the surface's smoothness across ground strips; colours within noise
    from slopedist.synthetic.render import Renderer

    seq = SyntheticSequence(load_scenario(name))
    fast = seq.render(k)
    r = seq.renderer
    seq.renderer = Renderer(
        r.static, r.K, r.width, r.height, r.layout, seq.scenario.seed, interpolate=False
    )
    exact = seq.render(k)
    assert np.array_equal(fast.labels, exact.labels)
    sky = ~np.isfinite(exact.depth_m)
    assert np.array_equal(sky, ~np.isfinite(fast.depth_m))
    rel = np.abs(fast.depth_m[~sky] / exact.depth_m[~sky] - 1.0)
    vehicle = exact.owner[~sky] >= 0
    assert rel[vehicle].max() < 1e-4  # single planes: exact
    assert rel.max() < 2e-3 and np.median(rel) < 1e-5
    diff = np.abs(fast.image.astype(int) - exact.image.astype(int))
    # differences: mip levels rounded either side of a level's edge; on curves the texture
    # frames of neighbouring ground strips and wall pieces do not quite meet (seams of a few
    # texels, as the world is built), which the interpolation smooths
    assert diff.mean() < 0.8 and np.percentile(diff, 99.9) <= 28


def test_tall_structures_are_refused() -> None:
    from slopedist.core.errors import ConfigurationError
    from slopedist.synthetic.scene import WorldSpec

    with pytest.raises(ConfigurationError, match="structure_height_m"):
        WorldSpec(structure_height_m=(3.0, 40.0))
    with pytest.raises(ConfigurationError, match="structure_segment_m"):
        WorldSpec(structure_segment_m=(6.0, 60.0))


def test_depth_is_positive_or_infinite() -> None:
    # pixels the fill reaches past a far polygon's horizon are seen at infinity, not behind
    # the camera (same_flat frame 27 has three at the horizon)
    import warnings

    seq = SyntheticSequence(load_scenario("same_flat"))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        for k in (0, 27, 80):
            d = seq.render(k).depth_m
            assert not np.isnan(d).any() and np.all(d > 0)


def test_depth_map_made_on_request_matches_the_labels() -> None:
    # the depth map is made when first asked for: the same map from the frame and the render,
    # +inf where the sky is seen, positive elsewhere (finite but for pixels the fill reaches
    # past a far polygon's horizon)
    seq = SyntheticSequence(load_scenario("ego_crest"))
    frame, r = seq.frame(60), seq.render(60)
    d = frame.depth_m
    assert d is frame.depth_m and d.flags.c_contiguous and d.shape == r.labels.shape
    np.testing.assert_array_equal(d, r.depth_m)
    sky = r.labels == 0
    assert sky.any() and np.all(np.isinf(d[sky]))
    assert np.all(d[~sky] > 0) and np.isfinite(d[~sky]).mean() > 0.999
