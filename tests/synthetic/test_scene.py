"""Ground truth of the synthetic scenes: vehicle poses, camera, exact 2D boxes, distances."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from slopedist.core import geometry as geo
from slopedist.synthetic.road import GradeChange, Road, RoadSpec
from slopedist.synthetic.scene import CameraSpec, Scenario, simulate_truth
from slopedist.synthetic.vehicles import (
    CameraRig,
    VehicleSpec,
    camera_poses,
    vehicle_poses,
)

H = 1.65


def _scenario(
    road: RoadSpec,
    targets: tuple[VehicleSpec, ...],
    rig: CameraRig | None = None,
    ego_speed: float = 10.0,
) -> Scenario:
    return Scenario(
        "t",
        "",
        road,
        CameraSpec(rig=rig or CameraRig(height_m=H)),
        VehicleSpec(-1, 0.0, 0.0, ego_speed),
        targets,
        duration_s=3.0,
    )


def test_vehicle_pitch_follows_the_grade() -> None:
    road = Road(RoadSpec(start_grade_pct=10.0, s_max_m=200.0))
    poses = vehicle_poses(road, np.array([0.0, 50.0]), 1.75, 2.7)
    np.testing.assert_allclose(poses.pitch_rad, math.atan(0.10), atol=1e-9)
    # bottom centre on the road surface under the vehicle (straight road: on the chord)
    np.testing.assert_allclose(poses.origin_world[:, 2], 0.10 * np.array([0.0, 50.0]), atol=1e-9)
    np.testing.assert_allclose(poses.origin_world[:, 1], 1.75, atol=1e-9)


def test_camera_is_height_above_the_road_and_pitched_by_the_mount() -> None:
    road = Road(RoadSpec(s_max_m=200.0))
    ego = vehicle_poses(road, np.array([5.0]), 0.0, 2.7)
    R, C = camera_poses(ego, CameraRig(height_m=H, mount_angle_rad=math.radians(2.0)))
    np.testing.assert_allclose(C[0], [5.0, 0.0, H], atol=1e-9)
    # optical axis pitched up by 2°: its world z component is sin 2°
    assert R[0][:, 2][2] == pytest.approx(math.sin(math.radians(2.0)))
    # camera y axis points down (world −Z) up to the pitch, x axis to the right (world −Y)
    assert R[0][:, 1][2] < -0.99 and R[0][:, 0][1] == pytest.approx(-1.0)
    assert np.linalg.det(R[0]) == pytest.approx(1.0)


def test_exact_box_bottom_satisfies_eq1_on_a_flat_road() -> None:
    target = VehicleSpec(1, 0.0, 25.0, 10.0)
    truth = simulate_truth(_scenario(RoadSpec(s_max_m=300.0), (target,)))
    cam = CameraSpec()
    u = truth.box[:, 0, 3]
    d = geo.ground_contact_distance(cam.f, H, u, cam.c_y)
    # eq. 1 with the level camera's vanishing line gives the rear contact point exactly
    np.testing.assert_allclose(d, truth.z_rear_m[:, 0], rtol=1e-9)
    np.testing.assert_allclose(truth.z_m[:, 0] - truth.z_rear_m[:, 0], 2.25, atol=1e-9)
    np.testing.assert_allclose(truth.z_m[:, 0], 25.0, atol=1e-9)  # same speed: constant gap
    np.testing.assert_allclose(truth.y_m[:, 0], H, atol=1e-9)  # KITTI y: bottom below camera
    assert truth.distance_m[0, 0] == pytest.approx(math.hypot(25.0, H))
    assert not truth.truncation[:, 0].any()


def test_target_on_an_uphill_sits_above_the_flat_model() -> None:
    road = RoadSpec(grade_changes=(GradeChange(20.0, 12.0, 10.0),), s_max_m=300.0)
    target = VehicleSpec(1, 0.0, 40.0, 0.0)
    truth = simulate_truth(_scenario(road, (target,), ego_speed=0.0))
    cam = CameraSpec()
    z_flat = geo.ground_contact_distance(cam.f, H, truth.box[0, 0, 3], cam.c_y)
    assert truth.target_grade[0, 0] == pytest.approx(0.12)
    assert truth.target_pitch_rad[0, 0] == pytest.approx(math.atan(0.12), abs=1e-6)
    # the box bottom is higher in the image than on a flat road: flat overestimates, or the
    # bottom is already above the vanishing line (NaN)
    assert not z_flat <= truth.z_rear_m[0, 0]


def test_poses_are_relative_to_the_first_camera() -> None:
    road = RoadSpec(grade_changes=(GradeChange(30.0, 8.0, 20.0),), s_max_m=300.0)
    truth = simulate_truth(_scenario(road, (VehicleSpec(1, 0.0, 20.0, 10.0),)))
    P = truth.poses_cam0()
    np.testing.assert_allclose(P[0], np.hstack([np.eye(3), np.zeros((3, 1))]), atol=1e-12)
    # the camera moves forward along its z axis on the flat part
    assert P[5, 2, 3] == pytest.approx(5.0, abs=1e-6)
    # on the hill it has pitched up with the ego: the forward axis gains a −y (up) component
    assert truth.ego_pitch_rad[-1] > 0.03
    assert P[-1, 1, 2] == pytest.approx(-math.sin(truth.ego_pitch_rad[-1]), abs=1e-9)


def test_truncated_target_at_the_image_border() -> None:
    target = VehicleSpec(1, 4.0, 8.0, 10.0)  # close, one lane to the left
    truth = simulate_truth(_scenario(RoadSpec(s_max_m=300.0), (target,)))
    assert truth.in_view[0, 0]
    assert 0.0 < truth.truncation[0, 0] < 1.0
    assert truth.box[0, 0, 0] == 0.0  # clipped at the left border
    assert truth.box_unclipped[0, 0, 0] < 0.0


def test_target_behind_the_camera_is_not_in_view() -> None:
    target = VehicleSpec(1, 3.5, -10.0, 10.0)
    truth = simulate_truth(_scenario(RoadSpec(s_max_m=300.0), (target,)))
    assert not truth.in_view[:, 0].any()
    assert np.isnan(truth.box[:, 0]).all()


def test_duplicate_track_ids_rejected() -> None:
    from slopedist.core.errors import ConfigurationError

    t = VehicleSpec(1, 0.0, 20.0, 10.0)
    with pytest.raises(ConfigurationError, match="unique"):
        _scenario(RoadSpec(), (t, replace(t, start_m=40.0)))
