"""Whether any of many axis-aligned rectangles contains a point or meets a horizontal segment,
answered for many points or segments at once without testing every pair.

A segment tree over the sorted x positions splits every x range into ``O(log n)`` nodes; a point
lies below one node per level. A rectangle and a point (or segment) can meet only at a node they
share, and there only their y extents remain to compare: sorted by node and by the lower y, a
running maximum of the upper y answers every query with one binary search. In all
``O(n log² n)`` for ``n`` rectangles and queries, whatever the number of pairs that meet (a
crowded image has ``O(n²)``).

Coordinates are compared, never computed with, so the answers are those of testing every pair,
bit for bit. Sides are open or closed as each function says.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


def contains_point(
    rect_x: tuple[FloatArray, FloatArray],
    rect_y: tuple[FloatArray, FloatArray],
    px: FloatArray,
    py: FloatArray,
    closed_x: Literal["lower", "upper", "neither"],
) -> BoolArray:
    """Per point ``(px, py)``, whether some rectangle holds it: ``y_lo < py < y_hi`` and
    ``x_lo ≤ px < x_hi`` (``closed_x="lower"``), ``x_lo < px ≤ x_hi`` (``"upper"``) or
    ``x_lo < px < x_hi`` (``"neither"``).

    ``rect_x`` and ``rect_y`` are ``(lo, hi)`` arrays of shape ``(R,)``; ``px``, ``py`` ``(P,)``.
    """
    order = np.argsort(px, kind="stable")
    xs = px[order]
    # the points in a rectangle's x range are xs[start:stop]
    start = np.searchsorted(xs, rect_x[0], side="left" if closed_x == "lower" else "right")
    stop = np.searchsorted(xs, rect_x[1], side="right" if closed_x == "upper" else "left")
    return _held(order, start, stop, rect_y, py)


def contains_edges(
    rect_x: tuple[FloatArray, FloatArray],
    rect_y: tuple[FloatArray, FloatArray],
    left_x: FloatArray,
    right_x: FloatArray,
    py: FloatArray,
) -> tuple[BoolArray, BoolArray]:
    """:func:`contains_point` of the points ``(left_x, py)`` with ``closed_x="lower"`` and of
    the points ``(right_x, py)`` with ``closed_x="upper"`` (all ``(P,)``), in one tree.

    Sorted by x, with a right point before a left one at the same x, the points a rectangle
    holds are those between the two places that fall after the right points and before the
    left points at ``x_lo`` and at ``x_hi``: ``x_lo ≤ left_x < x_hi`` and ``x_lo < right_x ≤
    x_hi``.
    """
    n = left_x.shape[0]
    px = np.concatenate([right_x, left_x])
    order = np.lexsort((np.arange(2 * n) >= n, px))  # by x, right points first
    xs_right, xs_left = np.sort(right_x), np.sort(left_x)

    def place(x: FloatArray) -> IntArray:
        """Where x falls: after the right points at x, before the left points."""
        return np.searchsorted(xs_right, x, side="right") + np.searchsorted(xs_left, x, "left")

    held = _held(order, place(rect_x[0]), place(rect_x[1]), rect_y, np.concatenate([py, py]))
    return held[n:], held[:n]


def _held(
    order: NDArray[np.intp],
    start: IntArray,
    stop: IntArray,
    rect_y: tuple[FloatArray, FloatArray],
    py: FloatArray,
) -> BoolArray:
    """Per point, whether a rectangle whose x range holds the sorted points
    ``order[start:stop]`` has ``y_lo < py < y_hi``: the segment tree over the points."""
    size = _leaves(py.shape[0])
    rect, rect_node = _covering_nodes(start, stop, size)
    at, point_node = _ancestors(py.shape[0], size)
    point = order[at]
    (y_lo, y_hi, y), span = _ranks(rect_y[0], rect_y[1], py)
    hit = _stabbed(rect_node, y_lo[rect], y_hi[rect], point_node, y[point], span)
    return np.bincount(point[hit], minlength=py.shape[0]) > 0


def meets_segment(
    rect_x: tuple[FloatArray, FloatArray],
    rect_y: tuple[FloatArray, FloatArray],
    seg_x: tuple[FloatArray, FloatArray],
    sy: FloatArray,
    start_held: BoolArray | None = None,
) -> BoolArray:
    """Per horizontal segment ``x_lo < x < x_hi`` at ``y = sy``, whether it meets the open
    interior ``(x_lo, x_hi) × (y_lo, y_hi)`` of some rectangle.

    Two open x ranges meet when the rectangle starts inside the segment (``s_lo ≤ x_lo < s_hi``)
    or the segment starts inside the rectangle (``x_lo ≤ s_lo < x_hi``; ``x_lo = s_lo`` is in
    both). Rectangles with ``x_hi ≤ x_lo`` and segments with ``s_hi ≤ s_lo`` meet nothing.

    ``start_held``: the second half if the caller has it already, i.e.
    ``contains_point(rect_x, rect_y, seg_x[0], sy, "lower")``; None computes it.
    """
    wide = seg_x[1] > seg_x[0]
    proper = np.flatnonzero(rect_x[1] > rect_x[0])
    rx = (rect_x[0][proper], rect_x[1][proper])
    ry = (rect_y[0][proper], rect_y[1][proper])
    if start_held is None:
        start_held = contains_point(rx, ry, seg_x[0], sy, "lower")
    starts = _starts_in_segment(rx[0], ry, seg_x, sy)
    return wide & (start_held | starts)


def _starts_in_segment(
    rect_x_lo: FloatArray,
    rect_y: tuple[FloatArray, FloatArray],
    seg_x: tuple[FloatArray, FloatArray],
    sy: FloatArray,
) -> BoolArray:
    """Per segment, whether a rectangle starts within it (``s_lo ≤ x_lo < s_hi``) and spans its
    height ``sy`` (``y_lo < sy < y_hi``): the tree is over the rectangles' starts."""
    order = np.argsort(rect_x_lo, kind="stable")
    starts = rect_x_lo[order]
    first = np.searchsorted(starts, seg_x[0], side="left")
    stop = np.searchsorted(starts, seg_x[1], side="left")
    size = _leaves(rect_x_lo.shape[0])
    seg, seg_node = _covering_nodes(first, stop, size)
    at, rect_node = _ancestors(rect_x_lo.shape[0], size)
    rect = order[at]
    (y_lo, y_hi, y), span = _ranks(rect_y[0], rect_y[1], sy)
    hit = _stabbed(rect_node, y_lo[rect], y_hi[rect], seg_node, y[seg], span)
    return np.bincount(seg[hit], minlength=seg_x[0].shape[0]) > 0


