"""Plots over time of the demo and the report (matplotlib on the Agg canvas, no display):
distances against the truth per target, the ego gradient θ and the Δy of eq. 6, and the one
colour of each method. Distances in metres, θ in radians (plotted in degrees), Δy in pixels."""

from __future__ import annotations

import io
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

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


def draw_distance_panel(ax: Any, t_s: NDArray[np.float64], series: DistanceSeries) -> None:
    """One target's distances over time on the matplotlib axes ``ax``: the truth in black, each
    method in its :func:`method_colour`, and a triangle at the top where a method's box bottom
    was at or above its vanishing line. The y axis runs from 0 to twice the largest true
    distance or a little over the largest estimate, whichever is more (20 to 100 m)."""
    finite = series.truth[np.isfinite(series.truth)]
    if finite.size:
        ax.plot(t_s, series.truth, color="black", lw=2.0, label="truth")
    values = [2.0 * finite.max()] if finite.size else [100.0]
    values += [
        1.05 * float(np.nanmax(d)) for d in series.estimates.values() if np.isfinite(d).any()
    ]
    top = float(np.clip(max(values), 20.0, 100.0))
    for i, (name, d) in enumerate(series.estimates.items()):
        colour = method_colour(name)
        ax.plot(t_s, d, color=colour, lw=1.0, marker=".", ms=3, label=name)
        miss = series.below_horizon.get(name)
        if miss is not None and miss.any():
            marks = np.full(int(miss.sum()), top * (0.97 - 0.03 * i))
            ax.plot(t_s[miss], marks, "v", color=colour, ms=4)
    ax.set_ylim(0.0, top)
    ax.grid(alpha=0.3)


BELOW_HORIZON_NOTE = "▼ = counted at the cap: box at or near the vanishing line, or unresolved"
"""What the triangles of :func:`draw_distance_panel` mean (for an axis label or caption)."""


def plot_distance_series(
    path: str | Path, t_s: NDArray[np.float64], series: list[DistanceSeries], title: str = ""
) -> Path:
    """Distance vs. truth over time, one panel per target (:func:`draw_distance_panel`);
    saved as PNG (Agg, no display)."""
    path = Path(path)
    fig = new_figure(10, 2.6 * max(len(series), 1))
    axes = fig.subplots(max(len(series), 1), 1, squeeze=False)[:, 0]
    for ax, s in zip(axes, series):
        draw_distance_panel(ax, t_s, s)
        ax.set_ylabel(f"target {s.track_id}: z (m)")
    if series:  # no target: an empty panel without a legend
        axes[0].legend(loc="upper left", ncol=4, fontsize=8)
    else:
        axes[0].set_title("no target in this scenario")
    axes[-1].set_xlabel(f"time (s)   ({BELOW_HORIZON_NOTE})")
    if title:
        fig.suptitle(title)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    return path


def plot_theta_series(
    path: str | Path,
    t_s: NDArray[np.float64],
    theta_est: NDArray[np.float64],
    theta_true: NDArray[np.float64],
    targets: list[TargetTheta],
    title: str = "",
    thresholds_px: tuple[float, ...] = (0.0, -10.0, -20.0),
) -> Path:
    """θ vs. truth over time (top) and Δy of eq. 6 per target (bottom); saved as PNG.

    Top panel, degrees: θ of eq. 4 from the odometry and from the true rotations, and per
    target the θ that would make eq. 1 exact and the paper's adjusted θ (eq. 7).
    """
    path = Path(path)
    fig = new_figure(10, 6.0)
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
    for th in thresholds_px:
        ax2.axhline(th, color="grey", lw=0.8, ls="--")
    ax1.set_ylabel("θ (deg)")
    ax1.grid(alpha=0.3)
    ax1.legend(fontsize=7, ncol=2, loc="best")
    ax2.set_ylabel("Δy = b_y − v (px)")
    ax2.set_xlabel("time (s)")
    ax2.grid(alpha=0.3)
    if targets:
        ax2.legend(fontsize=7, loc="best")
    if title:
        fig.suptitle(title)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    return path
