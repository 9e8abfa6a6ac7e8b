"""Moving a distance between reference points (contact, nearest face, centre), by hand."""

from __future__ import annotations

import numpy as np
import pytest

from slopedist.estimators import native_reference
from slopedist.estimators.base import FrameEstimates, ReferencePoint
from slopedist.estimators.ours.priors import CLASS_PRIORS, UNKNOWN_CLASS_PRIOR
from slopedist.estimators.references import (
    CENTRE_COLUMN,
    DEFAULT_REFERENCE,
    NEAREST_FACE_COLUMN,
    at_reference,
    half_length_prior_m,
    own_half_extent_m,
    reported_labels,
    to_reference,
)

CENTRE, FACE, CONTACT = ReferencePoint.CENTRE, ReferencePoint.NEAREST_FACE, ReferencePoint.CONTACT


def test_half_length_prior_per_class() -> None:
    np.testing.assert_allclose(
        half_length_prior_m(["Car", "van", "Bicycle?"]),
        [3.88 / 2, 5.08 / 2, UNKNOWN_CLASS_PRIOR.length_m / 2],
    )


def test_a_contact_distance_reaches_the_centre_by_half_the_class_length() -> None:
    d = to_reference([10.0, 20.0, np.nan], ["contact"] * 3, ["Car", "Van", "Car"], CENTRE)
    assert d[0] == pytest.approx(10.0 + CLASS_PRIORS["Car"].length_m / 2)
    assert d[1] == pytest.approx(20.0 + CLASS_PRIORS["Van"].length_m / 2)
    assert np.isnan(d[2])


def test_contact_nearest_face_and_a_surface_pixel_are_the_same_distance() -> None:
    reported = ["contact", "nearest_face", "box_centre_pixel"]
    for wanted in (FACE, CONTACT):
        np.testing.assert_array_equal(
            to_reference([5.0, 6.0, 7.0], reported, ["Car"] * 3, wanted), [5.0, 6.0, 7.0]
        )


def test_a_centre_distance_reaches_the_face_by_the_method_s_own_extent_if_it_has_one() -> None:
    extra = {CENTRE_COLUMN: np.array([12.0, 30.0]), NEAREST_FACE_COLUMN: np.array([10.5, np.nan])}
    own = own_half_extent_m(extra, 2)
    np.testing.assert_allclose(own[:1], [1.5])
    assert np.isnan(own[1])
    d = to_reference([12.0, 30.0], ["centre", "centre"], ["Car", "Car"], FACE, own)
    np.testing.assert_allclose(d, [10.5, 30.0 - 3.88 / 2])
    np.testing.assert_array_equal(
        to_reference([12.0], ["centre"], ["Car"], CENTRE, own[:1]), [12.0]
    )
    assert np.isnan(own_half_extent_m({}, 3)).all()


def test_the_input_is_not_changed() -> None:
    d = np.array([10.0])
    to_reference(d, ["contact"], ["Car"], CENTRE)
    assert d[0] == 10.0


def estimates(
    distance_m: list[float], reference: list[str], **extra: list[float]
) -> FrameEstimates:
    n = len(distance_m)
    nan = np.full(n, np.nan)
    return FrameEstimates(
        theta_rad=nan.copy(),
        theta_adj_rad=nan.copy(),
        delta_y_px=nan.copy(),
        v_px=nan.copy(),
        distance_m=np.array(distance_m, dtype=float),
        reason=np.full(n, "", dtype=object),
        reference=np.array(reference, dtype=object),
        extra={k: np.array(v, dtype=float) for k, v in extra.items()},
    )


def test_the_default_point_a_user_sees_is_the_nearest_face() -> None:
    assert DEFAULT_REFERENCE is FACE


def test_at_the_nearest_face_a_contact_row_keeps_its_distance_and_says_contact() -> None:
    est = estimates([10.0, 12.0], ["contact", "box_centre_pixel"])
    moved = at_reference(est, ["Car", "Car"], FACE)
    np.testing.assert_array_equal(moved.distance_m, [10.0, 12.0])
    assert moved.reference.tolist() == ["contact", "nearest_face"]


def test_a_centre_row_reaches_the_face_by_its_own_extent_and_its_ttc_with_it() -> None:
    est = estimates(
        [20.0],
        ["centre"],
        **{
            CENTRE_COLUMN: [20.0],
            NEAREST_FACE_COLUMN: [18.0],
            "ttc_s": [10.0],
            "ttc_sigma_s": [1.0],
        },
    )
    moved = at_reference(est, ["Car"], FACE)
    assert moved.distance_m[0] == pytest.approx(18.0)
    assert moved.reference[0] == "nearest_face"
    # the gap closes at the same speed: 18 m at 2 m/s
    assert moved.extra["ttc_s"][0] == pytest.approx(9.0)
    assert moved.extra["ttc_sigma_s"][0] == pytest.approx(0.9)
    assert est.distance_m[0] == 20.0 and est.extra["ttc_s"][0] == 10.0  # the method's own


def test_asked_for_the_centre_every_point_moves_there() -> None:
    est = estimates([10.0, 12.0, np.nan], ["contact", "nearest_face", "contact"])
    moved = at_reference(est, ["Car", "Van", "Car"], CENTRE)
    np.testing.assert_allclose(moved.distance_m[:2], [10.0 + 3.88 / 2, 12.0 + 5.08 / 2])
    assert np.isnan(moved.distance_m[2])
    assert set(moved.reference.tolist()) == {"centre"}
    assert reported_labels(["centre", "contact"], CONTACT).tolist() == ["contact", "contact"]


def test_the_point_each_method_reports_of_its_own() -> None:
    assert native_reference("ours") is CENTRE and native_reference("ours-offline") is CENTRE
    assert native_reference("paper") is CONTACT and native_reference("flat") is CONTACT
    assert native_reference("depthmap") is ReferencePoint.BOX_CENTRE_PIXEL
    assert native_reference("someone-else") is None
