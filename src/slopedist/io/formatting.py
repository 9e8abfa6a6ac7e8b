"""The output layer: how every table and summary slopedist writes is formatted.

One place for the rules every output file follows:

- numbers in CSV cells: integers as integers, floats with 6 significant digits (``.6g``), NaN and
  ±inf as an empty field, booleans as ``0``/``1``; the times of a drive (``TIME_COLUMNS``) to the
  microsecond, so that Unix-epoch timestamps keep their fraction;
- CSV files: UTF-8 (a file-name byte that is not UTF-8 as ``\\xNN``:
  :data:`~slopedist.core.paths.PATH_BYTES_ERRORS`), LF line ends, a header row, flushed after
  every :meth:`CsvStreamWriter.write_rows` call (one frame), so a killed run leaves whole rows;
- JSON: strict (RFC 8259): NaN and ±inf become ``null``, numpy scalars and arrays become numbers
  and lists, paths become strings; ``-`` as the path writes to standard output.
"""

from __future__ import annotations

import csv
import dataclasses
import enum
import json
import math
import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from slopedist.core.paths import PATH_BYTES_ERRORS

STDOUT_PATH = "-"
"""The path that means standard output in ``--json -`` and friends."""


def format_cell(value: Any) -> Any:
    """One CSV cell: ints as ints, floats ``.6g`` (non-finite → ``""``), bools 0/1, else as is."""
    kind = type(value)
    if kind is float or kind is np.float64:  # most cells: a float64 formats as its float
        return f"{value:.6g}" if math.isfinite(value) else ""
    if kind is str:
        return value
    if value is None:
        return ""
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        x = float(value)
        return f"{x:.6g}" if math.isfinite(x) else ""
    if isinstance(value, enum.Enum):
        return value.value
    return value


def exact_cell(value: Any) -> Any:
    """:func:`format_cell`, but a float that ``.6g`` would round is written in full (the
    shortest text that reads back as the same number): for values a file must keep exactly,
    such as box coordinates. A value that is a float32 (a detector's score, 0.8999999761581421)
    is written as that float32's shortest text (0.9), which reads back as the same float32."""
    text = format_cell(value)
    if isinstance(value, (float, np.floating)) and text and float(text) != float(value):
        single = np.float32(value)
        return repr(float(value)) if float(single) != float(value) else str(single)
    return text


TIME_COLUMNS = frozenset(
    ("timestamp_s", "first_s", "last_s", "min_distance_s", "first_event_s", "min_distance_bound_s")
)
"""Columns holding a time of the drive (seconds, often since the Unix epoch): written by
:func:`format_time_cell`, since ``.6g`` writes 1700000000.067 as 1.7e+09 and every frame of a
drive would get the same time."""


def format_time_cell(value: Any) -> Any:
    """A time in seconds to the microsecond, trailing zeros dropped (``1700000000.066667``,
    ``3.8``); a value that is not a float as :func:`format_cell` writes it."""
    if not isinstance(value, (float, np.floating)) or not math.isfinite(value):
        return format_cell(value)
    text = f"{float(value):.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("", "-0") else text


def _cell(key: str, value: Any) -> Any:
    """The CSV cell of column ``key``: :func:`format_time_cell` for ``TIME_COLUMNS``."""
    return format_time_cell(value) if key in TIME_COLUMNS else format_cell(value)


class TextSink(Protocol):
    """Where a :class:`CsvStreamWriter` writes: a text file, standard output, or a file that
    keeps whole batches only (:class:`~slopedist.io.outputs.WholeRowsFile`)."""

    def write(self, text: str, /) -> int: ...

    def flush(self) -> None: ...

    def close(self) -> None: ...


