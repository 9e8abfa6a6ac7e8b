"""Plots over time: one colour per method wherever it stands."""

from __future__ import annotations

from slopedist.evaluation import plots


def test_one_colour_per_method_whatever_its_position() -> None:
    from slopedist.estimators import available_methods

    colours = [plots.method_colour(m) for m in available_methods()]
    assert len(set(colours)) == len(colours)  # the built-in methods are told apart
    assert plots.method_colour("ours") == "tab:pink"
    assert plots.method_colour("custom-x") == plots.method_colour("custom-x")
    assert plots.method_colour("custom-x") in plots.OTHER_METHOD_COLOURS
