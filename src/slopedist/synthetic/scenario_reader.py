"""Typed access to parsed TOML tables whose every error names the file, the line and the field
(``road.curve[1].radius_m``), for the scenario files (:mod:`~slopedist.synthetic.
scenario_file`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from typing import Any

from slopedist.core.errors import ConfigurationError, InputFileError

_HEADER = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.\-\s\"]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"^\s*([A-Za-z0-9_\-]+|\"[^\"]*\")\s*=")


def field_lines(text: str) -> dict[str, int]:
    """Map dotted field paths (``road.curve[1].radius_m``, ``target[0]``) to 1-based lines.

    A best-effort scan of the file's table headers and ``key =`` lines (enough for messages;
    inline tables are located by their key).
    """
    lines: dict[str, int] = {}
    counts: dict[str, int] = {}
    prefix = ""
    for lineno, raw in enumerate(text.splitlines(), start=1):
        m = _HEADER.match(raw)
        if m and not raw.lstrip().startswith("#"):
            name = m.group(2).replace(" ", "").replace('"', "")
            if m.group(1) == "[[":
                i = counts.get(name, 0)
                counts[name] = i + 1
                prefix = f"{name}[{i}]"
            else:
                prefix = name
            lines.setdefault(prefix, lineno)
            continue
        k = _KEY.match(raw)
        if k:
            key = k.group(1).strip('"')
            lines.setdefault(f"{prefix}.{key}" if prefix else key, lineno)
    return lines


MAX_MAGNITUDE = 1e6
"""Largest magnitude of any number in a scenario (metres, km/h, pixels, ...): a road of
1000 km is more than any scenario needs, and larger values only overflow the renderer."""


class TableReader:
    """Typed access to a parsed TOML table with errors naming file, line and field."""

    def __init__(self, path: str, lines: dict[str, int]) -> None:
        self.path = path
        self.lines = lines

    def fail(self, field: str, message: str) -> InputFileError:
        line = self.lines.get(field)
        if line is None:  # fall back to the enclosing table
            parent = field.rsplit(".", 1)[0] if "." in field else ""
            line = self.lines.get(parent)
        return InputFileError(self.path, message, line=line, field=field)

    def table(
        self, data: dict[str, Any], key: str, where: str, allowed: tuple[str, ...]
    ) -> dict[str, Any]:
        value = data.get(key, {})
        field = f"{where}.{key}" if where else key
        if not isinstance(value, dict):
            raise self.fail(field, f"must be a table ([{field}]), got {kind(value)}")
        self.check_keys(value, field, allowed)
        return value

    def array_of_tables(
        self, data: dict[str, Any], key: str, where: str, allowed: tuple[str, ...]
    ) -> list[dict[str, Any]]:
        value = data.get(key, [])
        field = f"{where}.{key}" if where else key
        if isinstance(value, dict):
            value = [value]
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.fail(field, f"must be an array of tables ([[{field}]]), got {kind(value)}")
        for i, item in enumerate(value):
            self.check_keys(item, f"{field}[{i}]", allowed)
        return value

    def check_keys(self, table: dict[str, Any], where: str, allowed: tuple[str, ...]) -> None:
        for key in table:
            if key not in allowed:
                field = f"{where}.{key}" if where else key
                raise self.fail(
                    field, f"unknown field '{key}'; expected one of {', '.join(allowed)}"
                )

    def _value(self, table: dict[str, Any], key: str, where: str, default: Any) -> tuple[str, Any]:
        """``(field path, value)``; a missing field takes ``default`` (None = required)."""
        field = f"{where}.{key}" if where else key
        if key not in table:
            if default is None:
                raise self.fail(field, "required field is missing")
            return field, default
        return field, table[key]

    def number(
        self,
        table: dict[str, Any],
        key: str,
        where: str,
        default: float | None = None,
        check: Callable[[float], bool] | None = None,
        expect: str = "",
    ) -> float:
        field, value = self._value(table, key, where, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(field, f"must be a number, got {kind(value)}")
        value = float(value)
        if not (math.isfinite(value) and abs(value) <= MAX_MAGNITUDE):
            raise self.fail(field, f"must be finite and within ±{MAX_MAGNITUDE:g}, got {value:g}")
        if check is not None and not check(value):
            raise self.fail(field, f"must be {expect}, got {value:g}")
        return value

    def integer(
        self,
        table: dict[str, Any],
        key: str,
        where: str,
        default: int | None = None,
        check: Callable[[int], bool] | None = None,
        expect: str = "",
    ) -> int:
        field, value = self._value(table, key, where, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(field, f"must be an integer, got {kind(value)}")
        if check is not None and not check(value):
            raise self.fail(field, f"must be {expect}, got {value}")
        return value

    def string(self, table: dict[str, Any], key: str, where: str, default: str) -> str:
        field, value = self._value(table, key, where, default)
        if not isinstance(value, str):
            raise self.fail(field, f"must be a string, got {kind(value)}")
        return value

    def boolean(self, table: dict[str, Any], key: str, where: str, default: bool) -> bool:
        field, value = self._value(table, key, where, default)
        if not isinstance(value, bool):
            raise self.fail(field, f"must be true or false, got {kind(value)}")
        return value

    def numbers(
        self, table: dict[str, Any], key: str, where: str, n: int, default: tuple[float, ...]
    ) -> tuple[float, ...]:
        field, value = self._value(table, key, where, list(default))
        if (
            not isinstance(value, list)
            or len(value) != n
            or not all(
                isinstance(v, (int, float))
                and not isinstance(v, bool)
                and math.isfinite(v)
                and abs(v) <= MAX_MAGNITUDE
                for v in value
            )
        ):
            raise self.fail(field, f"must be a list of {n} finite numbers, got {value!r}")
        return tuple(float(v) for v in value)

    def build(self, field: str, factory: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """Call a constructor; its ConfigurationError becomes an error naming ``field``."""
        try:
            return factory(*args, **kwargs)
        except ConfigurationError as exc:
            raise self.fail(field, str(exc)) from None


def kind(value: Any) -> str:
    """How a wrong value is named in a message (``the string 'x'``, ``a table``, ...)."""
    if isinstance(value, bool):
        return f"the boolean {str(value).lower()}"
    if isinstance(value, str):
        return f"the string {value!r}"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "an array"
    return f"{type(value).__name__} {value!r}"


def positive(x: float) -> bool:
    """Check for :meth:`TableReader.number`: ``x > 0``."""
    return x > 0


def non_negative(x: float) -> bool:
    """Check for :meth:`TableReader.number`: ``x ≥ 0``."""
    return x >= 0