class CsvStreamWriter:
    """A CSV table written as it is produced: LF line ends, flushed after each batch of rows.

    The header is ``fields`` when given, otherwise the keys of the first row written (so that
    method-specific extra columns are included). Keys a row lacks are written empty; a key not in
    the header is an error of the caller (``ValueError``).
    """

    def __init__(self, stream: TextSink, fields: Sequence[str] | None = None) -> None:
        self._stream = stream
        self._writer: Any = None  # a csv.writer once the header is known
        self._fields: list[str] = []
        self._field_set: frozenset[str] = frozenset()
        self._owned = False
        if fields is not None:
            self._start(fields)

    @classmethod
    def open(cls, path: str | Path, fields: Sequence[str] | None = None) -> CsvStreamWriter:
        """Create (truncate) ``path`` as UTF-8 and return a writer that closes it."""
        fh = Path(path).open(  # noqa: SIM115 (closed by close())
            "w", newline="", encoding="utf-8", errors=PATH_BYTES_ERRORS
        )
        writer = cls(fh, fields)
        writer._owned = True
        return writer

    def _start(self, fields: Sequence[str]) -> None:
        self._fields = list(fields)
        self._field_set = frozenset(self._fields)
        self._writer = csv.writer(self._stream, lineterminator="\n")
        self._writer.writerow(self._fields)
        self._stream.flush()

    @property
    def fields(self) -> list[str] | None:
        """The header, once known."""
        return None if self._writer is None else list(self._fields)

    def write_rows(self, rows: Iterable[Mapping[str, Any]]) -> int:
        """Write ``rows`` (formatted with :func:`format_cell`, times with
        :func:`format_time_cell`), then flush; returns the count."""
        n = 0
        for row in rows:
            if self._writer is None:
                self._start(list(row))
            extra = row.keys() - self._field_set
            if extra:
                names = ", ".join(repr(k) for k in extra)
                raise ValueError(f"dict contains fields not in fieldnames: {names}")
            # a missing key is None, an empty cell (format_cell)
            self._writer.writerow([_cell(k, row.get(k)) for k in self._fields])
            n += 1
        self._stream.flush()
        return n

    def write_header(self, fields: Sequence[str]) -> None:
        """Write ``fields`` as the header now if none is written yet (an empty table keeps its
        columns); no effect otherwise."""
        if self._writer is None:
            self._start(fields)

    def write_row(self, row: Mapping[str, Any]) -> None:
        """Write one row and flush."""
        self.write_rows((row,))

    def write_values(self, rows: Iterable[Sequence[Any]]) -> int:
        """Write positional rows (values in header order; the header must be known), then
        flush; returns the count.

        Raises:
            ValueError: the header is not known yet, or a row has another length.
        """
        fields = self.fields
        if fields is None:
            raise ValueError("positional rows need the header: give fields when opening")
        records = []
        for row in rows:
            if len(row) != len(fields):
                raise ValueError(f"row of {len(row)} values for {len(fields)} columns")
            records.append(dict(zip(fields, row)))
        return self.write_rows(records)

    def close(self) -> None:
        """Flush, and close the file if this writer opened it."""
        if self._owned:
            self._stream.close()
        else:
            self._stream.flush()

    def __enter__(self) -> CsvStreamWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_csv(
    path: str | Path, rows: Iterable[Mapping[str, Any]], fields: Sequence[str] | None = None
) -> Path:
    """Write a whole table at once (same format as :class:`CsvStreamWriter`); returns ``path``."""
    path = Path(path)
    with CsvStreamWriter.open(path, fields) as writer:
        writer.write_rows(rows)
    return path


def json_ready(value: Any) -> Any:
    """``value`` with every non-finite float as None and numpy/paths/enums/dataclasses as plain
    JSON types, recursively (dict keys become strings)."""
    if value is None or isinstance(value, (str, bool)):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        x = float(value)
        return x if math.isfinite(x) else None
    if isinstance(value, np.ndarray):
        return json_ready(value.tolist())
    if isinstance(value, enum.Enum):
        return json_ready(value.value)
    if isinstance(value, Path):
        return str(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return json_ready(dataclasses.asdict(value))
    if isinstance(value, Mapping):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [json_ready(v) for v in value]
    raise TypeError(f"cannot write a {type(value).__name__} as JSON")


def dumps_json(value: Any, indent: int | None = 2) -> str:
    """Strict JSON text of ``value`` (see :func:`json_ready`), ending with a newline."""
    return json.dumps(json_ready(value), indent=indent, allow_nan=False) + "\n"


def write_json(path: str | Path, value: Any, indent: int | None = 2) -> str:
    """Write ``value`` as strict JSON to ``path`` (``-``: standard output); returns the text."""
    text = dumps_json(value, indent)
    if str(path) == STDOUT_PATH:
        sys.stdout.write(text)
        sys.stdout.flush()
    else:
        Path(path).write_text(text, encoding="utf-8")
    return text
