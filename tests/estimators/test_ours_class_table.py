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
