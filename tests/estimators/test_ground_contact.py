"""Per-box states of the ground-contact methods at the image border (hand-computed).

Camera f = 720 px, c_y = 180 px, h = 1.65 m, image 1240 × 375: eq. 1 on a level road is
``d = 720 · 1.65 / (u − 180) = 1188 / (u − 180)`` metres for a box bottom at row ``u``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.estimators import make_estimator
from slopedist.estimators.base import EstimateStatus
from slopedist.evaluation.metrics import cap_estimates
from slopedist.io.detections.boxes import BoxTable
from slopedist.streaming.step import FrameStep, iter_records

W, H = 1240, 375
CAMERA = Camera(720.0, 620.0, 180.0, height_m=1.65).with_image_size(W, H)
FH = 720.0 * 1.65


def settled(method: str, boxes: list[list[float]], classes: list[str] | None = None, cam=CAMERA):
    """A frame through :class:`FrameStep` (θ = 0, level camera)."""
    step = FrameStep(make_estimator(method, cam))
    table = BoxTable.build(np.zeros(len(boxes)), boxes, classes=classes)
    return step.estimate(0, 0.0, 0.0, np.eye(3), table)


def test_a_car_cut_by_the_bottom_is_an_upper_bound_above_its_true_distance() -> None:
    """A car 5 m ahead touches the road at row 180 + 1188/5 = 417.6, below the image: its box
    ends at the last row (374), which reads 1188/194 = 6.12 m ≥ 5 m."""
    true_z = 5.0
    contact_row = 180.0 + FH / true_z
    assert contact_row > H
    box = [560.0, 180.0 + 720 * (1.65 - 1.5) / true_z, 680.0, H - 1.0]
    for method in ("flat", "ego", "paper", "imu", "imu-ego"):
        est = settled(method, [box])
        assert est.status[0] == "upper_bound" and est.reason[0] == "cut_bottom"
        assert est.cut[0] == "bottom"
        assert est.distance_m[0] == pytest.approx(FH / (H - 1 - 180))
        assert est.distance_m[0] >= true_z


@pytest.mark.parametrize(
    ("box", "cut", "status", "reason", "distance"),
    [
        ([0.0, 200, 300, 300], "left", "ok", "", FH / 120),
        ([900, 200, 1239.0, 300], "right", "ok", "", FH / 120),
        ([500, 0.5, 700, 300], "top", "ok", "", FH / 120),
        ([-80, 200, 300, 374.0], "left+bottom", "upper_bound", "cut_bottom", FH / 194),
        ([500, 0.0, 700, 380.0], "top+bottom", "upper_bound", "cut_bottom", FH / 200),
        ([500, 200, 700, 300], "", "ok", "", FH / 120),
        ([1300, 200, 1400, 300], "", "missing", "outside_image", math.nan),
        ([500, 200, 500.4, 300], "", "missing", "degenerate_box", math.nan),
        ([500, 100, 700, 150], "", "missing", "below_horizon", math.nan),
    ],
)
def test_each_edge_by_hand(
    box: list[float], cut: str, status: str, reason: str, distance: float
) -> None:
    est = settled("ego", [box])  # θ = 0: the vanishing line is c_y (eq. 5)
    assert (est.cut[0], est.status[0], est.reason[0]) == (cut, status, reason)
    np.testing.assert_allclose(est.distance_m[0], distance, equal_nan=True)


def test_without_an_image_size_no_box_is_tested_against_the_border() -> None:
    cam = Camera(720.0, 620.0, 180.0, height_m=1.65)
    est = settled("flat", [[560, 190, 680, 374.0], [1300, 200, 1400, 300]], cam=cam)
    assert list(est.status) == ["ok", "ok"] and list(est.cut) == ["", ""]


def test_depthmap_keeps_a_cut_box_ok_with_its_flag() -> None:
    """The centre pixel of a box cut by the bottom is still on the vehicle."""
    depth = np.full((H, W), 5.0, dtype=np.float32)
    step = FrameStep(make_estimator("depthmap", CAMERA))
    table = BoxTable.build([0], [[560, 190, 680, 374.0]])
    est = step.estimate(0, 0.0, math.nan, None, table, None, depth)
    assert (est.status[0], est.cut[0], est.distance_m[0]) == ("ok", "bottom", 5.0)


def test_other_classes_are_missing_not_a_vehicle_for_every_method() -> None:
    boxes = [[500, 200, 700, 300]] * 4
    classes = ["Car", "Pedestrian", "DontCare", "van"]
    for method in ("flat", "paper", "ours"):
        est = settled(method, boxes, classes)
        assert list(est.reason[1:3]) == ["not_a_vehicle"] * 2, method
        assert list(est.status) == ["ok", "missing", "missing", "ok"], method
        assert np.isnan(est.distance_m[1:3]).all()
    step = FrameStep(make_estimator("flat", CAMERA), vehicle_classes=("Pedestrian",))
    est = step.estimate(0, 0.0, 0.0, None, BoxTable.build([0, 0], boxes[:2], classes=classes[:2]))
    assert list(est.status) == ["missing", "ok"]


def test_the_box_states_hold_for_ours_too() -> None:
    """Whatever a method says, outside/degenerate boxes are missing and cut boxes flagged;
    ``ours`` states itself what a cut box still tells (tests/estimators/test_ours_border.py):
    a bottom cut with both sides in view keeps its width cue, ``ok``."""
    boxes = [[1300, 200, 1400, 300], [500, 200, 500.2, 300], [0, 200, 300, 300]]
    est = settled("ours", [*boxes, [560, 190, 680, 374.0]])
    assert list(est.reason) == ["outside_image", "degenerate_box", "", ""]
    assert list(est.status) == ["missing", "missing", "ok", "ok"]
    assert list(est.cut) == ["", "", "left", "bottom"] and est.distance_m[3] > 0


def test_records_carry_status_and_cut_and_an_upper_bound_is_not_scored() -> None:
    boxes = [[500, 200, 700, 300], [560, 190, 680, 374.0], [1300, 200, 1400, 300]]
    est = settled("flat", boxes)
    table = BoxTable.build(np.zeros(3), boxes)
    rows = list(iter_records(table, 0.0, est, "flat"))
    assert [(r["status"], r["reason"], r["cut"]) for r in rows] == [
        ("ok", "", ""),
        ("upper_bound", "cut_bottom", "bottom"),
        ("missing", "outside_image", ""),
    ]
    assert rows[1]["distance_m"] == pytest.approx(FH / 194) and math.isnan(rows[2]["distance_m"])
    _, scorable = cap_estimates(est.distance_m, est.reason)
    assert list(scorable) == [True, False, False]
    assert EstimateStatus(rows[1]["status"]) is EstimateStatus.UPPER_BOUND


def test_the_kitti_raw_lead_car_cut_by_the_bottom_reads_at_least_its_lidar_distance(
    kitti_raw_lead_dir,
) -> None:
    """A lead car 4.2–4.8 m ahead (LiDAR nearest face) whose box is cut by
    the image bottom read 5.9 m ``ok``; it is now an upper bound, and it is one."""
    from slopedist.io.kitti.raw import KittiRawDrive, lidar_vehicle_boxes, read_velodyne

    drive = KittiRawDrive.open(kitti_raw_lead_dir)
    camera = drive.calib.camera().with_image_size(1242, 375)
    step = FrameStep(make_estimator("flat", camera))
    seen = 0
    for k in (0, 20, 40, 60, 77):
        scan = read_velodyne(drive.velodyne_paths[k])
        boxes = lidar_vehicle_boxes(scan, drive.calib, (1242, 375), k)
        est = step.estimate(k, 0.1 * k, 0.0, None, boxes)
        cut = np.array(["bottom" in c for c in est.cut], dtype=bool)
        assert (est.status[cut] == "upper_bound").all()
        assert (est.distance_m[cut] >= boxes.extra["z"][cut]).all()
        assert not (est.status[~cut] == "upper_bound").any()
        seen += int(cut.sum())
    assert seen >= 5


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.lists(
            st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-500, 1800)),
            min_size=4,
            max_size=4,
        ),
        min_size=1,
        max_size=5,
    ),
    st.sampled_from(["flat", "paper", "depthmap", "ours"]),
)
def test_ok_is_a_promise_for_any_box(boxes: list[list[float]], method: str) -> None:
    """Whatever the boxes, an ``ok`` row has a finite positive distance and a usable box, and
    an ``upper_bound`` row a box cut by the bottom."""
    step = FrameStep(make_estimator(method, CAMERA))
    table = BoxTable.build(np.zeros(len(boxes)), boxes)
    depth = np.full((H, W), 12.0, dtype=np.float32)
    est = step.estimate(0, 0.0, 0.0, np.eye(3), table, None, depth)
    for i in range(len(boxes)):
        if est.status[i] == "ok":
            assert np.isfinite(est.distance_m[i]) and est.distance_m[i] > 0
            assert est.reason[i] == ""
        elif est.status[i] == "upper_bound":
            assert "bottom" in est.cut[i] and est.distance_m[i] > 0
        else:
            assert est.status[i] == "missing" and est.reason[i] and np.isnan(est.distance_m[i])


@pytest.mark.parametrize("method", ["flat", "ego", "imu-ego"])
def test_a_box_bottom_within_two_pixels_of_the_horizon_has_no_ok_distance(method: str) -> None:
    """Rows 181.5 and 182.5 read 1188/1.5 = 792 m and 1188/2.5 = 475 m: a pixel moves the
    first by more than half (``near_horizon``, counted at the 80 m cap like ``below_horizon``);
    the second stays ``ok`` at eq. 1's value. (``paper`` and ``imu`` raise θ by eq. 7 for these
    boxes, whose centre is above the horizon: their vanishing line is 38 px higher.)"""
    est = settled(method, [[600.0, 170.0, 620.0, 181.5], [600.0, 170.0, 620.0, 182.5]])
    assert est.status.tolist() == ["missing", "ok"]
    assert est.reason.tolist() == ["near_horizon", ""]
    assert np.isnan(est.distance_m[0])
    assert est.distance_m[1] == pytest.approx(FH / 2.5)
    capped, scored = cap_estimates(est.distance_m, est.reason)
    assert capped.tolist() == [80.0, 80.0] and scored.all()


@pytest.mark.parametrize("method", ["paper", "imu"])
def test_an_adjustment_that_is_not_one_is_a_configuration_error(method: str) -> None:
    """``adjustment="x"`` was accepted, to fail later at the first box."""
    with pytest.raises(ConfigurationError, match=r"adjustment of method .* GradientAdjustment"):
        make_estimator(method, Camera(721.5, 609.6, 172.9), adjustment="x")
