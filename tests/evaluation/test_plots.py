"""Plots over time: one colour per method wherever it stands; the paper's method, flat and ours
in the first panel, legends outside the data, the eq. 7 thresholds labelled."""

from __future__ import annotations

from typing import Any

import numpy as np

from slopedist.evaluation import plots


def test_one_colour_per_method_whatever_its_position() -> None:
    from slopedist.estimators import available_methods

    colours = [plots.method_colour(m) for m in available_methods()]
    assert len(set(colours)) == len(colours)  # the built-in methods are told apart
    assert plots.method_colour("ours") == "tab:pink"
    assert plots.method_colour("custom-x") == plots.method_colour("custom-x")
    assert plots.method_colour("custom-x") in plots.OTHER_METHOD_COLOURS


def _series(methods: list[str], n: int = 20) -> plots.DistanceSeries:
    t = np.arange(n, dtype=float)
    estimates = {m: 20.0 + k + 0.1 * t for k, m in enumerate(methods)}
    below = {m: np.zeros(n, bool) for m in methods}
    below["flat"][5:8] = True  # counted at the cap: triangles at the top of the panel
    return plots.DistanceSeries(1, 20.0 + 0.1 * t, estimates, below)


def _outside(fig: Any, legend: Any) -> bool:
    """Whether ``legend`` overlaps none of the figure's axes."""
    fig.canvas.draw()
    box = legend.get_window_extent()
    return not any(box.overlaps(ax.get_window_extent()) for ax in fig.axes)


def test_the_distance_plot_puts_paper_flat_and_ours_first_and_the_legend_outside() -> None:
    methods = ["flat", "ego", "paper", "imu", "ours", "ours-selfcal"]
    fig = plots.distance_figure(np.arange(20.0), [_series(methods), _series(methods)], "t")
    left, right = fig.axes[0], fig.axes[1]

    def labels(ax: Any) -> list[str]:
        return [line.get_label() for line in ax.get_lines() if not line.get_label().startswith("_")]

    assert labels(left) == ["truth", "flat", "paper", "ours"]
    assert labels(right) == ["truth", "ego", "imu", "ours-selfcal"]
    assert max(line.get_linewidth() for line in right.get_lines()[1:]) < min(
        line.get_linewidth() for line in left.get_lines()[1:]
    )  # the headline methods drawn bolder
    assert left.get_ylim() == right.get_ylim()  # one scale per target
    (legend,) = fig.legends
    assert [t.get_text() for t in legend.get_texts()] == [
        "truth",
        "flat",
        "paper",
        "ours",
        "ego",
        "imu",
        "ours-selfcal",
    ]
    assert _outside(fig, legend)


def test_a_demo_of_the_headline_methods_alone_has_one_column() -> None:
    fig = plots.distance_figure(np.arange(20.0), [_series(["flat", "paper"])])
    assert len(fig.axes) == 1
    assert plots.method_groups(["ego", "imu"]) == [("the other methods", ["ego", "imu"])]


def test_the_theta_plot_labels_the_eq7_thresholds_and_keeps_its_legends_outside() -> None:
    from slopedist.core.geometry import GradientAdjustment

    n = 20
    target = plots.TargetTheta(1, np.zeros(n), np.full(n, 0.01), np.linspace(30.0, -40.0, n))
    adjustment = GradientAdjustment.from_degrees((2.0, 4.0, 7.0), (5.0, -5.0, -15.0))
    fig = plots.theta_figure(
        np.arange(n, dtype=float), np.zeros(n), np.zeros(n), [target], adjustment=adjustment
    )
    ax = fig.axes[1]
    texts = [t.get_text() for t in ax.texts]
    assert texts == ["Δy ≤ 5 px: θ + 2°", "≤ −5 px: + 4°", "< −15 px: + 7°"]
    assert [line.get_ydata()[0] for line in ax.get_lines()[-3:]] == [5.0, -5.0, -15.0]
    for a in fig.axes:
        assert _outside(fig, a.get_legend())
    assert plots.threshold_labels(GradientAdjustment())[0] == "Δy ≤ 0 px: θ + 3°"
