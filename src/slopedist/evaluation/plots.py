"""Plots over time of the demo and the report (matplotlib on the Agg canvas, no display):
distances against the truth per target, the ego gradient θ and the Δy of eq. 6, and the one
colour of each method. Distances in metres, θ in radians (plotted in degrees), Δy in pixels."""

from __future__ import annotations

import io
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.core.geometry import GradientAdjustment

PALETTE = (
    "tab:blue",
    "tab:orange",
    "tab:green",
    "tab:red",
    "tab:purple",
    "tab:brown",
    "tab:pink",
    "tab:olive",
    "tab:cyan",
)
"""Matplotlib colours of series that are not methods (targets), in turn."""

METHOD_COLOURS: dict[str, str] = {
    "flat": "tab:blue",
    "ego": "tab:orange",
    "paper": "tab:green",
    "imu": "tab:red",
    "imu-ego": "tab:purple",
    "depthmap": "tab:brown",
    "ours": "tab:pink",
    "ours-selfcal": "tab:olive",
    "ours-offline": "crimson",
}
"""The colour of each built-in method in every plot (demo and report alike)."""

OTHER_METHOD_COLOURS = ("tab:cyan", "tab:gray", "gold", "navy", "teal", "maroon")
"""Colours of methods not in :data:`METHOD_COLOURS`, chosen by a hash of the name."""


def method_colour(name: str) -> str:
    """The one colour of method ``name`` in every plot: :data:`METHOD_COLOURS`, else a colour
    of :data:`OTHER_METHOD_COLOURS` fixed by the name (not by the method's position)."""
    if name in METHOD_COLOURS:
        return METHOD_COLOURS[name]
    return OTHER_METHOD_COLOURS[zlib.crc32(name.encode()) % len(OTHER_METHOD_COLOURS)]


@dataclass(frozen=True)
class DistanceSeries:
    """One target's distances over the frames of a sequence (metres, NaN = none).

    Attributes:
        track_id: the target.
        truth: ``(F,)`` true distance (NaN where the target is not in view).
        estimates: ``{method: (F,)}`` estimated distance (NaN where missing or not detected).
        below_horizon: ``{method: (F,) bool}`` frames where the box bottom was at or above the
            method's vanishing line (eq. 1 undefined), too near it, or whose distance the image
            does not resolve (``beyond_resolution``): the frames counted at the cap.
    """

    track_id: int
    truth: NDArray[np.float64]
    estimates: dict[str, NDArray[np.float64]]
    below_horizon: dict[str, NDArray[np.bool_]]


@dataclass(frozen=True)
class TargetTheta:
    """Per-target gradients over the frames (radians) and the eq. 6 offset (pixels).

    Attributes:
        track_id: the target.
        needed: θ that would make eq. 1 exact for the target's exact box and true distance.
        adjusted: θ after the paper's per-target adjustment (eq. 7), NaN where not estimated.
        delta_y: Δy of eq. 6, pixels.
    """

    track_id: int
    needed: NDArray[np.float64]
    adjusted: NDArray[np.float64]
    delta_y: NDArray[np.float64]


