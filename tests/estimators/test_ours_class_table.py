"""``ours``'s class table: the per-heading class constants gathered per frame."""

from __future__ import annotations

import numpy as np

from slopedist.estimators.ours.class_table import ClassTable
from slopedist.estimators.ours.priors import yaw_grid


def test_the_planes_repeat_over_the_size_modes_and_not_over_the_types() -> None:
    """With ``n_modes`` size modes a specific class's hypotheses are its per-heading constants
    repeated mode-major (the same values in every mode); a generic class keeps its vehicle
    types' planes."""
    names = np.array(["Car", "Van", "Pedestrian", "Car"], dtype=object)
    k = yaw_grid().size
    one = ClassTable(None, yaw_grid()).gather(names).hypotheses
    three = ClassTable(None, yaw_grid(), n_modes=3).gather(names).hypotheses
    for a, b in zip(one, three, strict=True):
        assert a.shape == (4, k) and b.shape == (4, 3 * k)
        assert np.array_equal(np.tile(a, 3), b)
    typed = ClassTable(None, yaw_grid(), ("Car",), n_modes=3)
    assert typed.gather(names).hypotheses.height_m.shape == (4, 4 * k)  # the four types
    assert typed.gather(names[1:3]).hypotheses.height_m.shape == (2, 3 * k)


def test_a_new_name_leaves_the_constants_of_the_others_as_they_were() -> None:
    """A class name seen for the first time adds a row; the constants the table gives for the
    names it knew stay those of a fresh table."""
    names = np.array(["Car", "Van", "Car"], dtype=object)
    table = ClassTable(None, yaw_grid(), n_modes=2)
    first = table.gather(names)
    table.gather(np.array(["Truck", "Car"], dtype=object))  # a new row for Truck
    again = table.gather(names)
    fresh = ClassTable(None, yaw_grid(), n_modes=2).gather(names)
    for gathered in (first, again):
        for a, b in zip(gathered.hypotheses, fresh.hypotheses, strict=True):
            assert np.array_equal(a, b)
        assert np.array_equal(gathered.height_m, fresh.height_m)


def test_generic_names_are_compared_without_regard_to_case() -> None:
    """A generic (or σ-only generic) class name matches a box's class whatever its case and
    surrounding spaces, as ``--vehicle-classes`` do: a detector's ``car`` is ``--generic-class
    Car``'s; until then only the exact spelling was generic."""
    names = np.array(["Car", " CAR ", "Van"], dtype=object)
    generic = ClassTable(None, yaw_grid(), ("Car",)).gather(names).generic
    assert generic.tolist() == [True, True, False]
    spread = ClassTable(None, yaw_grid(), spread_classes=("cAr",)).gather(names)
    assert spread.type_moments is not None
    assert not np.array_equal(spread.type_moments[0], spread.type_moments[2])
    assert np.array_equal(spread.type_moments[0], spread.type_moments[1])
