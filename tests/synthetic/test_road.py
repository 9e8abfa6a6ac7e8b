"""Road model: elevation, grade, heading and plan position against closed-form geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slopedist.core.errors import ConfigurationError
from slopedist.synthetic.road import (
    GradeChange,
    HorizontalCurve,
    Road,
    RoadSpec,
    SpeedBump,
)


def test_constant_grade_is_a_straight_incline() -> None:
    road = Road(RoadSpec(start_grade_pct=-6.0, s_max_m=200.0))
    s = np.array([-30.0, 0.0, 17.3, 150.0])
    np.testing.assert_allclose(road.elevation(s), -0.06 * s, atol=1e-9)
    np.testing.assert_allclose(road.grade_at(s), -0.06, atol=1e-9)
    np.testing.assert_allclose(road.centre(s)[:, 0], s, atol=1e-9)
    # 3D length along the incline
    np.testing.assert_allclose(road.driven_distance(100.0), 100.0 * math.hypot(1, 0.06), rtol=1e-9)


def test_vertical_curve_is_a_parabola_between_two_grades() -> None:
    # 0 % → 12 % over 20 m centred at 55 m: z = 0.12/(2·20)·(s − 45)² inside, linear after
    road = Road(RoadSpec(grade_changes=(GradeChange(55.0, 12.0, 20.0),), s_max_m=200.0))
    s = np.array([40.0, 45.0, 50.0, 55.0, 65.0, 100.0])
    expected = np.where(
        s <= 45,
        0.0,
        np.where(s <= 65, 0.12 / 40.0 * (s - 45) ** 2, 0.12 / 40.0 * 400.0 + 0.12 * (s - 65)),
    )
    np.testing.assert_allclose(road.elevation(s), expected, atol=2e-4)
    assert road.grade_at(100.0) == pytest.approx(0.12, abs=1e-6)


def test_arc_turns_the_heading_by_length_over_radius() -> None:
    # quarter circle of radius 100 m without transitions, starting at s = 0
    arc = 0.5 * math.pi * 100.0
    road = Road(RoadSpec(curves=(HorizontalCurve(0.0, arc, 100.0, 0.0),), s_max_m=300.0))
    assert road.heading_at(arc + 10.0) == pytest.approx(0.5 * math.pi, abs=1e-3)
    end = road.centre(arc)
    np.testing.assert_allclose(end[:2], [100.0, 100.0], atol=0.05)  # left turn: +Y
    # the left vector points to the centre of the turn
    np.testing.assert_allclose(road.point(arc / 2, 100.0)[:2], [0.0, 100.0], atol=0.05)


def test_clothoid_transitions_keep_the_total_turn() -> None:
    # curvature ramps over 20 m on each side: total turn = (L + T)/R
    road = Road(RoadSpec(curves=(HorizontalCurve(10.0, 50.0, -150.0, 20.0),), s_max_m=300.0))
    assert road.heading_at(200.0) == pytest.approx(-(50.0 + 20.0) / 150.0, abs=1e-4)


def test_speed_bump_profile() -> None:
    road = Road(RoadSpec(bumps=(SpeedBump(30.0, 0.08, 4.0),), s_max_m=200.0))
    assert road.elevation(30.0) == pytest.approx(0.08, abs=1e-6)
    assert road.elevation(28.0) == pytest.approx(0.0, abs=1e-6)
    assert road.elevation(29.0) == pytest.approx(0.04, abs=1e-3)


def test_driven_distance_inverse() -> None:
    road = Road(RoadSpec(grade_changes=(GradeChange(50.0, 10.0, 30.0),), s_max_m=300.0))
    s = np.linspace(-20.0, 250.0, 17)
    np.testing.assert_allclose(road.s_at_driven_distance(road.driven_distance(s)), s, atol=1e-6)
    with pytest.raises(ConfigurationError, match="leaves the modelled road"):
        road.s_at_driven_distance(1e6)


@pytest.mark.parametrize(
    "bad",
    [
        lambda: GradeChange(0.0, 50.0),
        lambda: GradeChange(0.0, 5.0, 0.0),
        lambda: HorizontalCurve(0.0, 10.0, 10.0),
        lambda: SpeedBump(0.0, 0.5),
        lambda: RoadSpec(lanes=0),
        lambda: RoadSpec(lane_width_m=float("nan")),
    ],
)
def test_invalid_definitions_are_configuration_errors(bad) -> None:
    with pytest.raises(ConfigurationError):
        bad()
