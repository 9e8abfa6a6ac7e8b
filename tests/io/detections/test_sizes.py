"""The vehicle-size columns of box files: read as written, unknown where empty, clear errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from slopedist.core.errors import InputFileError
from slopedist.io.detections import read_box_csv, read_box_file, read_pointrcnn
from slopedist.io.detections.sizes import (
    DEFAULT_SIZE_SIGMA_PCT,
    SIZE_COLUMNS,
    size_arrays,
    without_sizes,
)
from slopedist.io.detections.writers import write_box_csv
from slopedist.io.kitti.tracking import BoxSource, load_sequence

TMP = settings(suppress_health_check=[HealthCheck.function_scoped_fixture], max_examples=40)
dimension = st.one_of(st.none(), st.floats(0.3, 30.0, allow_nan=False))
sigma = st.one_of(st.none(), st.floats(0.01, 100.0, allow_nan=False))
size_row = st.tuples(dimension, dimension, dimension, sigma)

HEADER = "frame,left,top,right,bottom,height_m,width_m,length_m,size_sigma_pct"


def _cell(value: float | None) -> str:
    return "" if value is None else repr(value)


def _as_float(value: float | None) -> float:
    return math.nan if value is None else value


@TMP
@given(rows=st.lists(size_row, min_size=1, max_size=15))
def test_csv_sizes_are_read_as_written_and_empty_is_unknown(
    tmp_path: Path, rows: list[tuple[float | None, ...]]
) -> None:
    path = tmp_path / "boxes.csv"
    lines = [HEADER] + [f"0,10,20,60,50,{','.join(_cell(v) for v in r)}" for r in rows]
    path.write_text("\n".join(lines) + "\n")
    table = read_box_csv(path)
    for k, name in enumerate((*SIZE_COLUMNS, "size_sigma_pct")):
        expected = np.array([_as_float(r[k]) for r in rows])
        np.testing.assert_array_equal(table.extra[name], expected)
    # the σ in metres: percent of each known dimension, the default where none is given
    got = size_arrays(table.extra, np.arange(len(rows)))
    if got is None:
        assert all(r[:3] == (None, None, None) for r in rows)
        return
    dims, sigma_m = got
    for i, r in enumerate(rows):
        pct = DEFAULT_SIZE_SIGMA_PCT if r[3] is None else r[3]
        for k in range(3):
            assert (math.isnan(dims[i, k]) and r[k] is None) or dims[i, k] == r[k]
            if r[k] is not None:
                assert sigma_m[i, k] == pytest.approx(r[k] * pct / 100.0)


@TMP
@given(rows=st.lists(size_row, min_size=1, max_size=10))
def test_csv_sizes_round_trip_through_the_writer(
    tmp_path: Path, rows: list[tuple[float | None, ...]]
) -> None:
    path = tmp_path / "boxes.csv"
    lines = [HEADER]
    lines += [f"{i},10,20,60,50,{','.join(_cell(v) for v in r)}" for i, r in enumerate(rows)]
    path.write_text("\n".join(lines) + "\n")
    table = read_box_csv(path)
    again = read_box_csv(write_box_csv(table, tmp_path / "again.csv"))
    for name in (*SIZE_COLUMNS, "size_sigma_pct"):
        np.testing.assert_array_equal(again.extra[name], table.extra[name])


def test_a_file_without_size_columns_has_none() -> None:
    assert size_arrays({"z": np.ones(2)}, np.arange(2)) is None
    assert size_arrays({"height_m": np.full(2, np.nan)}, np.arange(2)) is None
    assert without_sizes({"height_m": np.ones(1), "z": np.ones(1)}).keys() == {"z"}


def test_a_size_column_alone_is_enough() -> None:
    got = size_arrays({"height_m": np.array([2.5, np.nan])}, np.arange(2))
    assert got is not None
    dims, sigma_m = got
    np.testing.assert_array_equal(dims[:, 1:], np.full((2, 2), np.nan))
    assert dims[0, 0] == 2.5 and math.isnan(dims[1, 0])
    assert sigma_m[0, 0] == pytest.approx(0.25)


@pytest.mark.parametrize(
    ("column", "value", "match"),
    [
        ("height_m", "0", "0.3–30 m"),
        ("width_m", "-1.7", "0.3–30 m"),
        ("length_m", "45", "0.3–30 m"),
        ("height_m", "0.1", "0.3–30 m"),
        ("length_m", "inf", "not a finite number"),
        ("width_m", "wide", "'wide' is not a number"),
        ("size_sigma_pct", "0", r"percentage in \(0, 100\]"),
        ("size_sigma_pct", "150", r"percentage in \(0, 100\]"),
        ("size_sigma_pct", "-5", r"percentage in \(0, 100\]"),
    ],
)
def test_a_bad_size_names_file_line_and_field(
    tmp_path: Path, column: str, value: str, match: str
) -> None:
    path = tmp_path / "boxes.csv"
    good = {"height_m": "1.5", "width_m": "1.7", "length_m": "4.2", "size_sigma_pct": "5"}
    bad = {**good, column: value}
    path.write_text(
        f"{HEADER}\n0,10,20,60,50,{','.join(good.values())}\n"
        f"1,10,20,60,50,{','.join(bad[c] for c in good)}\n"
    )
    with pytest.raises(InputFileError, match=match) as err:
        read_box_file(path)
    assert f"{path}, line 3, field '{column}'" in str(err.value)


POINTRCNN_LINE = "0,2,298.3,165.2,458.2,293.4,8.3,{h},1.81,4.75,-4.57,1.84,13.53,-2.11,-1.79\n"


def test_pointrcnn_sizes_are_its_h_w_l(tmp_path: Path) -> None:
    path = tmp_path / "0000.txt"
    path.write_text(POINTRCNN_LINE.format(h="1.96"))
    table = read_pointrcnn(path)
    assert [float(table.extra[c][0]) for c in SIZE_COLUMNS] == [1.96, 1.81, 4.75]
    assert "dims_hwl" not in table.extra


def test_a_pointrcnn_size_out_of_range_names_line_and_field(tmp_path: Path) -> None:
    path = tmp_path / "0000.txt"
    path.write_text(POINTRCNN_LINE.format(h="1.5") + POINTRCNN_LINE.format(h="-1"))
    with pytest.raises(InputFileError, match=r"line 2, field 'h': a vehicle dimension"):
        read_pointrcnn(path)


def test_kitti_detections_carry_sizes_only_when_asked(kitti_tracking_dir: Path) -> None:
    seq = load_sequence(kitti_tracking_dir, "0000")
    plain = seq.detections(2.0, BoxSource.POINTRCNN)
    sized = seq.detections(2.0, BoxSource.POINTRCNN, sizes=True)
    assert not any(c in plain.extra for c in SIZE_COLUMNS)
    heights = sized.extra["height_m"]
    assert len(heights) == len(plain) and bool(((heights > 1.0) & (heights < 3.0)).all())
