"""The output layer: cell formatting, LF CSV streaming, strict JSON."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from slopedist.io.formatting import CsvStreamWriter, dumps_json, format_cell, write_csv, write_json


def test_format_cell_hand_values() -> None:
    assert format_cell(3) == 3
    assert format_cell(np.int64(7)) == 7
    assert format_cell(True) == 1
    assert format_cell(1.0 / 3.0) == "0.333333"
    assert format_cell(np.float32(2.5)) == "2.5"
    assert format_cell(math.nan) == ""
    assert format_cell(-math.inf) == ""
    assert format_cell(None) == ""
    assert format_cell("car") == "car"


def test_csv_stream_writer_lf_header_from_first_row_and_flush(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    w = CsvStreamWriter.open(path)
    w.write_rows([{"a": 1, "b": math.nan}, {"a": 2.0, "b": "x"}])
    # flushed: readable before close
    assert path.read_bytes() == b"a,b\n1,\n2,x\n"
    w.close()
    assert b"\r" not in path.read_bytes()


def test_csv_stream_writer_fixed_fields_missing_key_empty() -> None:
    buf = io.StringIO()
    w = CsvStreamWriter(buf, fields=("a", "b"))
    w.write_row({"a": 1})
    assert buf.getvalue() == "a,b\n1,\n"
    with pytest.raises(ValueError):
        w.write_row({"c": 1})


def test_csv_stream_writer_quotes_text_and_leaves_none_empty() -> None:
    buf = io.StringIO()
    w = CsvStreamWriter(buf, fields=("a", "b", "c"))
    w.write_rows([{"a": 'x, "y"', "b": None, "c": math.nan}, {"c": True}])
    assert buf.getvalue() == 'a,b,c\n"x, ""y""",,\n,,1\n'


def test_write_header_only_before_the_first_row() -> None:
    empty = io.StringIO()
    CsvStreamWriter(empty).write_header(("a", "b"))
    assert empty.getvalue() == "a,b\n"
    started = io.StringIO()
    w = CsvStreamWriter(started)
    w.write_row({"x": 1})
    w.write_header(("a", "b"))
    assert started.getvalue() == "x\n1\n"


def test_csv_stream_writer_positional_rows() -> None:
    buf = io.StringIO()
    w = CsvStreamWriter(buf, fields=("a", "b"))
    assert w.write_values([[1, 0.5], [np.int64(2), math.inf]]) == 2
    assert buf.getvalue() == "a,b\n1,0.5\n2,\n"
    with pytest.raises(ValueError, match="2 columns"):
        w.write_values([[1]])
    with pytest.raises(ValueError, match="header"):
        CsvStreamWriter(io.StringIO()).write_values([[1]])


def test_write_csv_whole_table(tmp_path: Path) -> None:
    path = write_csv(tmp_path / "w.csv", [], fields=("x",))
    assert path.read_text() == "x\n"


def test_json_strict_nan_inf_numpy(tmp_path: Path) -> None:
    value = {"a": math.nan, "b": [np.float64(math.inf), np.int32(3)], 4: np.array([1.5, np.nan])}
    text = write_json(tmp_path / "o.json", value)
    parsed = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-strict token {c}"))
    assert parsed == {"a": None, "b": [None, 3], "4": [1.5, None]}


def test_json_dash_writes_stdout(capsys: pytest.CaptureFixture[str]) -> None:
    write_json("-", {"x": 1.0}, indent=None)
    assert capsys.readouterr().out == '{"x": 1.0}\n'


@given(
    st.recursive(
        st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
        lambda children: (
            st.lists(children, max_size=4)
            | st.dictionaries(st.text(max_size=3), children, max_size=4)
        ),
        max_leaves=20,
    )
)
def test_dumps_json_always_strict(value: object) -> None:
    json.loads(dumps_json(value), parse_constant=lambda c: pytest.fail(c))


def test_exact_cell_keeps_what_6_digits_would_round() -> None:
    from slopedist.io.formatting import exact_cell

    assert exact_cell(1234.5678) == "1234.5678" and exact_cell(0.1234567891) == "0.1234567891"
    assert exact_cell(100.0) == "100" and exact_cell(0.25) == "0.25"  # as format_cell
    assert exact_cell(float(np.float32(0.9))) == "0.9"  # a detector's float32 score
    assert exact_cell(float("nan")) == "" and exact_cell(3) == 3 and exact_cell("Car") == "Car"


def test_times_of_the_drive_keep_their_microseconds(tmp_path: Path) -> None:
    # .6g wrote every Unix-epoch timestamp of a drive as 1.7e+09
    path = write_csv(
        tmp_path / "t.csv",
        [{"timestamp_s": 1700000000.0666667, "first_s": 3.8, "distance_m": 12.3456789}],
    )
    assert path.read_text().splitlines()[1] == "1700000000.066667,3.8,12.3457"
    stream = io.StringIO()
    CsvStreamWriter(stream).write_row({"timestamp_s": 0.0, "last_s": float("nan")})
    assert stream.getvalue().splitlines()[1] == "0,"
