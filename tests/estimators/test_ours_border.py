"""``ours`` at the image border: which cut boxes stay ``ok`` and which are upper bounds.

Camera f = 720 px, c_y = 180 px, h = 1.65 m, image 1240 × 375 (as test_ground_contact.py).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.estimators import make_estimator
from slopedist.estimators.ours.border import ImageBorder, border_cuts_of
from slopedist.io.detections.boxes import BoxTable
from slopedist.streaming.step import FrameStep

W, H = 1240, 375
CAMERA = Camera(720.0, 620.0, 180.0, height_m=1.65).with_image_size(W, H)


def settled(boxes: list[list[float]], camera: Camera = CAMERA, **options: object):
    step = FrameStep(make_estimator("ours", camera, **options))
    table = BoxTable.build(np.zeros(len(boxes)), boxes)
    return step.estimate(0, 0.0, 0.0, np.eye(3), table)


@pytest.mark.parametrize(
    ("box", "cut", "status"),
    [
        ([560, 190, 680, 374.0], "bottom", "ok"),  # the width cue is whole
        ([0, 190, 300, 300], "left", "ok"),  # height and ground contact whole
        ([560, 0, 700, 300], "top", "ok"),  # width and ground contact whole
        ([0, 0, 300, 300], "left+top", "ok"),  # the ground contact is whole
        ([-80, 200, 300, 374.0], "left+bottom", "upper_bound"),
        ([900, 150, 1239, 374.0], "right+bottom", "upper_bound"),
        ([0, 0, 1239, 374.0], "left+top+right+bottom", "upper_bound"),
    ],
)
def test_a_cut_box_is_ok_while_one_of_its_cues_is_uncut(box, cut, status) -> None:
    est = settled([box])
    assert est.cut[0] == cut and est.status[0] == status
    assert np.isfinite(est.distance_m[0]) and est.distance_m[0] > 0
    if status == "upper_bound":
        assert est.reason[0] == "cut_bottom"
        bound = min(est.extra["distance_ground_contact_m"][0], est.extra["distance_width_m"][0])
        assert est.distance_m[0] == pytest.approx(bound)
    else:
        assert est.reason[0] == ""


def test_without_the_width_cue_a_bottom_cut_is_an_upper_bound_at_the_contact_row() -> None:
    est = settled([[560, 190, 680, 374.0]], use_width=False)
    assert est.status[0] == "upper_bound" and est.reason[0] == "cut_bottom"
    assert est.distance_m[0] == pytest.approx(est.extra["distance_ground_contact_m"][0])


def test_the_censored_cues_are_the_edges_of_the_cut_column() -> None:
    """``ours`` censors exactly the edges :func:`border_cuts` names (1 px tolerance)."""
    border = ImageBorder(CAMERA)
    boxes = np.array([[1.0, 1.0, 1238.0, 373.0], [1.5, 1.5, 1237.5, 372.5]])
    assert border.cut_edges(boxes).tolist() == [[True] * 4, [False] * 4]


def test_without_an_image_size_the_border_is_what_the_boxes_reveal() -> None:
    border = ImageBorder(Camera(720.0, 620.0, 180.0, height_m=1.65))
    assert border.known_size is None
    assert not border.cut_edges(np.array([[500.0, 100, 700, 300]])).any()  # nothing known yet
    cut = border.cut_edges(np.array([[500.0, 100, 1241, 374], [0, 100, 20, 200]]))
    assert cut.tolist() == [[False, False, True, True], [True, False, False, False]]


def test_absurd_boxes_are_missing_without_overflow() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        est = settled([[1e23, 1e23, 2e23, 2e23], [-1e23, 100, 300, 200], [500, 190, 620, 300]])
    assert list(est.status) == ["missing", "missing", "ok"]
    assert list(est.reason[:2]) == ["degenerate_box", "degenerate_box"]


def test_the_kitti_raw_lead_car_cut_by_the_bottom_is_ok_and_near_its_lidar_distance(
    kitti_raw_lead_dir,
) -> None:
    """The lead car (in the ego lane, |x| < 1.5 m) closer than ~6 m is cut by the image bottom
    with both sides in view: ``ok`` from its width and its track, its nearest face within 15 %
    of the LiDAR's; every ``upper_bound`` is at least the LiDAR distance."""
    from slopedist.io.kitti.raw import KittiRawDrive, lidar_vehicle_boxes, read_velodyne

    drive = KittiRawDrive.open(kitti_raw_lead_dir)
    camera = drive.calib.camera().with_image_size(1242, 375)
    step = FrameStep(make_estimator("ours", camera))
    rel_err, bounds = [], 0
    for k in range(len(drive.velodyne_paths)):
        boxes = lidar_vehicle_boxes(
            read_velodyne(drive.velodyne_paths[k]), drive.calib, (1242, 375), k
        )
        est = step.estimate(k, 0.1 * k, 0.0, np.eye(3), boxes)
        z = boxes.extra["z"]
        upper = est.status == "upper_bound"
        assert (est.distance_m[upper] >= z[upper]).all()
        bounds += int(upper.sum())
        lead = (np.abs(boxes.extra["x"]) < 1.5) & (est.cut == "bottom")
        assert (est.status[lead] == "ok").all()
        face = est.extra["distance_nearest_face_m"][lead]
        rel_err.extend((face - z[lead]) / z[lead])
    assert len(rel_err) >= 40 and bounds >= 10
    assert np.max(np.abs(rel_err)) < 0.15


def test_the_reference_option_chooses_the_main_column() -> None:
    boxes = [[560, 190, 680, 300], [-80, 200, 300, 374.0]]
    centre = settled(boxes)
    face = settled(boxes, reference="nearest_face")
    contact = settled(boxes, reference="contact")
    assert list(centre.reference) == ["centre"] * 2 and list(face.reference) == ["nearest_face"] * 2
    assert list(contact.reference) == ["contact"] * 2
    half = centre.distance_m[0] - centre.extra["distance_nearest_face_m"][0]
    assert 1.0 < half < 3.0
    assert face.distance_m[0] == pytest.approx(centre.extra["distance_nearest_face_m"][0])
    assert contact.distance_m[0] == pytest.approx(face.distance_m[0])
    np.testing.assert_allclose(face.extra["distance_centre_m"], centre.distance_m)
    assert face.status[1] == "upper_bound" and face.distance_m[1] < centre.distance_m[1]
    with pytest.raises(ConfigurationError, match="reference must be one of"):
        make_estimator("ours", CAMERA, reference="box_centre_pixel")


def test_border_cuts_of_the_cut_edges() -> None:
    """The (side, top, bottom) flags of the cut edges (left, top, right, bottom); None when no
    box is cut."""
    edges = np.array([[False, False, True, False], [False, True, False, True], [False] * 4])
    cuts = border_cuts_of(edges)
    assert cuts is not None
    assert cuts.sides.tolist() == [True, False, False]
    assert cuts.top.tolist() == [False, True, False]
    assert cuts.bottom.tolist() == [False, True, False]
    assert border_cuts_of(np.zeros((2, 4), dtype=bool)) is None
