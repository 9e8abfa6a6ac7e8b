"""Which of many rectangles hold a point or meet a segment: the same answers as testing every
pair, ties included."""

from __future__ import annotations

from typing import Literal

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist.core.rectangles import contains_edges, contains_point, meets_segment


def _grid(rng: np.random.Generator, n: int, span: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` (lo, hi) pairs on a coarse integer grid (many equal ends); some empty or inverted."""
    lo = rng.integers(0, span, n).astype(float)
    return lo, lo + rng.integers(-2, span // 2 + 2, n)


def _in(lo: float, hi: float, x: float, closed: str) -> bool:
    return bool(
        (lo <= x if closed == "lower" else lo < x) and (x <= hi if closed == "upper" else x < hi)
    )


def _held_by_some(
    rx: tuple[np.ndarray, np.ndarray],
    ry: tuple[np.ndarray, np.ndarray],
    px: np.ndarray,
    py: np.ndarray,
    closed: Literal["lower", "upper", "neither"],
) -> list[bool]:
    """Per point, whether some rectangle holds it, testing every pair."""
    return [
        any(
            _in(rx[0][r], rx[1][r], px[p], closed) and ry[0][r] < py[p] < ry[1][r]
            for r in range(rx[0].shape[0])
        )
        for p in range(px.shape[0])
    ]


@settings(max_examples=60, deadline=None)
@given(
    st.integers(0, 2**31),
    st.integers(0, 90),
    st.integers(0, 90),
    st.sampled_from([4, 12, 60]),
    st.sampled_from(["lower", "upper", "neither"]),
)
def test_contains_point_equals_testing_every_pair(
    seed: int, n_rect: int, n_point: int, span: int, closed: Literal["lower", "upper", "neither"]
) -> None:
    rng = np.random.default_rng(seed)
    rx, ry = _grid(rng, n_rect, span), _grid(rng, n_rect, span)
    px, py = rng.integers(-1, span + 1, n_point).astype(float), rng.integers(0, span, n_point)
    py = py.astype(float)
    got = contains_point(rx, ry, px, py, closed)
    assert got.tolist() == _held_by_some(rx, ry, px, py, closed)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31), st.integers(0, 90), st.integers(0, 90), st.sampled_from([4, 12, 60]))
def test_contains_edges_equals_testing_every_pair(
    seed: int, n_rect: int, n_point: int, span: int
) -> None:
    """Left ends closed below, right ends closed above, in one tree; many shared x values."""
    rng = np.random.default_rng(seed)
    rx, ry = _grid(rng, n_rect, span), _grid(rng, n_rect, span)
    left, right = _grid(rng, n_point, span)
    py = rng.integers(0, span, n_point).astype(float)
    got_left, got_right = contains_edges(rx, ry, left, right, py)
    assert got_left.tolist() == _held_by_some(rx, ry, left, py, "lower")
    assert got_right.tolist() == _held_by_some(rx, ry, right, py, "upper")


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31), st.integers(0, 90), st.integers(0, 90), st.sampled_from([4, 12, 60]))
def test_meets_segment_equals_testing_every_pair(
    seed: int, n_rect: int, n_seg: int, span: int
) -> None:
    rng = np.random.default_rng(seed)
    rx, ry = _grid(rng, n_rect, span), _grid(rng, n_rect, span)
    sx, sy = _grid(rng, n_seg, span), rng.integers(0, span, n_seg).astype(float)
    got = meets_segment(rx, ry, sx, sy)
    want = [
        any(
            min(rx[1][r], sx[1][s]) > max(rx[0][r], sx[0][s])
            and sx[1][s] > sx[0][s]
            and ry[0][r] < sy[s] < ry[1][r]
            for r in range(n_rect)
        )
        for s in range(n_seg)
    ]
    assert got.tolist() == want
    held = contains_point(rx, ry, sx[0], sy, "lower")  # the caller's own answer, reused
    assert meets_segment(rx, ry, sx, sy, start_held=held).tolist() == want


def test_by_hand() -> None:
    rx, ry = (
        (np.array([0.0, 10.0]), np.array([5.0, 20.0])),
        (np.array([0.0, 0.0]), np.array([5.0, 5.0])),
    )
    px, py = np.array([0.0, 5.0, 5.0, 12.0, 12.0]), np.array([1.0, 1.0, 5.0, 4.0, 0.0])
    assert contains_point(rx, ry, px, py, "lower").tolist() == [True, False, False, True, False]
    assert contains_point(rx, ry, px, py, "upper").tolist() == [False, True, False, True, False]
    seg = (np.array([5.0, 4.0, 20.0]), np.array([10.0, 6.0, 30.0]))
    assert meets_segment(rx, ry, seg, np.array([2.0, 2.0, 2.0])).tolist() == [False, True, False]
