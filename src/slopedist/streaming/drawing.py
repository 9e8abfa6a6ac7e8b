"""The Fig. 3 overlay (OpenCV; the plots over time are in :mod:`slopedist.evaluation.plots`).

Convention: images are BGR ``H×W×3`` uint8 (OpenCV order), origin top-left, rows downwards;
boxes ``(left, top, right, bottom)`` pixels; θ in radians.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core import geometry as geo
from slopedist.core.camera import Camera
from slopedist.estimators.base import FrameEstimates
from slopedist.io.detections.boxes import BoxTable
from slopedist.streaming.label_placement import Placement, Rect, box_rect, layout_labels

# --- Fig. 3 overlay (paper style) -------------------------------------------------------------

FIG3_GREEN = (0, 255, 0)
"""BGR colour of the vanishing line."""
FIG3_YELLOW = (0, 255, 255)
"""BGR colour of the dashed line at each box's vertical centre."""
FIG3_BOX = (255, 160, 0)
"""BGR colour of the boxes (blue)."""
FIG3_MISSING = (0, 0, 255)
"""BGR colour of the boxes of targets without a distance (red)."""
FIG3_MISSING_TEXT = (110, 110, 255)
"""BGR colour of the labels of targets without a distance: a light red, twice pure red's
luma (153 against 76 of 255), so that it reads on dark backgrounds too."""
FIG3_TEXT = (255, 255, 255)
"""BGR colour of the labels."""

_FONT = cv2.FONT_HERSHEY_SIMPLEX


def dash_spans(x0: int, x1: int, dash_px: int, gap_px: int) -> NDArray[np.int32]:
    """``(K, 2)`` first and last coordinate of each dash from ``x0`` to ``x1`` (pixels): dashes of
    ``dash_px`` every ``dash_px + gap_px``, the last one cut at ``x1``."""
    starts = np.arange(x0, x1, dash_px + gap_px, dtype=np.int32)
    spans = np.empty((len(starts), 2), dtype=np.int32)
    spans[:, 0] = starts
    np.minimum(starts + dash_px, x1, out=spans[:, 1])
    return spans


def draw_segments(
    image: NDArray[np.uint8],
    segments: NDArray[np.int32],
    colour: tuple[int, int, int],
    thickness: int,
) -> None:
    """Draw ``(K, 2, 2)`` line segments (start and end ``(x, y)`` pixels) in one call, each
    exactly as ``cv2.line`` draws it (``LINE_8``; in place)."""
    if len(segments):
        cv2.polylines(image, list(segments), False, colour, thickness, cv2.LINE_8)


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
    spans = dash_spans(x0, x1, dash_px, gap_px)
    segments = np.empty((len(spans), 2, 2), dtype=np.int32)
    segments[:, :, 0] = spans
    segments[:, :, 1] = row
    draw_segments(image, segments, colour, thickness)


_OUTLINE_KERNEL = np.ones((3, 3), dtype=np.uint8)
"""The outline reaches one pixel around the text in every direction (8-neighbourhood)."""


def outlined_text(
    image: NDArray[np.uint8],
    text: str,
    org: tuple[int, int],
    scale: float,
    colour: tuple[int, int, int],
    thickness: int = 1,
) -> None:
    """``cv2.putText`` with a dark one-pixel outline, so the text reads on any background.

    The outline darkens the text's anti-aliased coverage grown by one pixel (a 3×3 dilation:
    the text drawn in black at the eight one-pixel offsets, in one pass), then the text is
    drawn over it. (A thicker black stroke would advance each glyph further and drift away
    from the text on long lines.)
    """
    (w, h), base = cv2.getTextSize(text, _FONT, scale, thickness)
    x, y = org
    pad = thickness + 2
    top, left = max(y - h - pad, 0), max(x - pad, 0)
    bottom, right = min(y + base + pad, image.shape[0]), min(x + w + pad, image.shape[1])
    if top < bottom and left < right:
        coverage = np.zeros((bottom - top, right - left), dtype=np.uint8)
        cv2.putText(coverage, text, (x - left, y - top), _FONT, scale, 255, thickness, cv2.LINE_AA)
        keep = 255 - cv2.dilate(coverage, _OUTLINE_KERNEL)  # 255: untouched (uint8, no wrap)
        roi = image[top:bottom, left:right]
        if roi.ndim == 3:
            keep = cv2.merge([keep] * roi.shape[2])
        image[top:bottom, left:right] = cv2.multiply(roi, keep, scale=1.0 / 255.0)
    cv2.putText(image, text, org, _FONT, scale, colour, thickness, cv2.LINE_AA)


