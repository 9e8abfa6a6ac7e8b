"""The vehicle size a detector may give with each box: height, width and length, and its σ.

A monocular 3D detector (or a LiDAR one, or a fine-grained class) knows how big the vehicle in
a box is. The box table carries it as the optional one-dimensional columns
:data:`SIZE_COLUMNS` (metres, NaN where unknown) and :data:`SIZE_SIGMA_COLUMN` (the size's 1σ
in percent of each dimension, one value for all three; NaN = :data:`DEFAULT_SIZE_SIGMA_PCT`).
``ours`` uses a box's known dimensions in place of its class prior's
(:class:`~slopedist.estimators.ours.class_table.ClassTable`); a dimension that is unknown
keeps the class prior's value and spread.

Convention: the dimensions of the vehicle's 3D box as KITTI labels them: height (road to roof),
width (side to side, without mirrors), length (front to back), metres.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import InputFileError
from slopedist.core.textfiles import number_cell

SIZE_COLUMNS = ("height_m", "width_m", "length_m")
"""Box columns of the vehicle's height, width and length, metres (NaN = unknown)."""
SIZE_SIGMA_COLUMN = "size_sigma_pct"
"""Box column of the sizes' 1σ, percent of each dimension (NaN = the default)."""

MIN_SIZE_M = 0.3
"""The smallest dimension accepted, metres (below it a value is no road vehicle's size, or is
in other units)."""
MAX_SIZE_M = 30.0
"""The largest dimension accepted, metres (an articulated bus is 18 m, a road train 25 m)."""
MAX_SIZE_SIGMA_PCT = 100.0
"""The largest size σ accepted, percent (beyond it the size says nothing: leave it out)."""

DEFAULT_SIZE_SIGMA_PCT = 10.0
"""The σ of a size given without one, percent of each dimension: the conservative end of
what monocular 3D detectors reach on KITTI cars (dimension errors of 5–10 %)."""


def size_value(path: str | Path, line: int, field: str, token: str) -> float:
    """A size field as written: metres in [:data:`MIN_SIZE_M`, :data:`MAX_SIZE_M`]; empty or
    ``nan`` = unknown (NaN).

    Raises:
        InputFileError: not a number, infinite, or outside the accepted range (naming the file,
            line and field).
    """
    value = _number(path, line, field, token)
    if math.isnan(value) or MIN_SIZE_M <= value <= MAX_SIZE_M:
        return value
    raise InputFileError(
        path,
        f"a vehicle dimension must be {MIN_SIZE_M:g}–{MAX_SIZE_M:g} m (or empty = unknown), "
        f"got '{token.strip()}'",
        line=line,
        field=field,
    )


def size_sigma_value(path: str | Path, line: int, field: str, token: str) -> float:
    """A size σ field as written: percent in (0, :data:`MAX_SIZE_SIGMA_PCT`]; empty or ``nan``
    = the default (NaN).

    Raises:
        InputFileError: not a number, or not in the accepted range.
    """
    value = _number(path, line, field, token)
    if math.isnan(value) or 0.0 < value <= MAX_SIZE_SIGMA_PCT:
        return value
    raise InputFileError(
        path,
        f"the size σ must be a percentage in (0, {MAX_SIZE_SIGMA_PCT:g}] (or empty = "
        f"{DEFAULT_SIZE_SIGMA_PCT:g} %), got '{token.strip()}'",
        line=line,
        field=field,
    )


def _number(path: str | Path, line: int, field: str, token: str) -> float:
    """A float field (:func:`~slopedist.core.textfiles.number_cell`: NaN when empty);
    infinities refused."""
    value = number_cell(token.strip(), path, line, field)
    if math.isinf(value):
        raise InputFileError(
            path, f"'{token.strip()}' is not a finite number", line=line, field=field
        )
    return value


def has_sizes(extra: dict[str, NDArray]) -> bool:
    """Whether a box table's extra columns carry any vehicle size."""
    return any(k in extra for k in SIZE_COLUMNS)


def size_arrays(
    extra: dict[str, NDArray], rows: NDArray[np.intp]
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """The sizes of the boxes ``rows`` of a table with the extra columns ``extra``: ``(n, 3)``
    height, width, length (m, NaN = unknown) and ``(n, 3)`` their 1σ (m); None when the table
    has no size column or none of these boxes has a size."""
    if not has_sizes(extra):
        return None
    n = rows.shape[0]
    dims = np.full((n, 3), np.nan)
    for k, name in enumerate(SIZE_COLUMNS):
        if name in extra:
            dims[:, k] = np.asarray(extra[name], dtype=float)[rows]
    if not np.isfinite(dims).any():
        return None
    pct = np.full(n, np.nan)
    if SIZE_SIGMA_COLUMN in extra:
        pct = np.asarray(extra[SIZE_SIGMA_COLUMN], dtype=float)[rows]
    pct = np.where(np.isfinite(pct), pct, DEFAULT_SIZE_SIGMA_PCT)
    return dims, dims * (pct[:, None] / 100.0)


def without_sizes(extra: dict[str, NDArray]) -> dict[str, NDArray]:
    """``extra`` without the size columns (:data:`SIZE_COLUMNS`, :data:`SIZE_SIGMA_COLUMN`)."""
    drop = {*SIZE_COLUMNS, SIZE_SIGMA_COLUMN}
    return {k: v for k, v in extra.items() if k not in drop}