def new_figure(width: float, height: float) -> Any:
    """A matplotlib figure on the Agg canvas (no display, no pyplot state), ``width`` ×
    ``height`` inches, constrained layout."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def png_bytes(fig: Any, dpi: int = 90) -> bytes:
    """A figure as PNG bytes."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def draw_distance_panel(
    ax: Any,
    t_s: NDArray[np.float64],
    series: DistanceSeries,
    methods: Sequence[str] | None = None,
    lw: float = 1.0,
) -> None:
    """One target's distances over time on the matplotlib axes ``ax``: the truth in black, each
    method of ``methods`` (default: every one of ``series``) in its :func:`method_colour` with
    line width ``lw``, and a triangle at the top where a method's box bottom was at or above
    its vanishing line. The y axis runs from 0 to twice the largest true distance or a little
    over the largest estimate of any method of ``series``, whichever is more (20 to 100 m), so
    panels of one target share it."""
    finite = series.truth[np.isfinite(series.truth)]
    if finite.size:
        ax.plot(t_s, series.truth, color="black", lw=2.0, label="truth")
    values = [2.0 * finite.max()] if finite.size else [100.0]
    values += [
        1.05 * float(np.nanmax(d)) for d in series.estimates.values() if np.isfinite(d).any()
    ]
    top = float(np.clip(max(values), 20.0, 100.0))
    drawn = series.estimates if methods is None else [m for m in methods if m in series.estimates]
    for i, name in enumerate(drawn):
        colour = method_colour(name)
        d = series.estimates[name]
        ax.plot(t_s, d, color=colour, lw=lw, marker=".", ms=2 + lw, label=name)
        miss = series.below_horizon.get(name)
        if miss is not None and miss.any():
            marks = np.full(int(miss.sum()), top * (0.97 - 0.03 * i))
            ax.plot(t_s[miss], marks, "v", color=colour, ms=4)
    ax.set_ylim(0.0, top)
    ax.grid(alpha=0.3)


BELOW_HORIZON_NOTE = "▼ = counted at the cap: box at or near the vanishing line, or unresolved"
"""What the triangles of :func:`draw_distance_panel` mean (for an axis label or caption)."""

HEADLINE_METHODS = ("flat", "paper", "ours")
"""The methods of the demo's first distance panel: flat ground, the paper's method and ours;
the others go to a second panel beside it."""


def method_groups(methods: Sequence[str]) -> list[tuple[str, list[str]]]:
    """``methods`` split for the distance plots: ``(title, methods)`` of the
    :data:`HEADLINE_METHODS` and of the others, leaving out an empty group."""
    headline = [m for m in HEADLINE_METHODS if m in methods]
    others = [m for m in methods if m not in HEADLINE_METHODS]
    groups = [("flat ground, the paper's method and ours", headline), ("the other methods", others)]
    return [(title, group) for title, group in groups if group]


def plot_distance_series(
    path: str | Path, t_s: NDArray[np.float64], series: list[DistanceSeries], title: str = ""
) -> Path:
    """:func:`distance_figure` saved as PNG at ``path``."""
    return _save(distance_figure(t_s, series, title), path)


