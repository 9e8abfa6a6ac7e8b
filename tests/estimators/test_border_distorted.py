"""The image border cuts boxes in the frame's own pixels, also when a lens model maps them.

Camera f = 720 px, c = (620, 180), image 1240 × 375, radial distortion k1 = ±0.3: the boxes are
mapped into the ideal camera (:meth:`Intrinsics.rectify_table`), which moves their edges by
many pixels, in (pincushion) or out (barrel) of the image. Whether an edge is cut is a fact of
the frame: it must not change with the lens model.
"""

from __future__ import annotations

import numpy as np
import pytest

from slopedist.estimators import make_estimator
from slopedist.estimators.base import FrameInput
from slopedist.io.detections.boxes import FRAME_BOX_COLUMN, BoxTable, frame_pixel_boxes
from slopedist.io.intrinsics import Intrinsics
from slopedist.streaming.step import FrameStep

W, H = 1240, 375
K = np.array([[720.0, 0.0, 620.0], [0.0, 720.0, 180.0], [0.0, 0.0, 1.0]])
BOXES = [
    [700.0, 250.0, 900.0, 374.0],  # a near car cut by the bottom of the image
    [560.0, 300.0, 700.0, 369.0],  # 5 px above the bottom: not cut
    [600.0, 180.0, 640.0, 215.0],  # a car in the middle of the image
]


def states(method: str, k1: float) -> tuple[list[str], list[str]]:
    lens = Intrinsics(K, np.array([k1, 0.0, 0.0, 0.0]), image_size=(W, H))
    table = lens.rectify_table(BoxTable.build(np.zeros(len(BOXES)), BOXES))
    step = FrameStep(make_estimator(method, lens.camera(1.65)))
    est = step.estimate(0, 0.0, 0.0, np.eye(3), table)
    return est.status.tolist(), est.cut.tolist()


@pytest.mark.parametrize("method", ["flat", "paper", "ours"])
@pytest.mark.parametrize("k1", [-0.1, 0.3])
def test_the_cut_states_do_not_change_with_the_lens(method: str, k1: float) -> None:
    status, cut = states(method, k1)
    assert (status, cut) == states(method, 0.0)
    assert cut == ["bottom", "", ""]
    assert status[0] == ("ok" if method == "ours" else "upper_bound")  # ours: the width cue
    assert status[1:] == ["ok", "ok"]


def test_frame_pixel_boxes_are_the_boxes_as_given() -> None:
    lens = Intrinsics(K, np.array([0.3, 0.0, 0.0, 0.0]), image_size=(W, H))
    given = BoxTable.build(np.zeros(len(BOXES)), BOXES)
    mapped = lens.rectify_table(given)
    assert FRAME_BOX_COLUMN in mapped.extra
    assert not np.allclose(mapped.boxes, given.boxes)
    np.testing.assert_array_equal(frame_pixel_boxes(mapped), given.boxes)
    np.testing.assert_array_equal(frame_pixel_boxes(given), given.boxes)


@pytest.mark.parametrize("method", ["flat", "paper", "ours"])
def test_a_box_in_the_frame_is_in_the_image_whatever_the_lens(method: str) -> None:
    # barrel distortion maps boxes at the side edges of the frame beyond the ideal camera's
    # image; they were 'missing, outside_image'. A box beyond the frame stays outside.
    edge_boxes = [[1205.0, 300.0, 1238.0, 330.0], [0.0, 300.0, 30.0, 330.0]]
    beyond = [[1250.0, 300.0, 1290.0, 330.0]]
    for k1 in (0.0, -0.1, 0.3):
        lens = Intrinsics(K, np.array([k1, 0.0, 0.0, 0.0]), image_size=(W, H))
        table = lens.rectify_table(BoxTable.build(np.zeros(3), edge_boxes + beyond))
        step = FrameStep(make_estimator(method, lens.camera(1.65)))
        est = step.estimate(0, 0.0, 0.0, np.eye(3), table)
        assert est.reason[2] == "outside_image", k1
        assert "outside_image" not in est.reason[:2].tolist(), k1
        assert est.cut[:2].tolist() == ["right", "left"], k1


@pytest.mark.parametrize("k1", [0.0, -0.1, 0.3])
def test_ours_uses_no_box_beyond_the_frame_whatever_the_lens(k1: float) -> None:
    # a pincushion lens (k1 = 0.3) maps boxes beyond the frame's right edge into the ideal
    # camera's image: the fast path took them as usable (and cut: their right edge), fed them
    # to the tracker and gave them a distance; the frame's pixels say they are outside
    beyond = [[1250.0, 300.0, 1290.0, 330.0], [1245.0, 200.0, 1300.0, 240.0]]
    lens = Intrinsics(K, np.array([k1, 0.0, 0.0, 0.0]), image_size=(W, H))
    table = lens.rectify_table(BoxTable.build(np.zeros(3), [BOXES[2], *beyond], [1, 2, 3]))
    estimator = make_estimator("ours", lens.camera(1.65))
    est = estimator.estimate(FrameInput(0, 0.0, 0.0, table))
    assert est.reason.tolist() == ["", "outside_image", "outside_image"]
    assert est.status.tolist() == ["ok", "missing", "missing"]
    assert np.isnan(est.distance_m[1:]).all()
    assert len(estimator.tracks) == 1  # only the box in the frame started a track
