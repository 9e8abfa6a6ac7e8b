"""Overlays and plots.

Convention: images are BGR ``H×W×3`` uint8 (OpenCV order), origin top-left, rows downwards;
boxes ``(left, top, right, bottom)`` pixels; θ in radians.
"""

from __future__ import annotations

import io
import math
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist import geometry as geo
from slopedist.camera import Camera
from slopedist.detections.boxes import BoxTable
from slopedist.estimators.base import FrameEstimates

# --- Fig. 3 overlay (paper style) -------------------------------------------------------------

FIG3_GREEN = (0, 255, 0)
"""BGR colour of the vanishing line."""
FIG3_YELLOW = (0, 255, 255)
"""BGR colour of the dashed line at each box's vertical centre."""
FIG3_BOX = (255, 160, 0)
"""BGR colour of the boxes (blue)."""
FIG3_MISSING = (0, 0, 255)
"""BGR colour of boxes and text of targets without a distance (red)."""
FIG3_TEXT = (255, 255, 255)
"""BGR colour of the labels."""

_FONT = cv2.FONT_HERSHEY_SIMPLEX


def dashed_hline(
    image: NDArray[np.uint8],
    row: int,
    x0: int,
    x1: int,
    colour: tuple[int, int, int],
    dash_px: int = 12,
    gap_px: int = 8,
    thickness: int = 1,
) -> None:
    """Draw a dashed horizontal line at ``row`` from column ``x0`` to ``x1`` (in place)."""
    x = x0
    while x < x1:
        cv2.line(image, (x, row), (min(x + dash_px, x1), row), colour, thickness, cv2.LINE_8)
        x += dash_px + gap_px


def outlined_text(
    image: NDArray[np.uint8],
    text: str,
    org: tuple[int, int],
    scale: float,
    colour: tuple[int, int, int],
    thickness: int = 1,
) -> None:
    """``cv2.putText`` with a dark one-pixel outline, so the text reads on any background.

    The outline is the same text drawn in black at the eight one-pixel offsets (a thicker
    stroke would advance each glyph further and drift away from the text on long lines).
    """
    x, y = org
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            if dx or dy:
                cv2.putText(
                    image, text, (x + dx, y + dy), _FONT, scale, (0, 0, 0), thickness, cv2.LINE_AA
                )
    cv2.putText(image, text, org, _FONT, scale, colour, thickness, cv2.LINE_AA)


def _label(
    image: NDArray[np.uint8],
    lines: list[str],
    box: NDArray[np.float64],
    colour: tuple[int, int, int],
) -> None:
    """Write ``lines`` beside ``box``: right of it, or left of it when there is no room."""
    scale, thick = 0.45, 1
    sizes = [cv2.getTextSize(t, _FONT, scale, thick)[0] for t in lines]
    width = max(s[0] for s in sizes) + 4
    line_h = max(s[1] for s in sizes) + 6
    left, top, right, _ = (round(float(c)) for c in box)
    x = right + 4 if right + 4 + width <= image.shape[1] else max(left - 4 - width, 0)
    y = max(top, 0) + line_h
    for text in lines:
        outlined_text(image, text, (x, y), scale, colour, thick)
        y += line_h


def draw_fig3_overlay(
    image: NDArray[np.uint8],
    camera: Camera,
    boxes: BoxTable,
    estimates: FrameEstimates,
    theta_rad: float | None = None,
    header: str | None = None,
) -> NDArray[np.uint8]:
    """Annotate a frame in the style of the paper's Fig. 3; returns a new image.

    Draws each box, a dashed yellow line at each box's vertical centre ``b_y`` (across the box
    and half its width to either side),
    beside each box its distance (m) and Δy (px, eq. 6) — or ``missing: reason`` — and, last and
    on top, the vanishing line of the ego gradient (eq. 5, ``v = c_y − f·tan θ``) as a solid green
    line across the full width. Hershey fonts have no Greek letters, so Δy is written ``dy``.

    Args:
        image: BGR ``H×W×3`` (or grey ``H×W``) uint8 frame; not modified.
        camera: the frame's camera (``f``, ``c_y``).
        boxes: the frame's boxes.
        estimates: the estimates of those boxes (same order).
        theta_rad: ego road gradient θ of the frame, radians. None takes it from
            ``estimates.theta_rad`` (first finite value). No green line when θ is unknown.
        header: optional text written at the top left (e.g. frame number and θ).
    """
    out = np.asarray(
        cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy(), dtype=np.uint8
    )
    h, w = out.shape[:2]
    if theta_rad is None:
        finite = estimates.theta_rad[np.isfinite(estimates.theta_rad)]
        theta_rad = float(finite[0]) if finite.size else math.nan
    for i in range(len(boxes)):
        box = boxes.boxes[i]
        if not np.all(np.isfinite(box)):
            continue
        ok = estimates.reason[i] == ""
        b_y = round(float(geo.box_centre_row(box)))
        left, top, right, bottom = (round(float(c)) for c in box)
        if 0 <= b_y < h:
            reach = max((right - left) // 2, 20)
            dashed_hline(out, b_y, max(left - reach, 0), min(right + reach, w - 1), FIG3_YELLOW)
        cv2.rectangle(out, (left, top), (right, bottom), FIG3_BOX if ok else FIG3_MISSING, 2)
        dy = float(estimates.delta_y_px[i])
        dy_text = f"dy {dy:+.0f} px" if math.isfinite(dy) else "dy -"
        if ok:
            lines = [f"{float(estimates.distance_m[i]):.1f} m", dy_text]
            colour = FIG3_TEXT
        else:
            lines = [f"missing: {estimates.reason[i]}", dy_text]
            colour = FIG3_MISSING
        _label(out, lines, box, colour)
    if header:
        outlined_text(out, header, (8, 20), 0.55, FIG3_TEXT)
    if math.isfinite(theta_rad):
        v = float(geo.vanishing_line_row(theta_rad, camera.f, camera.c_y))
        row = round(v)
        if 0 <= row < h:
            cv2.line(out, (0, row), (w - 1, row), FIG3_GREEN, 2, cv2.LINE_8)
    return out


# --- plots over time (demo and report) ---------------------------------------------------------

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
            method's vanishing line (eq. 1 undefined).
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


BELOW_HORIZON_NOTE = "▼ = box bottom at or above the vanishing line"
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
    axes[0].legend(loc="upper left", ncol=4, fontsize=8)
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