LABEL_SCALE = 0.45
"""Font scale of the box labels (Hershey simplex)."""

SMALL_LABEL_SCALE = 0.38
"""Font scale of a label's last, smallest form (Hershey simplex; still readable on a
1242-pixel-wide frame)."""

LEADER_MIN_PX = 5.0
"""A label further than this from its box (beyond the layout's gap) gets a leader line."""

TRACK_COLOURS = (
    (255, 160, 0),
    (0, 200, 255),
    (255, 0, 255),
    (0, 255, 128),
    (255, 255, 0),
    (128, 128, 255),
    (0, 128, 255),
    (255, 128, 128),
    (180, 255, 0),
    (200, 200, 200),
)
"""BGR colours of tracks, by ``track_id`` modulo their number (boxes without a track:
:data:`FIG3_BOX`)."""

LEAD_COLOUR = (0, 255, 255)
"""BGR colour of the lead vehicle's banner and frame (yellow)."""

LANE_HALF_WIDTH_M = 1.75
"""Half the width of the ego lane, metres: a target whose bottom centre lies within this
lateral offset of the optical axis, at its estimated distance, is in the ego lane."""

CUT_MARGIN_PX = 1
"""A box within this many pixels of the image border is cut by it (its extent is unknown)."""


def track_colour(track_id: int) -> tuple[int, int, int]:
    """BGR colour of a track (:data:`TRACK_COLOURS`); :data:`FIG3_BOX` without a track."""
    if track_id < 0:
        return FIG3_BOX
    return TRACK_COLOURS[track_id % len(TRACK_COLOURS)]


def is_cut(box: NDArray[np.float64], width: int, height: int) -> bool:
    """True when ``box`` touches the border of a ``width × height`` image (within
    :data:`CUT_MARGIN_PX`)."""
    left, top, right, bottom = (float(c) for c in box)
    m = CUT_MARGIN_PX
    return left <= m or top <= m or right >= width - 1 - m or bottom >= height - 1 - m


def lead_index(camera: Camera, boxes: BoxTable, estimates: FrameEstimates) -> int | None:
    """Index of the lead vehicle: the nearest target of status ``ok`` (an upper bound is not a
    distance to show as one, whatever its reason) whose bottom centre lies in the ego lane
    (lateral offset ``(b_x − c_x)/f · z`` within :data:`LANE_HALF_WIDTH_M`)."""
    best: int | None = None
    for i in range(len(boxes)):
        z = float(estimates.distance_m[i])
        if estimates.status[i] != "ok" or not math.isfinite(z):  # only a distance to act on
            continue
        left, _, right, _ = (float(c) for c in boxes.boxes[i])
        lateral_m = ((left + right) / 2 - camera.c_x) / camera.f * z
        if abs(lateral_m) <= LANE_HALF_WIDTH_M and (
            best is None or z < float(estimates.distance_m[best])
        ):
            best = i
    return best


def _motion_text(estimates: FrameEstimates, i: int) -> str:
    """``"v -1.2 m/s  TTC 6.3 s"`` from the estimator's speed / TTC columns, where known."""
    parts = []
    speed = estimates.extra.get("speed_mps")
    ttc = estimates.extra.get("ttc_s")
    if speed is not None and math.isfinite(float(speed[i])):
        parts.append(f"v {float(speed[i]):+.1f} m/s")
    if ttc is not None and math.isfinite(float(ttc[i])) and float(ttc[i]) > 0:
        parts.append(f"TTC {float(ttc[i]):.1f} s")
    return "  ".join(parts)