def _leaves(n: int) -> int:
    """Leaves of a segment tree over ``n`` positions: the power of two at or above ``n``."""
    return 1 << max(n - 1, 0).bit_length()


def _covering_nodes(start: IntArray, stop: IntArray, size: int) -> tuple[IntArray, IntArray]:
    """``(range, node)`` pairs: the nodes of a segment tree over ``size`` leaves (node 1 the
    root, the children of ``k`` are ``2k`` and ``2k + 1``, leaf ``i`` is node ``size + i``)
    that together cover exactly the leaves ``start ≤ i < stop`` of each range, at most two
    a level."""
    owner = np.arange(start.shape[0])
    lo, hi = start.astype(np.int64) + size, stop.astype(np.int64) + size
    owners, nodes = [owner[:0]], [lo[:0]]
    while owner.size:
        live = lo < hi
        owner, lo, hi = owner[live], lo[live], hi[live]
        left = (lo & 1) == 1  # a right child: taken whole, its parent reaches further left
        owners.append(owner[left])
        nodes.append(lo[left])
        right = (hi & 1) == 1  # the range ends on a left child's right edge: take the child
        owners.append(owner[right])
        nodes.append(hi[right] - 1)
        lo, hi = (lo + left) >> 1, (hi - right) >> 1
    return np.concatenate(owners), np.concatenate(nodes)


def _ancestors(n: int, size: int) -> tuple[IntArray, IntArray]:
    """``(leaf, node)`` pairs: every node on the path from each of the first ``n`` leaves to
    the root, level by level from the leaves up."""
    levels = size.bit_length()  # log2(size) + 1 nodes on each path
    leaf = np.arange(n)
    node = (leaf[None, :] + size) >> np.arange(levels)[:, None]
    return np.broadcast_to(leaf, node.shape).ravel(), node.ravel()


def _ranks(*values: FloatArray) -> tuple[list[IntArray], int]:
    """Each array's values replaced by their rank among all of them (equal values, equal
    ranks: every ``<`` between them is kept), and the number of distinct values."""
    distinct, rank = np.unique(np.concatenate(values), return_inverse=True)
    bounds = np.cumsum([v.shape[0] for v in values])[:-1]
    return np.split(rank.astype(np.int64), bounds), distinct.shape[0]


def _stabbed(
    entry_node: IntArray,
    entry_lo: IntArray,
    entry_hi: IntArray,
    query_node: IntArray,
    query_y: IntArray,
    span: int,
) -> BoolArray:
    """Per query, whether an entry of its node has ``entry_lo < query_y < entry_hi`` (ranks,
    all below ``span``).

    The entries sorted by node and lower end; the last one of the query's node below
    ``query_y`` carries the largest upper end of all of them (a running maximum). Node and
    rank combine into one integer key ``node·span + rank``, ordered by node first.
    """
    if entry_lo.size == 0 or query_y.size == 0:
        return np.zeros(query_y.shape[0], dtype=bool)
    key = entry_node * span + entry_lo
    order = np.argsort(key, kind="stable")
    key = key[order]
    node = entry_node[order]
    top = np.maximum.accumulate(node * span + entry_hi[order])
    below = np.searchsorted(key, query_node * span + query_y, side="left") - 1
    k = np.maximum(below, 0)
    same_node = (below >= 0) & (node[k] == query_node)
    return same_node & (top[k] - query_node * span > query_y)
