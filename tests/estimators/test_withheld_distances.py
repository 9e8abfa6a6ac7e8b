"""``ok`` is a promise: a row whose ``distance_m`` is withheld has no distance in any column.

Camera f = 720 px, c_y = 180 px, h = 1.65 m, image 1240 × 375 (as test_too_uncertain.py). A
car 20 m ahead is 58 px wide and 55 px high, its bottom 59 px below the horizon.
"""

from __future__ import annotations

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.estimators import make_estimator
from slopedist.estimators.base import FrameEstimates
from slopedist.io.detections.boxes import BoxTable
from slopedist.streaming.step import FrameStep

DISTANCE_COLUMNS = ("distance_centre_m", "distance_nearest_face_m")
CAMERA = Camera(720.0, 620.0, 180.0, height_m=1.65).with_image_size(1240, 375)
CAR_20M = [560.0, 180 + 720 * (1.65 - 1.53) / 20, 560 + 720 * 1.63 / 20, 180 + 720 * 1.65 / 20]
FEW_PIXELS = [600.0, 298.5, 601.5, 300.0]  # too_uncertain (test_too_uncertain.py)
CUT = [-80.0, 200.0, 300.0, 374.0]  # cut by the left and the bottom: an upper bound


def frame_step(method: str = "ours", **options: object) -> FrameStep:
    return FrameStep(make_estimator(method, CAMERA, **options))


def settled(boxes: list[list[float]], classes: list[str], **options: object) -> FrameEstimates:
    table = BoxTable.build(np.zeros(len(boxes)), boxes, classes=classes)
    return frame_step(**options).estimate(0, 0.0, 0.0, np.eye(3), table)


def assert_withheld(est: FrameEstimates, row: int) -> None:
    assert est.status[row] == "missing"
    assert np.isnan(est.distance_m[row])
    for name in DISTANCE_COLUMNS:
        assert np.isnan(est.extra[name][row]), name


@pytest.mark.parametrize("reference", ["centre", "nearest_face"])
def test_a_missing_row_keeps_no_distance_column(reference: str) -> None:
    est = settled([CAR_20M, CAR_20M, FEW_PIXELS], ["Car", "Pedestrian", "Car"], reference=reference)
    assert est.status.tolist() == ["ok", "missing", "missing"]
    assert est.reason.tolist()[1:] == ["not_a_vehicle", "too_uncertain"]
    assert np.isfinite([est.extra[c][0] for c in DISTANCE_COLUMNS]).all()
    for row in (1, 2):
        assert_withheld(est, row)
        assert np.isfinite(est.extra["distance_size_m"][row])  # the cues stay: diagnostics
    assert np.isnan(est.extra["sigma_m"][1])  # not why the row is missing
    assert est.extra["sigma_m"][2] > 0.5 * est.extra["distance_size_m"][2]  # says why


@pytest.mark.parametrize("reference", ["centre", "nearest_face"])
def test_an_upper_bound_is_a_bound_in_every_distance_column(reference: str) -> None:
    est = settled([CUT, CAR_20M], ["Car", "Car"], reference=reference)
    assert est.status.tolist() == ["upper_bound", "ok"]
    centre = est.extra["distance_centre_m"]
    face = est.extra["distance_nearest_face_m"]
    for row in (0, 1):  # the same half extent as an ok row's, and the reported one's column
        assert 0.5 < centre[row] - face[row] < 3.5
        main = centre if reference == "centre" else face
        assert est.distance_m[row] == main[row]
    # the bound: the least of the cut cues (the contact cue, the width cue)
    cues = [est.extra["distance_ground_contact_m"][0], est.extra["distance_width_m"][0]]
    assert centre[0] == pytest.approx(np.nanmin(cues))


def test_the_offline_pass_withholds_as_the_causal_one() -> None:
    step = frame_step("ours-offline")
    for k in range(5):
        top, bottom = CAR_20M[1] + 0.2 * k, CAR_20M[3] + 0.3 * k
        boxes = [[CAR_20M[0], top, CAR_20M[2], bottom], CAR_20M, FEW_PIXELS]
        table = BoxTable.build(
            np.full(3, k), boxes, [1, 2, 3], classes=["Car", "Pedestrian", "Car"]
        )
        step.estimate(k, 0.1 * k, 0.0, np.eye(3), table)
    for est in step.finish():
        assert est.status.tolist() == ["ok", "missing", "missing"]
        assert_withheld(est, 1)
        assert_withheld(est, 2)


def test_speed_and_ttc_are_given_in_ok_rows_only() -> None:
    """Two frames 0.1 s apart, every box 2 % larger in the second (closing in): the ok car
    has a speed and a time to collision, the bound and the too-uncertain box none."""
    step = frame_step()
    boxes = np.array([CAR_20M, CUT, FEW_PIXELS])
    ids = np.arange(3)
    for k, grow in enumerate((1.0, 1.02)):
        centre = (boxes[:, [0, 1]] + boxes[:, [2, 3]]) / 2
        half = (boxes[:, [2, 3]] - boxes[:, [0, 1]]) / 2 * grow
        table = BoxTable.build(
            np.full(3, k), np.hstack([centre - half, centre + half]), ids, classes=["Car"] * 3
        )
        est = step.estimate(k, 0.1 * k, 0.0, np.eye(3), table)
    assert est.status.tolist() == ["ok", "upper_bound", "missing"]
    for name in ("speed_mps", "speed_sigma_mps", "ttc_s", "ttc_sigma_s"):
        assert np.isfinite(est.extra[name][0]), name
        assert np.isnan(est.extra[name][1:]).all(), name
