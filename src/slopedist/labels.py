"""Greedy placement of box labels so that no two labels overlap.

Convention: pixels, image origin top-left, rows downwards; boxes and rectangles are
``(left, top, right, bottom)`` with ``right``/``bottom`` exclusive for rectangles.

Each label is tried, in priority order (the caller's order: e.g. nearest target first), at a
list of candidate spots around its box (:func:`candidate_spots`: right of the box, above it,
left of it, below it, then the same spots pushed further out in steps of the label's height).
The first spot inside the image that overlaps no label placed before it wins, preferring
spots that cover no other box (a spot covering boxes is taken only when every free spot is
taken). A label that finds no spot is not placed (None), and the caller draws its box without
it; placed labels never overlap.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

LABEL_GAP_PX = 3
"""Space between a box and its label, and between stacked labels, pixels."""

PUSH_STEPS = 6
"""How many label heights a spot may be pushed away from its box."""


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


def box_rect(box: ArrayLike) -> Rect:
    """A ``(left, top, right, bottom)`` float box as the integer rectangle covering it."""
    left, top, right, bottom = (float(v) for v in np.asarray(box, dtype=float))
    return Rect(int(np.floor(left)), int(np.floor(top)), int(np.ceil(right)), int(np.ceil(bottom)))


def candidate_spots(box: Rect, width: int, height: int) -> list[Rect]:
    """Spots for a ``width × height`` label around ``box``, best first (module docstring)."""
    g = LABEL_GAP_PX
    spots: list[Rect] = []
    for step in range(PUSH_STEPS + 1):
        dy = step * (height + g)
        dx = step * (width + g) // 2
        x_right, x_left = box.right + g, box.left - g - width
        y_above, y_below = box.top - g - height - dy, box.bottom + g + dy
        for x, y in (
            (x_right, box.top + dy),  # right of the box, top-aligned, then lower
            (box.left + dx, y_above),  # above
            (x_left, box.top + dy),  # left
            (box.left + dx, y_below),  # below
            (x_right, box.top - dy),  # right, higher
            (x_left, box.top - dy),  # left, higher
            (box.left - dx, y_above),  # above, shifted left
        ):
            spots.append(Rect(x, y, x + width, y + height))
    return spots


def place_labels(
    boxes: ArrayLike,
    sizes: Sequence[tuple[int, int]],
    image_size: tuple[int, int],
    reserved: Sequence[Rect] = (),
) -> list[Rect | None]:
    """Label rectangles for ``boxes`` (``(N, 4)``), label ``sizes`` ``(width, height)`` pixels,
    in a ``(width, height)`` image; labels are placed in the given order (see the module
    docstring) and never on a ``reserved`` rectangle (e.g. a header). Boxes with non-finite
    coordinates get None.
    """
    arr = np.asarray(boxes, dtype=float).reshape(-1, 4)
    finite = np.all(np.isfinite(arr), axis=1)
    rects = [box_rect(b) if ok else None for b, ok in zip(arr, finite)]
    obstacles = [r for r in rects if r is not None]
    placed: list[Rect] = list(reserved)
    out: list[Rect | None] = []
    W, H = image_size
    for own, (w, h) in zip(rects, sizes):
        if own is None:
            out.append(None)
            continue
        best: Rect | None = None
        best_cover = -1
        for spot in candidate_spots(own, int(w), int(h)):
            if not spot.inside(W, H) or any(spot.intersects(p) for p in placed):
                continue
            cover = sum(spot.overlap_area(o) for o in obstacles if o is not own)
            if best is None or cover < best_cover:
                best, best_cover = spot, cover
                if cover == 0:
                    break
        if best is not None:
            placed.append(best)
        out.append(best)
    return out
