"""Greedy placement of box labels so that no two labels overlap.

Convention: pixels, image origin top-left, rows downwards; boxes and rectangles are
``(left, top, right, bottom)`` with ``right``/``bottom`` exclusive for rectangles.

Labels are placed one after the other in the caller's order (e.g. the lead vehicle first, then
the nearest targets), each never over a label placed before it nor over a ``reserved``
rectangle (a header), and always inside the image. A label may come in several forms, best
first (e.g. two lines; one short line; one short line in a smaller font). Each form is tried
at the spots of :func:`candidate_grid` (touching the box on its right, on its left, above and
below it, slid along each edge; over the box; then pushed further out), and the cheapest
allowed spot of any form wins (:func:`grid_costs`): its distance from the box in pixels, plus
:data:`COVER_COST_PX` for covering other boxes, :data:`OWN_COVER_COST_PX` for covering its
own box, :data:`LINE_COST_PX` for crossing a row to keep clear (the vanishing line) and
:data:`FORM_COST_PX` for each step to a shorter form; ties go to the earlier spot. A label for
which no spot around its box is free takes, in its last form, the cheapest free spot anywhere
in the image (:func:`image_grid`; the caller draws a leader line to it). A label is left out
(None) only when no free spot of its size is left in the whole image.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

LABEL_GAP_PX = 3
"""Space between a box and its label, and between stacked labels, pixels."""

PUSH_STEPS = 6
"""How many label heights (and half label widths) a spot may be pushed away from its box."""

COVER_COST_PX = 150.0
"""Cost of a label lying wholly over other boxes, in pixels of distance from its own box
(pro rata of the covered fraction of the label's area, summed over the boxes)."""

OWN_COVER_COST_PX = 30.0
"""Cost of a label lying wholly over its own box (pro rata), pixels of distance."""

LINE_COST_PX = 12.0
"""Cost of a label crossed by the row to keep clear (the vanishing line), pixels of distance."""

FORM_COST_PX = 40.0
"""Cost of each step from a label's first form to a shorter one, pixels of distance."""

BLOCKED_COST_PX = 1e9
"""Cost of each square pixel of a label over a rectangle no label may cover (a spot costing
this much or more is not allowed)."""


@dataclass(frozen=True)
class SpotGrid:
    """Label spots: every combination of the columns ``xs`` and rows ``ys`` of a label's
    top-left corner (pixels); a grid's spots are tried row by row, ties going to the first."""

    xs: list[int]
    ys: list[int]


@dataclass(frozen=True)
class Rect:
    """Axis-aligned rectangle, pixels; ``right`` and ``bottom`` exclusive."""

    left: int
    top: int
    right: int
    bottom: int

    def intersects(self, other: Rect) -> bool:
        """True when the two rectangles share at least one pixel."""
        return (
            self.left < other.right
            and other.left < self.right
            and self.top < other.bottom
            and other.top < self.bottom
        )

    def inside(self, width: int, height: int) -> bool:
        """True when the rectangle lies within a ``width × height`` image."""
        return self.left >= 0 and self.top >= 0 and self.right <= width and self.bottom <= height

    def overlap_area(self, other: Rect) -> int:
        """Shared area, square pixels."""
        w = min(self.right, other.right) - max(self.left, other.left)
        h = min(self.bottom, other.bottom) - max(self.top, other.top)
        return max(w, 0) * max(h, 0)


@dataclass(frozen=True)
class Placement:
    """Where a label went.

    Attributes:
        rect: the label's rectangle, pixels.
        form: index of the label's form that fitted (0 = its first, fullest form).
        gap_px: distance between the label and its box beyond :data:`LABEL_GAP_PX`, pixels
            (0 when it touches the box's side or lies over the box).
    """

    rect: Rect
    form: int
    gap_px: float


def box_rect(box: ArrayLike) -> Rect:
    """A ``(left, top, right, bottom)`` float box as the integer rectangle covering it."""
    left, top, right, bottom = (float(v) for v in np.asarray(box, dtype=float))
    return Rect(int(np.floor(left)), int(np.floor(top)), int(np.ceil(right)), int(np.ceil(bottom)))


def _slide(first: int, last: int, step: int) -> list[int]:
    """``first, first + step, …`` up to ``last`` (which is included); ``[first, last]`` when
    ``last < first``."""
    if last <= first:
        return [first, last] if last < first else [first]
    values = list(range(first, last, max(step, 1)))
    return [*values, last]


def candidate_grid(box: Rect, width: int, height: int) -> SpotGrid:
    """Spots for a ``width × height`` label around ``box``.

    Columns: right of the box (:data:`LABEL_GAP_PX` away), over it (left-aligned, then slid
    right in steps of half the label's width), left of it, then pushed further out right and
    left (up to :data:`PUSH_STEPS` half widths plus gaps). Rows: along its side (top-aligned,
    then slid down in steps of half the label's height), above it, below it, then pushed
    further up and down (up to :data:`PUSH_STEPS` heights plus gaps). Ties go to the first
    spot: right of the box, top-aligned, then left of it.
    """
    g = LABEL_GAP_PX
    x_right, x_left = box.right + g, box.left - g - width
    y_above, y_below = box.top - g - height, box.bottom + g
    dx, dy = width // 2 + g, height + g
    steps = range(1, PUSH_STEPS + 1)
    xs = [x_right, *_slide(box.left, box.right - width, width // 2), x_left]
    xs += [v for p in steps for v in (x_right + p * dx, x_left - p * dx)]
    ys = [*_slide(box.top, box.bottom - height, height // 2), y_above, y_below]
    ys += [v for p in steps for v in (y_above - p * dy, y_below + p * dy)]
    return SpotGrid(xs, ys)


def image_grid(image_size: tuple[int, int], width: int, height: int) -> SpotGrid:
    """Spots for a ``width × height`` label over the whole image, in steps of a quarter of its
    width and half its height (the last column and row flush with the border)."""
    w_img, h_img = image_size
    return SpotGrid(_slide(0, w_img - width, width // 4), _slide(0, h_img - height, height // 2))


def _extent(starts: NDArray[np.float64], size: int, lo: NDArray, hi: NDArray) -> NDArray:
    """``(n, M)`` length shared by the intervals ``[start, start + size)`` and ``[lo, hi)``."""
    a = starts[:, None]
    return np.maximum(np.minimum(a + size, hi) - np.maximum(a, lo), 0.0)


def _gaps(starts: NDArray[np.float64], size: int, lo: int, hi: int) -> NDArray[np.float64]:
    """Distance between each interval ``[start, start + size)`` and ``[lo, hi)``."""
    return np.maximum(np.maximum(lo - (starts + size), starts - hi), 0.0)


def grid_costs(
    grid: SpotGrid,
    size: tuple[int, int],
    own: Rect,
    rects: NDArray[np.float64],
    weights: NDArray[np.float64],
    clear_row: int | None,
) -> NDArray[np.float64]:
    """``(len(ys), len(xs))`` cost of each spot of ``grid`` for a ``size = (width, height)``
    label of box ``own`` (module docstring), pixels: its distance from the box beyond the gap,
    plus the area it shares with each of ``rects`` (``(M, 4)``) times that rectangle's weight
    (per square pixel: :data:`COVER_COST_PX` over the label's area for another box,
    :data:`BLOCKED_COST_PX` for a rectangle no label may cover), plus :data:`LINE_COST_PX` when
    row ``clear_row`` crosses it.

    The area a spot shares with a rectangle is the product of the column overlap and the row
    overlap, so the sum over the rectangles is a matrix product of ``(ny, M)`` and ``(M, nx)``.
    """
    w, h = size
    xs, ys = np.asarray(grid.xs, np.float64), np.asarray(grid.ys, np.float64)
    wx = _extent(xs, w, rects[:, 0], rects[:, 2])
    hy = _extent(ys, h, rects[:, 1], rects[:, 3])
    line = np.zeros(len(ys))
    if clear_row is not None:
        line[(ys <= clear_row) & (clear_row < ys + h)] = LINE_COST_PX
    dx = _gaps(xs, w, own.left, own.right)
    dy = _gaps(ys, h, own.top, own.bottom)
    gap = np.maximum(np.hypot(dx[None, :], dy[:, None]) - LABEL_GAP_PX, 0.0)
    return (hy * weights) @ wx.T + gap + line[:, None]


@dataclass
class _Layout:
    """The state of a layout: the boxes (the first ``n_boxes`` rectangles), then the
    rectangles no label may cover (the reserved ones and the labels placed so far)."""

    image_size: tuple[int, int]
    rects: NDArray[np.float64]
    n_boxes: int
    clear_row: int | None

    def best(
        self, grid: SpotGrid, size: tuple[int, int], own: int, extra_cost: float
    ) -> tuple[float, Rect] | None:
        """Cost (plus ``extra_cost``) and rectangle of the cheapest spot of ``grid`` for a
        ``size`` label of box ``own`` that lies inside the image and off every taken
        rectangle; None if there is none."""
        w, h = size
        xs = [x for x in grid.xs if 0 <= x <= self.image_size[0] - w]
        ys = [y for y in grid.ys if 0 <= y <= self.image_size[1] - h]
        if not xs or not ys:
            return None
        weights = np.full(len(self.rects), BLOCKED_COST_PX)
        weights[: self.n_boxes] = COVER_COST_PX / (w * h)
        weights[own] = OWN_COVER_COST_PX / (w * h)
        cost = grid_costs(
            SpotGrid(xs, ys), size, self.box(own), self.rects, weights, self.clear_row
        )
        iy, ix = divmod(int(np.argmin(cost)), len(xs))
        if cost[iy, ix] >= BLOCKED_COST_PX:
            return None
        return float(cost[iy, ix]) + extra_cost, Rect(xs[ix], ys[iy], xs[ix] + w, ys[iy] + h)

    def box(self, i: int) -> Rect:
        """Box ``i`` as a rectangle."""
        left, top, right, bottom = (int(v) for v in self.rects[i])
        return Rect(left, top, right, bottom)

    def take(self, rect: Rect) -> None:
        """No later label may cover ``rect``."""
        row = np.array([[rect.left, rect.top, rect.right, rect.bottom]], np.float64)
        self.rects = np.vstack([self.rects, row])

    def place(self, own: int, forms: Sequence[tuple[int, int]]) -> Placement | None:
        """Place the label of box ``own`` (``forms``: its ``(width, height)`` sizes, best
        first) and take its rectangle."""
        box = self.box(own)
        found: tuple[float, Rect, int] | None = None
        for f, (w, h) in enumerate(forms):
            if found is not None and found[0] <= f * FORM_COST_PX:
                break  # a shorter form cannot beat it
            size = (int(w), int(h))
            hit = self.best(candidate_grid(box, *size), size, own, f * FORM_COST_PX)
            if hit is not None and (found is None or hit[0] < found[0]):
                found = (*hit, f)
        if found is None:  # anywhere in the image, in the last form
            f = len(forms) - 1
            size = (int(forms[f][0]), int(forms[f][1]))
            hit = self.best(image_grid(self.image_size, *size), size, own, 0.0)
            if hit is None:
                return None
            found = (*hit, f)
        _, rect, f = found
        self.take(rect)
        return Placement(rect, f, rect_gap(rect, box))


def rect_gap(rect: Rect, box: Rect) -> float:
    """Distance between ``rect`` and ``box`` beyond :data:`LABEL_GAP_PX`, pixels (0 when they
    touch or overlap)."""
    dx = max(box.left - rect.right, rect.left - box.right, 0)
    dy = max(box.top - rect.bottom, rect.top - box.bottom, 0)
    return max(float(np.hypot(dx, dy)) - LABEL_GAP_PX, 0.0)


def _as_array(rects: Sequence[Rect]) -> NDArray[np.float64]:
    return np.array([[r.left, r.top, r.right, r.bottom] for r in rects], np.float64).reshape(-1, 4)


def layout_labels(
    boxes: ArrayLike,
    forms: Sequence[Sequence[tuple[int, int]]],
    image_size: tuple[int, int],
    reserved: Sequence[Rect] = (),
    clear_row: int | None = None,
) -> list[Placement | None]:
    """Placements of the labels of ``boxes`` (``(N, 4)`` pixels), in the given order (see the
    module docstring).

    Args:
        boxes: ``(N, 4)`` boxes ``(left, top, right, bottom)``, pixels; a box with non-finite
            coordinates gets None.
        forms: per box, the ``(width, height)`` pixel sizes of its label's forms, best first.
        image_size: ``(width, height)`` of the image, pixels.
        reserved: rectangles no label may cover (e.g. a header).
        clear_row: a row labels should rather not cross (e.g. the vanishing line), or None.
    """
    arr = np.asarray(boxes, dtype=float).reshape(-1, 4)
    finite = np.all(np.isfinite(arr), axis=1)
    keep = np.flatnonzero(finite)
    rects = _as_array([*(box_rect(b) for b in arr[keep]), *reserved])
    layout = _Layout(image_size, rects, len(keep), clear_row)
    out: list[Placement | None] = [None] * len(arr)
    for k, i in enumerate(keep):
        out[int(i)] = layout.place(k, forms[int(i)])
    return out


def place_labels(
    boxes: ArrayLike,
    sizes: Sequence[tuple[int, int]],
    image_size: tuple[int, int],
    reserved: Sequence[Rect] = (),
) -> list[Rect | None]:
    """Label rectangles for ``boxes`` (``(N, 4)``) with one label size ``(width, height)``
    pixels each, in a ``(width, height)`` image (:func:`layout_labels` with one form per
    label); None where a box is not finite or the image has no room left."""
    placed = layout_labels(boxes, [[s] for s in sizes], image_size, reserved)
    return [p.rect if p is not None else None for p in placed]
