"""Reading user text files: strict UTF-8, real line numbers, clear errors.

Every text reader of slopedist (calibration, labels, detections, box CSV, poses, timestamps,
scenarios; run records and ``run.json`` through :class:`CsvRows` and :func:`read_json`) goes
through these helpers, so a bad byte, an over-long line or CSV field or a broken quote ends in
one :class:`~slopedist.core.errors.InputFileError` naming the file and the line (1-based, counting
every physical line, comments and blank lines included), never a ``UnicodeDecodeError`` or
``_csv.Error``.

Rules: text is UTF-8 (a leading byte-order mark is allowed and dropped); lines end with ``\\n``
or ``\\r\\n``.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from slopedist.core.errors import InputFileError, MissingInputError

MAX_LINE_BYTES = 1 << 20
"""Longest accepted line, bytes (1 MiB); no line of a calibration, box, pose or record file
comes near it, and a longer one is a corrupt or hostile file (read no further than this)."""

_BOM = "\ufeff"


def _require_file(path: Path, what: str) -> None:
    if not path.is_file():
        raise MissingInputError(f"{what} not found: {path}")


def _not_utf8(path: Path, lineno: int, raw: bytes, exc: UnicodeDecodeError) -> InputFileError:
    byte = raw[exc.start : exc.start + 1].hex()
    return InputFileError(
        path,
        f"not UTF-8 text (byte 0x{byte}, byte {exc.start + 1} of the line); save it as UTF-8",
        line=lineno,
    )


def decoded_lines(path: str | Path, what: str) -> Iterator[str]:
    """Every physical line of ``path`` decoded as strict UTF-8, line ending included.

    Raises:
        MissingInputError: ``"{what} not found: {path}"``.
        InputFileError: a byte that is not UTF-8, or a line over :data:`MAX_LINE_BYTES`, naming
            its line.
    """
    path = Path(path)
    _require_file(path, what)
    with path.open("rb") as fh:
        for lineno, raw in enumerate(iter(lambda: fh.readline(MAX_LINE_BYTES + 1), b""), 1):
            if len(raw) > MAX_LINE_BYTES:
                raise InputFileError(
                    path,
                    f"line longer than {MAX_LINE_BYTES} bytes (not a text table?)",
                    line=lineno,
                )
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise _not_utf8(path, lineno, raw, exc) from None
            yield text[1:] if lineno == 1 and text.startswith(_BOM) else text


def numbered_lines(
    path: str | Path, what: str, comment: str | None = "#"
) -> Iterator[tuple[int, str]]:
    """``(line number, stripped line)`` of the non-blank lines of ``path``, skipping lines that
    start with ``comment`` (None: skip none). Line numbers count every physical line."""
    for lineno, raw in enumerate(decoded_lines(path, what), start=1):
        line = raw.strip()
        if line and not (comment is not None and line.startswith(comment)):
            yield lineno, line


def read_text(path: str | Path, what: str) -> str:
    """The whole of ``path`` as strict UTF-8 text (for JSON and TOML files).

    Raises:
        MissingInputError: no such file.
        InputFileError: a byte that is not UTF-8, naming its line.
    """
    return "".join(decoded_lines(path, what))


def read_json(path: str | Path, what: str) -> Any:
    """The JSON document in ``path`` (strict UTF-8; ``NaN``/``Infinity`` are not JSON and are
    refused, as :func:`slopedist.io.formatting.dumps_json` never writes them).

    Raises:
        MissingInputError: no such file.
        InputFileError: bad UTF-8 or invalid JSON, naming the line.
    """
    text = read_text(path, what)
    try:
        return json.loads(text, parse_constant=_no_constant)
    except json.JSONDecodeError as exc:
        raise InputFileError(path, f"not valid JSON ({exc.msg})", line=exc.lineno) from None
    except ValueError as exc:
        raise InputFileError(path, f"not valid JSON ({exc})") from None
    except RecursionError:
        raise InputFileError(path, "not valid JSON (nested too deeply)") from None


def parse_bool(text: str) -> bool:
    """``true/false``, ``yes/no``, ``on/off``, ``1/0`` (any case, surrounding spaces ignored).

    Raises:
        ValueError: any other text.
    """
    value = text.strip().lower()
    if value in ("true", "yes", "on", "1"):
        return True
    if value in ("false", "no", "off", "0"):
        return False
    raise ValueError(text)


def number_cell(
    text: str | None, path: str | Path, line: int, field: str, bound: float | None = None
) -> float:
    """A CSV cell as a number; empty (or absent) is NaN.

    Raises:
        InputFileError: the cell is not a number, or (with ``bound``) infinite or beyond
            ±``bound`` (naming file, line and field).
    """
    if text is None or not text.strip():
        return math.nan
    try:
        x = float(text)
    except ValueError:
        raise InputFileError(path, f"'{text}' is not a number", line=line, field=field) from None
    if bound is not None and abs(x) > bound:
        raise InputFileError(
            path, f"'{text}' is beyond ±{bound:g} (a corrupt record?)", line=line, field=field
        )
    return x


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not a JSON number")


def repeated_names(names: Sequence[str]) -> list[str]:
    """The non-empty names that occur more than once in ``names`` (a CSV header), sorted."""
    return sorted({n for n in names if n and names.count(n) > 1})


class CsvRows:
    """Rows of a CSV file with a header, as ``{column: text}`` dicts, with real line numbers.

    ``header`` holds the stripped column names; iterating yields ``(line, row)`` where ``line``
    is the physical line the row ends on. With ``strict`` a row of another field count than the
    header is an error; otherwise missing trailing fields are ``None``, and empty extra ones
    (a trailing comma) are dropped while a non-empty one is an error: an unquoted comma inside
    a value would shift every column after it.

    Raises (while reading):
        MissingInputError: no such file.
        InputFileError: a column named twice in the header; bad UTF-8, an over-long line or
            field (the ``csv`` module's field size limit), an unterminated quote or a NUL byte,
            a row with a value beyond the header's columns or (``strict``) of the wrong width,
            naming the line.
    """

    def __init__(self, path: str | Path, what: str, strict: bool = False) -> None:
        self.path = Path(path)
        self.strict = strict
        _require_file(self.path, what)
        self._lines = decoded_lines(self.path, what)
        self._reader = csv.reader(self._lines)
        first = self._next()
        self.header: list[str] = [h.strip() for h in first] if first is not None else []
        twice = repeated_names(self.header)
        if twice:
            raise InputFileError(
                self.path, f"column(s) {', '.join(twice)} named twice in the header", line=1
            )

    def _next(self) -> list[str] | None:
        try:
            return next(self._reader)
        except StopIteration:
            return None
        except csv.Error as exc:
            line = self._reader.line_num
            raise InputFileError(self.path, f"not a valid CSV row ({exc})", line=line) from None

    def __iter__(self) -> Iterator[tuple[int, dict[str, str | None]]]:
        while (fields := self._next()) is not None:
            if not any(f.strip() for f in fields):
                continue
            wide = len(fields) > len(self.header) and any(
                f.strip() for f in fields[len(self.header) :]
            )
            if wide or (self.strict and len(fields) != len(self.header)):
                raise InputFileError(
                    self.path,
                    f"row has {len(fields)} fields, the header has {len(self.header)}"
                    + (" (an unquoted comma in a value?)" if wide else ""),
                    line=self._reader.line_num,
                )
            row: dict[str, str | None] = dict.fromkeys(self.header)
            row.update(zip(self.header, fields))
            yield self._reader.line_num, row
