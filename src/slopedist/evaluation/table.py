"""Tables as data, rendered as plain text, GitHub Markdown or HTML.

A :class:`Table` is built once (headers, rows of values, which cells are the best, a note) by
the code that owns the numbers (:mod:`slopedist.evaluation.accuracy_tables`, the demo, the report)
and
rendered here: as text by ``slopedist eval`` and ``slopedist demo``, as Markdown and HTML by
``slopedist report``; its rows go to CSV through :mod:`slopedist.io.formatting`. Floats are shown
with 2 decimals unless the table gives a column format; NaN and ±inf are shown as ``-``.
"""

from __future__ import annotations

import html
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

BEST_TOLERANCE = 5e-3
"""Values within this of the best one are marked best too (they print the same at 2 decimals)."""


@dataclass
class Table:
    """A table: a file key, a title, headers, rows of values, best cells, a note.

    Attributes:
        key: file stem of the table's CSV (``table1_rmse``) and its HTML anchor.
        title: one line shown above it.
        headers: column names.
        rows: values (numbers stay numbers; formatting happens when rendering).
        bold: per cell, whether it is the best of its group (empty = none).
        note: lines shown below it.
        formats: per column index, the ``format`` spec of its floats (default ``.2f``).
    """

    key: str
    title: str
    headers: list[str]
    rows: list[list[Any]]
    bold: list[list[bool]] = field(default_factory=list)
    note: str = ""
    formats: dict[int, str] = field(default_factory=dict)

    def cell(self, i: int, j: int) -> str:
        """The text of cell ``(i, j)``."""
        v = self.rows[i][j]
        if isinstance(v, (float, np.floating)):
            return "-" if not math.isfinite(v) else format(float(v), self.formats.get(j, ".2f"))
        return str(v)

    def is_bold(self, i: int, j: int) -> bool:
        """Whether cell ``(i, j)`` is marked best."""
        return bool(self.bold) and self.bold[i][j]

    def records(self) -> list[dict[str, Any]]:
        """The rows as ``{header: value}`` records (raw values, for CSV)."""
        return [dict(zip(self.headers, row)) for row in self.rows]


def best_marks(values: Sequence[Any], larger_is_better: bool = False) -> list[bool]:
    """Which of ``values`` are the best finite float (within :data:`BEST_TOLERANCE`); none
    when fewer than two are finite floats (nothing was compared: one method's only value in
    bold would read as a win) or when every finite value ties with the best (no method did
    better than another: the recall of one box source, a metric no method scored)."""
    arr = np.array(
        [v if isinstance(v, float) and math.isfinite(v) else np.nan for v in values], dtype=float
    )
    if np.count_nonzero(np.isfinite(arr)) < 2:
        return [False] * len(values)
    best = np.nanmax(arr) if larger_is_better else np.nanmin(arr)
    marks = [bool(np.isfinite(a) and abs(a - best) < BEST_TOLERANCE) for a in arr]
    if sum(marks) == np.count_nonzero(np.isfinite(arr)):
        return [False] * len(values)
    return marks


def format_table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """Plain-text grid with right-aligned columns (floats to 2 decimals, NaN as ``-``)."""

    def cell(v: Any) -> str:
        if isinstance(v, float):
            return "-" if not math.isfinite(v) else f"{v:.2f}"
        return str(v)

    cells = [[cell(v) for v in r] for r in rows]
    widths = [max(len(h), *(len(r[i]) for r in cells)) for i, h in enumerate(headers)]
    line = "  ".join(h.rjust(w) for h, w in zip(headers, widths))
    body = ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in cells]
    return "\n".join([line, "-" * len(line), *body])


def format_text(table: Table) -> str:
    """Plain text: the title, the grid (best values marked with ``*``), the note."""
    rows = [
        [table.cell(i, j) + ("*" if table.is_bold(i, j) else "") for j in range(len(table.headers))]
        for i in range(len(table.rows))
    ]
    text = table.title + "\n" + format_table(table.headers, rows)
    return text + ("\n" + table.note if table.note else "")


def format_texts(tables: Sequence[Table]) -> str:
    """Several tables as text, separated by blank lines."""
    return "\n\n".join(format_text(t) for t in tables)


_TAG_START = re.compile(r"<(?=[A-Za-z/!?])")
"""A ``<`` that Markdown would read as the start of an HTML tag (``δ<1.25`` is not one)."""


def markdown_text(text: str) -> str:
    """``text`` as it reads in Markdown: a ``<`` that would open an HTML tag as ``&lt;`` and a
    line break as a space."""
    return " ".join(_TAG_START.sub("&lt;", text).splitlines())


def markdown_cell(text: str) -> str:
    """``text`` as one cell of a Markdown table (:func:`markdown_text`, with ``\\``, ``|``,
    ``*`` and backticks escaped: a ``|`` in a name would split its row into one more cell and
    move every value after it under the next column)."""
    for c in "\\|*`":
        text = text.replace(c, "\\" + c)
    return markdown_text(text)


def format_markdown(table: Table) -> str:
    """GitHub Markdown, best values in bold; text from the data (names) escaped
    (:func:`markdown_cell`)."""

    def md(i: int, j: int) -> str:
        c = markdown_cell(table.cell(i, j))
        return f"**{c}**" if table.is_bold(i, j) else c

    lines = [
        f"### {markdown_text(table.title)}",
        "",
        "| " + " | ".join(markdown_cell(h) for h in table.headers) + " |",
        "|" + "|".join("---:" if j else ":---" for j in range(len(table.headers))) + "|",
    ]
    lines += [
        "| " + " | ".join(md(i, j) for j in range(len(table.headers))) + " |"
        for i in range(len(table.rows))
    ]
    if table.note:
        lines += ["", *(f"{markdown_text(n)}  " for n in table.note.splitlines())]
    return "\n".join(lines)


def html_text(text: str) -> str:
    """``text`` as HTML: escaped, its code spans (between backticks) as ``<code>`` elements
    (an unpaired backtick stays as it is), so no Markdown syntax shows on the page."""
    parts = text.split("`")
    if len(parts) % 2 == 0:  # an odd number of backticks: the last one opens nothing
        parts[-2:] = ["`".join(parts[-2:])]
    return "".join(
        f"<code>{html.escape(p)}</code>" if k % 2 else html.escape(p) for k, p in enumerate(parts)
    )


def plain_text(text: str) -> str:
    """``text`` without the backticks of its code spans (for an ``alt`` or ``title``)."""
    parts = text.split("`")
    return text if len(parts) % 2 == 0 else "".join(parts)


def format_html(table: Table) -> str:
    """An HTML ``<section>`` with the title, the ``<table>`` (best values in ``<b>``), the note."""

    def td(i: int, j: int) -> str:
        c = html.escape(table.cell(i, j))
        return f"<td><b>{c}</b></td>" if table.is_bold(i, j) else f"<td>{c}</td>"

    head = "".join(f"<th>{html.escape(h)}</th>" for h in table.headers)
    body = "\n".join(
        "<tr>" + "".join(td(i, j) for j in range(len(table.headers))) + "</tr>"
        for i in range(len(table.rows))
    )
    note = (
        ('<p class="note">' + "<br>".join(html_text(n) for n in table.note.splitlines()) + "</p>")
        if table.note
        else ""
    )
    return (
        f'<section id="{table.key}"><h2>{html_text(table.title)}</h2>\n'
        f"<table><thead><tr>{head}</tr></thead><tbody>\n{body}\n</tbody></table>{note}"
        f"</section>"
    )