def distance_label(track_id: int, distance_m: float, status: str, reason: str) -> str:
    """A target's label: ``#track distance m`` for status ``ok``, ``#track <= bound m
    (reason)`` for an ``upper_bound`` (a bound, not a distance to trust), ``#track missing:
    reason`` otherwise; no ``#track`` without a track id (negative); metres."""
    name = f"#{track_id} " if track_id >= 0 else ""
    if status == "ok":
        return f"{name}{distance_m:.1f} m"
    if status == "upper_bound":
        return f"{name}<= {distance_m:.1f} m ({reason})"
    return f"{name}missing: {reason}"


def _label_forms(
    boxes: BoxTable, estimates: FrameEstimates, i: int, cut: bool
) -> list[tuple[list[str], float]]:
    """The forms of box ``i``'s label, best first, as ``(lines, font scale)``: the full one
    (``#track distance m`` or ``<= bound m (reason)`` or ``missing: reason``, ``cut``, and
    Δy), the distance alone on one line, and that line in :data:`SMALL_LABEL_SCALE`."""
    tid = int(boxes.track_id[i])
    name = f"#{tid} " if tid >= 0 else ""
    dy = float(estimates.delta_y_px[i])
    dy_text = f"dy {dy:+.0f} px" if math.isfinite(dy) else "dy -"
    z = float(estimates.distance_m[i])
    status = str(estimates.status[i])
    first = distance_label(tid, z, status, str(estimates.reason[i]))
    if status == "ok":
        short = f"{name}{z:.1f} m"
    elif status == "upper_bound":  # a bound, not a distance to trust
        short = f"{name}<={z:.1f} m"
    else:
        short = f"{name}missing"
    full = [first + ("  cut" if cut else ""), dy_text]
    return [(full, LABEL_SCALE), ([short], LABEL_SCALE), ([short], SMALL_LABEL_SCALE)]


def _text_block_size(lines: list[str], scale: float) -> tuple[int, int, int]:
    """``(width, height, line height)`` of ``lines`` in pixels."""
    sizes = [cv2.getTextSize(t, _FONT, scale, 1)[0] for t in lines]
    line_h = max(sz[1] for sz in sizes) + 6
    return max(sz[0] for sz in sizes) + 4, line_h * len(lines) + 2, line_h


def _draw_box(
    out: NDArray[np.uint8], box: NDArray[np.float64], colour: tuple[int, int, int], cut: bool
) -> None:
    """The box outline; a cut box is dashed (its four dashed sides in one call)."""
    left, top, right, bottom = (round(float(c)) for c in box)
    if not cut:
        cv2.rectangle(out, (left, top), (right, bottom), colour, 2)
        return
    across, down = dash_spans(left, right, 8, 5), dash_spans(top, bottom, 8, 5)
    segments = np.empty((2 * (len(across) + len(down)), 2, 2), dtype=np.int32)
    n = len(across)
    for k, row in enumerate((top, bottom)):  # the horizontal sides
        segments[k * n : (k + 1) * n, :, 0] = across
        segments[k * n : (k + 1) * n, :, 1] = row
    m = len(down)
    for k, col in enumerate((left, right)):  # the vertical sides
        part = segments[2 * n + k * m : 2 * n + (k + 1) * m]
        part[:, :, 0] = col
        part[:, :, 1] = down
    draw_segments(out, segments, colour, 2)


