"""Moving a distance between reference points (contact, nearest face, centre), by hand."""

from __future__ import annotations

import numpy as np
import pytest

from slopedist.estimators.base import ReferencePoint
from slopedist.estimators.ours.priors import CLASS_PRIORS, UNKNOWN_CLASS_PRIOR
from slopedist.estimators.references import (
    CENTRE_COLUMN,
    NEAREST_FACE_COLUMN,
    half_length_prior_m,
    own_half_extent_m,
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
