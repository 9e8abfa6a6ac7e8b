"""The typed TOML reader of scenario files: every error names the file, the line and the field."""

from __future__ import annotations

import pytest

from slopedist.core.errors import InputFileError
from slopedist.synthetic.scenario_reader import TableReader, field_lines, positive

TEXT = "a = 1\n[[t]]\nx = 1\n[[t]]\nx = 2\n[r.c]\ny = 3\n"


def test_field_lines_counts_arrays_of_tables() -> None:
    lines = field_lines(TEXT)
    assert lines == {"a": 1, "t[0]": 2, "t[0].x": 3, "t[1]": 4, "t[1].x": 5, "r.c": 6, "r.c.y": 7}


def test_a_missing_field_is_reported_at_its_table() -> None:
    r = TableReader("f.toml", field_lines(TEXT))
    err = r.fail("r.c.z", "required field is missing")
    assert (err.line, err.field) == (6, "r.c.z")
    assert "f.toml" in str(err)


@pytest.mark.parametrize(
    "value,words",
    [(True, "the boolean true"), ("1", "the string '1'"), (float("inf"), "finite"), (-2.0, "> 0")],
)
def test_numbers_are_checked(value: object, words: str) -> None:
    r = TableReader("f.toml", field_lines(TEXT))
    with pytest.raises(InputFileError, match=words) as info:
        r.number({"y": value}, "y", "r.c", None, positive, "> 0")
    assert (info.value.line, info.value.field) == (7, "r.c.y")


def test_unknown_keys_and_defaults() -> None:
    r = TableReader("f.toml", field_lines(TEXT))
    assert r.integer({}, "n", "r.c", 3) == 3
    with pytest.raises(InputFileError, match="unknown field 'w'; expected one of y"):
        r.check_keys({"w": 1}, "r.c", ("y",))