def _draw_labels(
    out: NDArray[np.uint8],
    boxes: BoxTable,
    forms: list[list[tuple[list[str], float]]],
    colours: list[tuple[int, int, int]],
    order: list[int],
    keep_clear: tuple[list[Rect], int | None],
) -> list[Placement | None]:
    """Lay out (:func:`slopedist.streaming.label_placement.layout_labels`, in ``order``, off the
    ``keep_clear``
    rectangles and rather not across its row) and draw the labels; returns each box's
    placement (None where the image had no room left)."""
    blocks = [[_text_block_size(lines, scale) for lines, scale in forms[i]] for i in order]
    reserved, clear_row = keep_clear
    placements = layout_labels(
        boxes.boxes[order],
        [[(w, h) for w, h, _ in b] for b in blocks],
        (out.shape[1], out.shape[0]),
        reserved,
        clear_row,
    )
    placed: list[Placement | None] = [None] * len(boxes)
    for i, p, block in zip(order, placements, blocks):
        placed[i] = p
        if p is None:
            continue
        rect, (lines, scale), line_h = p.rect, forms[i][p.form], block[p.form][2]
        if p.gap_px > LEADER_MIN_PX:  # a leader line between the nearest points
            own = box_rect(boxes.boxes[i])
            a = _nearest_point(rect, ((own.left + own.right) // 2, (own.top + own.bottom) // 2))
            cv2.line(out, a, _nearest_point(own, a), colours[i], 1, cv2.LINE_AA)
        y = rect.top + line_h - 3
        for text in lines:
            outlined_text(out, text, (rect.left + 2, y), scale, colours[i])
            y += line_h
    return placed


def _nearest_point(rect: Rect, p: tuple[int, int]) -> tuple[int, int]:
    """The point of ``rect`` nearest to ``p`` (pixels)."""
    return min(max(p[0], rect.left), rect.right - 1), min(max(p[1], rect.top), rect.bottom - 1)


def _header_text(header: str | None, method: str | None, theta_rad: float) -> str:
    parts = [p for p in (header, method and f"method {method}") if p]
    if method and math.isfinite(theta_rad):
        parts.append(f"theta {math.degrees(theta_rad):+.2f} deg")
    return "   ".join(parts)


def draw_fig3_overlay(
    image: NDArray[np.uint8],
    camera: Camera,
    boxes: BoxTable,
    estimates: FrameEstimates,
    theta_rad: float | None = None,
    header: str | None = None,
    method: str | None = None,
) -> NDArray[np.uint8]:
    """Annotate a frame in the style of the paper's Fig. 3; returns a new image.

    Draws each box in its track's colour (:func:`track_colour`; dashed when the image border
    cuts it, :func:`is_cut`), a dashed yellow line at each box's vertical centre ``b_y``, the
    vanishing line of the ego gradient (eq. 5, ``v = c_y − f·tan θ``) as a solid green line,
    and, last and on top, a label per box — ``#track distance m`` (or ``missing: reason``) and
    Δy (px, eq. 6) — laid out by :func:`slopedist.streaming.label_placement.layout_labels` so that
    no two labels
    overlap: the lead vehicle first, then the nearest targets; a leader line joins a label set
    away from its box; where the full label finds no room, the distance alone on one line, in a
    smaller font as a last resort (:func:`_label_forms`). The lead vehicle (:func:`lead_index`)
    gets a yellow frame and a banner under the header with its distance, relative speed and TTC
    where the method gives them. Hershey fonts have no Greek letters, so Δy is written ``dy``
    and θ ``theta``.

    Args:
        image: BGR ``H×W×3`` (or grey ``H×W``) uint8 frame; not modified.
        camera: the frame's camera (``f``, ``c_x``, ``c_y``).
        boxes: the frame's boxes.
        estimates: the estimates of those boxes (same order).
        theta_rad: ego road gradient θ of the frame, radians. None takes it from
            ``estimates.theta_rad`` (first finite value). No green line when θ is unknown.
        header: optional text written at the top left (e.g. frame number and time).
        method: the method's name, written in the header with θ (degrees).
    """
    out = np.asarray(
        cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy(), dtype=np.uint8
    )
    h, w = out.shape[:2]
    if theta_rad is None:
        finite = estimates.theta_rad[np.isfinite(estimates.theta_rad)]
        theta_rad = float(finite[0]) if finite.size else math.nan
    valid = [i for i in range(len(boxes)) if np.all(np.isfinite(boxes.boxes[i]))]
    cut = {i: is_cut(boxes.boxes[i], w, h) for i in valid}
    colours = [track_colour(int(t)) for t in boxes.track_id]
    for i in valid:
        b_y = round(float(geo.box_centre_row(boxes.boxes[i])))
        left, _, right, _ = (round(float(c)) for c in boxes.boxes[i])
        if 0 <= b_y < h:
            reach = max((right - left) // 2, 20)
            dashed_hline(out, b_y, max(left - reach, 0), min(right + reach, w - 1), FIG3_YELLOW)
        ok = estimates.status[i] == "ok"
        _draw_box(out, boxes.boxes[i], colours[i] if ok else FIG3_MISSING, cut[i])
    lead = lead_index(camera, boxes, estimates)
    reserved = _draw_header(out, _header_text(header, method, theta_rad), boxes, estimates, lead)
    forms = [_label_forms(boxes, estimates, i, cut.get(i, False)) for i in range(len(boxes))]
    label_colours = [
        FIG3_MISSING_TEXT if estimates.status[i] != "ok" else FIG3_TEXT if t < 0 else colours[i]
        for i, t in enumerate(boxes.track_id)
    ]
    order = sorted(valid, key=lambda i: _label_priority(estimates, i, lead))
    row = (
        round(float(geo.vanishing_line_row(theta_rad, camera.f, camera.c_y)))
        if math.isfinite(theta_rad)
        else None
    )
    if row is not None and 0 <= row < h:
        cv2.line(out, (0, row), (w - 1, row), FIG3_GREEN, 2, cv2.LINE_8)
    _draw_labels(out, boxes, forms, label_colours, order, (reserved, row))
    return out


def _label_priority(estimates: FrameEstimates, i: int, lead: int | None) -> tuple[int, float]:
    """Order in which the labels are laid out: the lead vehicle, the targets with a distance
    (nearest first), then those with an upper bound (smallest first), then the rest."""
    if i == lead:
        return 0, 0.0
    z = float(estimates.distance_m[i])
    rank = {"ok": 1, "upper_bound": 2}.get(str(estimates.status[i]), 3)
    return rank, z if math.isfinite(z) else math.inf


def _draw_header(
    out: NDArray[np.uint8],
    text: str,
    boxes: BoxTable,
    estimates: FrameEstimates,
    lead: int | None,
) -> list[Rect]:
    """Header line, and the lead vehicle's frame and banner; returns the rectangles they take
    (no label may cover them)."""
    taken: list[Rect] = []
    y = 20
    if text:
        (tw, th), _ = cv2.getTextSize(text, _FONT, 0.55, 1)
        outlined_text(out, text, (8, y), 0.55, FIG3_TEXT)
        taken.append(Rect(6, y - th - 3, 10 + tw, y + 5))
        y += th + 12
    if lead is not None:
        left, top, right, bottom = (round(float(c)) for c in boxes.boxes[lead])
        cv2.rectangle(out, (left - 3, top - 3), (right + 3, bottom + 3), LEAD_COLOUR, 2)
        tid = int(boxes.track_id[lead])
        banner = f"LEAD{f' #{tid}' if tid >= 0 else ''}  {float(estimates.distance_m[lead]):.1f} m"
        motion = _motion_text(estimates, lead)
        banner += f"  {motion}" if motion else ""
        (tw, th), _ = cv2.getTextSize(banner, _FONT, 0.6, 2)
        cv2.rectangle(out, (6, y - th - 4), (14 + tw, y + 6), (0, 0, 0), -1)
        cv2.putText(out, banner, (10, y), _FONT, 0.6, LEAD_COLOUR, 2, cv2.LINE_AA)
        taken.append(Rect(6, y - th - 4, 15 + tw, y + 7))
    return taken
