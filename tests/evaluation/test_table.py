"""Tables as data: text, Markdown and HTML renderings of one table."""

from __future__ import annotations

import math
import re

from slopedist.evaluation.table import (
    Table,
    best_marks,
    format_html,
    format_markdown,
    format_table,
    format_text,
)


def test_format_table() -> None:
    text = format_table(["a", "b"], [["x", 1.234], ["yy", float("nan")]])
    assert text.splitlines()[2].split() == ["x", "1.23"]
    assert text.splitlines()[3].split() == ["yy", "-"]


def test_best_marks_within_tolerance_and_direction() -> None:
    assert best_marks([2.0, 1.0, 1.004, math.nan]) == [False, True, True, False]
    assert best_marks([0.5, 0.9], larger_is_better=True) == [False, True]
    assert best_marks([math.nan, "x"]) == [False, False]


def test_best_marks_needs_two_values_to_compare() -> None:
    # one method's time or RMSE (the others not measured) is no "best": no bold
    assert best_marks([9.8]) == [False]
    assert best_marks([math.nan, 3.4, "-"]) == [False, False, False]
    assert best_marks([math.nan, 3.4, 5.0]) == [False, True, False]


def test_best_marks_none_when_every_value_ties() -> None:
    """A tie of every method is no win: the recall of one box source (the same for every
    method), or 0.000 where no method had a scored target, is not marked best."""
    assert best_marks([0.0, 0.0], larger_is_better=True) == [False, False]
    assert best_marks([0.945, 0.945, math.nan], larger_is_better=True) == [False] * 3
    assert best_marks([1.0, 1.004]) == [False, False]
    assert best_marks([1.0, 1.004, 2.0]) == [True, True, False]


TABLE = Table(
    "t1",
    "Title <1>",
    ["sequence", "n", "flat"],
    [["0000", 3, 1.23456], ["0001", 2, math.nan]],
    [[False, False, True], [False, False, False]],
    "a note\nsecond line",
    {2: ".3f"},
)


def test_one_table_three_renderings() -> None:
    text = format_text(TABLE).splitlines()
    assert text[0] == "Title <1>" and text[3].split() == ["0000", "3", "1.235*"]
    assert text[4].split() == ["0001", "2", "-"] and text[-1] == "second line"
    md = format_markdown(TABLE)
    assert "| 0000 | 3 | **1.235** |" in md and "|:---|---:|---:|" in md
    page = format_html(TABLE)
    assert "<h2>Title &lt;1&gt;</h2>" in page and "<td><b>1.235</b></td>" in page
    assert "a note<br>second line" in page
    assert TABLE.records()[1] == {"sequence": "0001", "n": 2, "flat": TABLE.rows[1][2]}


def _gfm_cells(row: str) -> list[str]:
    """The cells of a GitHub Markdown table row (split on the pipes that are not escaped)."""
    return [c.strip() for c in re.split(r"(?<!\\)\|", row.strip())[1:-1]]


def test_markdown_names_with_pipes_and_tags_keep_their_columns() -> None:
    """A sequence named ``a|b<i>`` was written as is: GitHub read two cells (every value moved
    under the next method's column) and an ``<i>`` tag."""
    table = Table("t", "Title", ["sequence", "flat", "ours"], [["a|b<i>*`", 9.5, 2.25]])
    md = format_markdown(table).splitlines()
    header, row = _gfm_cells(md[2]), _gfm_cells(md[4])
    assert header == ["sequence", "flat", "ours"]
    assert row == [r"a\|b&lt;i>\*\`", "9.50", "2.25"]
    assert "δ<1.25" in format_markdown(Table("t", "T", ["δ<1.25"], [[1.0]]))  # not a tag
