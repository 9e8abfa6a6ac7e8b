"""Fig. 3 overlay: the green vanishing line at the row of eq. 5, boxes, labels, dashed centres."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.estimators import make_estimator
from slopedist.estimators.base import FrameInput
from slopedist.io.detections.boxes import BoxTable
from slopedist.streaming import drawing as viz

CAM = Camera(500.0, 160.0, 100.0)
GREEN = np.array(viz.FIG3_GREEN)
YELLOW = np.array(viz.FIG3_YELLOW)


def _frame(boxes: list[list[float]], theta: float) -> tuple[BoxTable, object]:
    table = BoxTable.build(np.zeros(len(boxes), int), np.asarray(boxes, float).reshape(-1, 4))
    est = make_estimator("ego", CAM).estimate(FrameInput(0, 0.0, theta, table))
    return table, est


def _is(colour: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    return np.all(pixels == colour, axis=-1)


def test_green_line_at_the_vanishing_row_across_the_full_width() -> None:
    theta = 0.02  # v = 100 − 500·tan(0.02) = 89.9987 → row 90
    image = np.full((200, 320, 3), 90, np.uint8)
    boxes, est = _frame([[100, 80, 180, 140]], theta)
    out = viz.draw_fig3_overlay(image, CAM, boxes, est, theta)
    assert _is(GREEN, out[90]).all()
    assert not _is(GREEN, out[80]).any() and not _is(GREEN, out[100]).any()
    assert (image == 90).all(), "input image must not be modified"


def test_theta_taken_from_the_estimates_when_not_given() -> None:
    theta = -0.04  # v = 100 + 500·tan(0.04) = 120.01 → row 120
    boxes, est = _frame([[100, 130, 180, 170]], theta)
    out = viz.draw_fig3_overlay(np.zeros((200, 320), np.uint8), CAM, boxes, est)
    assert out.shape == (200, 320, 3)
    assert _is(GREEN, out[120]).all()


def test_dashed_yellow_line_at_the_box_centre_and_box_drawn() -> None:
    boxes, est = _frame([[100, 120, 160, 160]], 0.0)  # b_y = 140
    out = viz.draw_fig3_overlay(np.zeros((200, 320, 3), np.uint8), CAM, boxes, est, 0.0)
    row = _is(YELLOW, out[140])
    assert 0.4 < row[60:200].mean() < 0.9, "dashed: partly yellow around the box"
    assert not row[250:].any(), "the dashes stop half a box width beside the box"
    assert _is(np.array(viz.FIG3_BOX), out[120:161, 100]).mean() > 0.9  # left edge of the box
    # text beside the box (right of it): white pixels there
    assert _is(np.array(viz.FIG3_TEXT), out[120:160, 165:260]).any()


def test_missing_target_in_red_and_no_line_without_rotation() -> None:
    boxes, est = _frame([[100, 120, 160, 160]], math.nan)
    assert est.reason[0] == "no_rotation"
    out = viz.draw_fig3_overlay(np.zeros((200, 320, 3), np.uint8), CAM, boxes, est, math.nan)
    assert not _is(GREEN, out).any()
    red = _is(np.array(viz.FIG3_MISSING), out)
    assert red[120:161, 100].mean() > 0.9  # the box in red, its label in a lighter red
    assert _is(np.array(viz.FIG3_MISSING_TEXT), out)[100:170, 165:].any()


def test_line_outside_the_image_is_not_drawn() -> None:
    boxes, est = _frame([], 0.5)  # v = 100 − 500·tan(0.5) < 0
    out = viz.draw_fig3_overlay(np.zeros((200, 320, 3), np.uint8), CAM, boxes, est, 0.5)
    assert not _is(GREEN, out).any()


@pytest.mark.parametrize("org", [(40, 30), (-8, 6), (125, 66)], ids=["inside", "cut", "corner"])
def test_outlined_text_is_the_text_in_a_dark_ring_one_pixel_wide(org: tuple[int, int]) -> None:
    """On a white frame: the text's own pixels are as ``cv2.putText`` draws them, every
    pixel one step from the text is darkened, and nothing two steps away changes (also where
    the image border cuts the text)."""
    white = np.full((70, 160, 3), 255, np.uint8)
    out = white.copy()
    viz.outlined_text(out, "#12 23.4 m", org, 0.45, (0, 200, 255))
    text = np.zeros((70, 160), np.uint8)
    cv2.putText(text, "#12 23.4 m", org, cv2.FONT_HERSHEY_SIMPLEX, 0.45, 255, 1, cv2.LINE_AA)
    solid = text == 255
    assert solid.any()
    np.testing.assert_array_equal(out[solid], np.tile([0, 200, 255], (int(solid.sum()), 1)))
    ring = (cv2.dilate(text, np.ones((3, 3), np.uint8)) > 0) & (text == 0)
    assert ring.any() and (out[ring].max(axis=1) < 255).all()
    far = cv2.dilate(text, np.ones((5, 5), np.uint8)) == 0
    np.testing.assert_array_equal(out[far], white[far])


@pytest.mark.parametrize("thickness", [1, 2])
def test_dashes_drawn_in_one_call_are_the_lines_drawn_one_by_one(thickness: int) -> None:
    image = np.zeros((40, 120, 3), np.uint8)
    viz.dashed_hline(image, 20, 3, 110, (0, 255, 255), 12, 8, thickness)
    expected = np.zeros_like(image)
    for x in range(3, 110, 20):
        cv2.line(expected, (x, 20), (min(x + 12, 110), 20), (0, 255, 255), thickness, cv2.LINE_8)
    assert np.array_equal(image, expected)


def test_a_cut_box_is_its_four_sides_dashed() -> None:
    image = np.zeros((60, 80, 3), np.uint8)
    viz._draw_box(image, np.array([5.2, 4.0, 70.0, 55.0]), (255, 160, 0), cut=True)
    expected = np.zeros_like(image)
    for row in (4, 55):
        for x in range(5, 70, 13):
            cv2.line(expected, (x, row), (min(x + 8, 70), row), (255, 160, 0), 2, cv2.LINE_8)
    for col in (5, 70):
        for y in range(4, 55, 13):
            cv2.line(expected, (col, y), (col, min(y + 8, 55)), (255, 160, 0), 2, cv2.LINE_8)
    assert np.array_equal(image, expected)
    assert viz.dash_spans(10, 10, 8, 5).shape == (0, 2)  # nothing to draw


def test_the_lead_vehicle_is_a_target_with_a_distance_to_act_on() -> None:
    """The lead (its banner shows a plain number) is chosen by status: an ``upper_bound`` or
    ``missing`` row with an empty reason was taken for the lead, its bound in the banner."""
    boxes, est = _frame([[140, 120, 180, 160], [150, 110, 170, 130]], 0.0)
    assert viz.lead_index(CAM, boxes, est) == 0
    est.status = np.array(["upper_bound", "ok"], dtype=object)  # reasons stay empty
    assert viz.lead_index(CAM, boxes, est) == 1
    est.status = np.array(["upper_bound", "missing"], dtype=object)
    assert viz.lead_index(CAM, boxes, est) is None