def _save(fig: Any, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    return path


def distance_figure(t_s: NDArray[np.float64], series: list[DistanceSeries], title: str = "") -> Any:
    """Distance vs. truth over time, one row per target (:func:`draw_distance_panel`): flat
    ground, the paper's method and ours in a first column, drawn bold, the other methods in a
    second (:func:`method_groups`), with a shared y axis per target; one legend outside the
    panels (right). A matplotlib figure on the Agg canvas."""
    methods = list(series[0].estimates) if series else []
    groups = method_groups(methods) or [("", [])]
    rows = max(len(series), 1)
    fig = new_figure(6.5 + 4.5 * (len(groups) - 1) + 1.6, 2.5 * rows + 0.6)
    axes = fig.subplots(rows, len(groups), squeeze=False, sharex=True, sharey="row")
    for r, s in enumerate(series):
        for c, (_, group) in enumerate(groups):
            draw_distance_panel(axes[r, c], t_s, s, group, lw=1.4 if c == 0 else 0.9)
        axes[r, 0].set_ylabel(f"target {s.track_id}: distance (m)")
    for c, (heading, _) in enumerate(groups):
        axes[0, c].set_title(heading, fontsize=9)
        axes[-1, c].set_xlabel("time (s)")
    if series:
        handles: dict[str, Any] = {}  # label → line, once per label
        for ax in axes[0]:
            lines, labels = ax.get_legend_handles_labels()
            handles.update(zip(labels, lines))
        fig.legend(list(handles.values()), list(handles), loc="outside right upper", fontsize=8)
    else:  # no target: an empty panel without a legend
        axes[0, 0].set_title("no target in this scenario")
    fig.supxlabel(BELOW_HORIZON_NOTE, fontsize=8)
    if title:
        fig.suptitle(title)
    return fig


def plot_theta_series(
    path: str | Path,
    t_s: NDArray[np.float64],
    theta_est: NDArray[np.float64],
    theta_true: NDArray[np.float64],
    targets: list[TargetTheta],
    title: str = "",
    adjustment: GradientAdjustment | None = None,
) -> Path:
    """:func:`theta_figure` saved as PNG at ``path``."""
    fig = theta_figure(t_s, theta_est, theta_true, targets, title, adjustment)
    return _save(fig, path)


def theta_figure(
    t_s: NDArray[np.float64],
    theta_est: NDArray[np.float64],
    theta_true: NDArray[np.float64],
    targets: list[TargetTheta],
    title: str = "",
    adjustment: GradientAdjustment | None = None,
) -> Any:
    """θ vs. truth over time (top) and Δy of eq. 6 per target (bottom), a matplotlib figure.

    Top panel, degrees: θ of eq. 4 from the odometry and from the true rotations, and per
    target the θ that would make eq. 1 exact and the paper's adjusted θ (eq. 7). Bottom panel,
    pixels: Δy per target and the thresholds of ``adjustment`` (eq. 7; None: the paper's),
    each labelled with the step it adds to θ. The legends stand outside the panels (right).
    """
    fig = new_figure(11.5, 6.0)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    ax1.plot(t_s, np.degrees(theta_true), color="black", lw=2.0, label="θ, true rotations")
    ax1.plot(t_s, np.degrees(theta_est), color="tab:blue", lw=1.2, label="θ, odometry")
    for i, tt in enumerate(targets):
        colour = PALETTE[(i + 2) % len(PALETTE)]
        ax1.plot(
            t_s,
            np.degrees(tt.needed),
            color=colour,
            ls=":",
            lw=1.5,
            label=f"target {tt.track_id}: θ that makes eq. 1 exact",
        )
        if np.isfinite(tt.adjusted).any():
            ax1.plot(
                t_s,
                np.degrees(tt.adjusted),
                color=colour,
                ls="--",
                lw=1.0,
                label=f"target {tt.track_id}: paper's adjusted θ",
            )
        ax2.plot(
            t_s, tt.delta_y, color=colour, lw=1.0, marker=".", ms=3, label=f"target {tt.track_id}"
        )
    _draw_thresholds(ax2, adjustment or GradientAdjustment())
    ax1.set_ylabel("θ (deg)")
    ax1.grid(alpha=0.3)
    ax1.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    ax2.set_ylabel("Δy = b_y − v (px)")
    ax2.set_xlabel("time (s)")
    ax2.grid(alpha=0.3)
    if targets:
        ax2.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    if title:
        fig.suptitle(title)
    return fig


def threshold_labels(adjustment: GradientAdjustment) -> list[str]:
    """The eq. 7 steps as words: ``"Δy ≤ 0 px: θ + 3°"``, ``"≤ −10 px: + 5°"``,
    ``"< −20 px: + 6°"`` (the paper's), most lenient first."""
    (t1, t2, t3), alphas = adjustment.thresholds_px, np.degrees(adjustment.alphas_rad)
    return [
        f"Δy ≤ {t1:g} px: θ + {alphas[0]:g}°",
        f"≤ {t2:g} px: + {alphas[1]:g}°",
        f"< {t3:g} px: + {alphas[2]:g}°",
    ]


def _draw_thresholds(ax: Any, adjustment: GradientAdjustment) -> None:
    """The eq. 7 thresholds as dashed lines across ``ax``, each labelled at its right end, just
    outside the data (:func:`threshold_labels`)."""
    for th, label in zip(adjustment.thresholds_px, threshold_labels(adjustment)):
        ax.axhline(th, color="grey", lw=0.8, ls="--")
        ax.annotate(
            label.replace("-", "−"),
            (1.0, th),
            xycoords=("axes fraction", "data"),
            xytext=(4, 0),
            textcoords="offset points",
            va="center",
            fontsize=7,
            color="0.3",
            annotation_clip=False,
        )
