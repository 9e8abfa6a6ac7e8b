"""Fleet outputs: the Parquet partitions and the summary tables, on hand-made run folders."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import pytest

from slopedist.batch.fleet import (
    SETTINGS_FIELDS,
    fleet_summary,
    records_dataset,
    settings_rows,
    write_fleet_summary,
    write_partition,
)
from slopedist.batch.stamp import SETTINGS_KEY
from slopedist.core.errors import InputFileError
from slopedist.io.formatting import write_csv, write_json

FIELDS = ("frame", "track_id", "method", "distance_m", "status", "reason", "gt_distance_m")


def drive(out: Path, name: str, rows: list[tuple[object, ...]], stamped: bool = True) -> None:
    folder = out / name
    folder.mkdir(parents=True)
    write_csv(folder / "records.csv", (dict(zip(FIELDS, r)) for r in rows), FIELDS)
    write_json(folder / "run.json", {"error": None, "batch_inputs": {} if stamped else None})


@pytest.fixture
def batch_out(tmp_path: Path) -> Path:
    nan = math.nan
    drive(
        tmp_path,
        "d1",
        [
            (0, 1, "m", 11.0, "ok", "", 10.0),
            (1, 1, "m", 18.0, "ok", "", 20.0),
            (2, 1, "m", nan, "missing", "below_horizon", 50.0),  # counted at the 80 m cap
            (3, 2, "m", 30.0, "ok", "", nan),  # no truth: not scored
        ],
    )
    drive(tmp_path, "d2", [(0, 1, "m", 5.0, "ok", "", 4.0), (0, 1, "x", 7.0, "ok", "", 4.0)])
    drive(tmp_path, "old", [(0, 1, "m", 100.0, "ok", "", 4.0)], stamped=False)  # not a batch's
    return tmp_path


def test_fleet_summary_by_hand(batch_out: Path) -> None:
    summary = fleet_summary(batch_out)
    d1 = next(r for r in summary.drives if r["drive"] == "d1")
    assert (d1["records"], d1["estimated"], d1["truth"], d1["n"]) == (4, 3, 3, 3)
    assert d1["rmse"] == pytest.approx(math.sqrt((1 + 4 + 30**2) / 3))
    assert {(r["drive"], r["method"]) for r in summary.drives} == {
        ("d1", "m"),
        ("d2", "m"),
        ("d2", "x"),
    }
    pooled = {r["method"]: r for r in summary.pooled}
    assert (pooled["m"]["drives"], pooled["m"]["n"]) == (2, 4)
    assert pooled["m"]["rmse"] == pytest.approx(math.sqrt((1 + 4 + 900 + 1) / 4))
    assert pooled["x"]["mae"] == pytest.approx(3.0)
    ranges = {r["range_m"]: r for r in summary.by_range if r["method"] == "m"}
    # bins are (lo, hi]: the 10 m truth is in 0-10
    assert (ranges["0-10"]["n"], ranges["0-10"]["rmse"]) == (2, pytest.approx(1.0))
    assert (ranges["10-20"]["n"], ranges["10-20"]["rmse"]) == (1, pytest.approx(2.0))
    assert (ranges["40-80"]["n"], ranges["20-30"]["n"]) == (1, 0)
    files = write_fleet_summary(batch_out, summary)
    assert [p.name for p in files] == [
        "drives.csv",
        "pooled.csv",
        "range.csv",
        "safety.csv",
        "safety_pooled.csv",
        "settings.csv",
    ]
    assert files[1].read_text().splitlines()[1].startswith("m,2,4,15.0")


def test_settings_table_by_hand(batch_out: Path) -> None:
    """``fleet/settings.csv``: each complete drive's options from its ``run.json``, lists and
    ours options as manifest cells; a drive without them (an older batch's) by name only."""
    options = {
        "method": "ours",
        "reference": "nearest_face",
        "ours_options": {"size_learning": True, "size_evidence_time_s": None, "gate_sigma": 4.5},
        "vehicle_classes": ["Car", "Van"],
        "offline": True,
        "export": ["mcap", "tum"],
        "height_m": 1.7,
    }
    write_json(
        batch_out / "d1" / "run.json", {"error": None, "batch_inputs": {}, SETTINGS_KEY: options}
    )
    rows = {r["drive"]: r for r in settings_rows(batch_out)}
    assert sorted(rows) == ["d1", "d2"]  # "old" is no batch's drive
    d1 = rows["d1"]
    assert d1["ours_options"] == "size_learning=true;size_evidence_time_s=none;gate_sigma=4.5"
    assert (d1["vehicle_classes"], d1["export"], d1["offline"]) == ("Car;Van", "mcap;tum", True)
    assert (d1["method"], d1["reference"], d1["height_m"], d1["overlay"]) == (
        "ours",
        "nearest_face",
        1.7,
        None,
    )
    assert set(rows["d2"]) == set(SETTINGS_FIELDS)
    assert [v for k, v in rows["d2"].items() if k != "drive"] == [None] * (len(SETTINGS_FIELDS) - 1)
    lines = write_fleet_summary(batch_out)[-1].read_text().splitlines()
    assert lines[0] == ",".join(SETTINGS_FIELDS)
    assert lines[1].startswith("d1,ours,nearest_face,size_learning=true;size_evidence_time_s=")
    assert ",Car;Van,1,,,mcap;tum,,,1.7," in lines[1]


def test_parquet_partition_round_trip(batch_out: Path) -> None:
    pq = pytest.importorskip("pyarrow.parquet", reason="pyarrow is not installed")
    path = write_partition(batch_out, "d1")
    assert path == batch_out / "records.parquet" / "drive=d1" / "part-0.parquet"
    table = pq.read_table(path)
    assert table.column("frame").to_pylist() == [0, 1, 2, 3]
    assert table.column("distance_m").to_pylist()[:2] == [11.0, 18.0]
    assert table.column("distance_m").null_count == 1
    assert table.column("reason").to_pylist()[2] == "below_horizon"
    stamp = path.stat().st_mtime_ns
    assert write_partition(batch_out, "d1", refresh=False).stat().st_mtime_ns == stamp


def test_the_records_dataset_keeps_drive_names_that_look_like_numbers(tmp_path: Path) -> None:
    """Drives ``007`` and ``2011`` read back by their names, not as the numbers 7 and 2011."""
    pytest.importorskip("pyarrow.parquet", reason="pyarrow is not installed")
    for name in ("007", "2011", "d1"):
        drive(tmp_path, name, [(0, 1, "m", 11.0, "ok", "", 10.0)])
        write_partition(tmp_path, name)
    table = records_dataset(tmp_path).to_table()
    assert sorted(table.column("drive").to_pylist()) == ["007", "2011", "d1"]


def test_a_kept_partition_is_one_of_the_drive_as_it_is_now(tmp_path: Path) -> None:
    """A batch killed after a drive ran again but before its partition was rewritten: the next
    batch skips the drive (its folder is complete) and must not keep the old run's records."""
    pq = pytest.importorskip("pyarrow.parquet", reason="pyarrow is not installed")
    drive(tmp_path, "d1", [(0, 1, "paper", 11.0, "ok", "", 10.0)])
    write_json(tmp_path / "d1" / "run.json", {"error": None, "batch_inputs": {"run": 1}})
    write_partition(tmp_path, "d1")
    shutil.rmtree(tmp_path / "d1")  # the drive runs again with another method
    drive(tmp_path, "d1", [(0, 1, "ours", 12.0, "ok", "", 10.0)])
    write_json(tmp_path / "d1" / "run.json", {"error": None, "batch_inputs": {"run": 2}})
    path = write_partition(tmp_path, "d1", refresh=False)
    assert pq.read_table(path).column("method").to_pylist() == ["ours"]
    kept = path.stat().st_mtime_ns
    assert write_partition(tmp_path, "d1", refresh=False).stat().st_mtime_ns == kept


def test_the_records_dataset_has_the_columns_of_every_drive(tmp_path: Path) -> None:
    """A dataset whose first drive has no truth and no ``ours`` columns still reads the truth
    and the extra columns of the others (pyarrow alone takes the first file's schema)."""
    pytest.importorskip("pyarrow.parquet", reason="pyarrow is not installed")
    folder = tmp_path / "a_paper"
    folder.mkdir()
    write_csv(folder / "records.csv", [{"frame": 0, "method": "paper", "distance_m": 9.0}])
    write_json(folder / "run.json", {"error": None, "batch_inputs": {}})
    write_partition(tmp_path, "a_paper")
    fields = (*FIELDS, "ttc_s", "track_uid")
    rows = [dict(zip(fields, (0, 1, "ours", 11.0, "ok", "", 10.0, 2.5, 7)))]
    drive(tmp_path, "b_ours", [])
    write_csv(tmp_path / "b_ours" / "records.csv", rows, fields)
    write_partition(tmp_path, "b_ours")
    table = records_dataset(tmp_path).to_table().sort_by("drive")
    assert table.column("gt_distance_m").to_pylist() == [None, 10.0]
    assert table.column("ttc_s").to_pylist() == [None, 2.5]
    assert table.column("track_uid").to_pylist() == [None, 7]
    assert table.column("drive").to_pylist() == ["a_paper", "b_ours"]


def test_a_method_run_at_another_reference_point_is_pooled_apart(tmp_path: Path) -> None:
    """``ours`` at its centre and ``ours`` at the nearest face measure different points: the
    pooled accuracy and safety rows keep them apart (``ours@nearest_face``)."""
    drive(tmp_path, "centre", [(0, 1, "ours", 11.0, "ok", "", 10.0)])
    drive(tmp_path, "face", [(0, 1, "ours", 8.0, "ok", "", 10.0)])
    for name, reference in (("centre", None), ("face", "nearest_face")):
        options = {"method": "ours", "reference": reference}
        summary = {"error": None, "method": "ours", "batch_inputs": {}, SETTINGS_KEY: options}
        write_json(tmp_path / name / "run.json", summary)
    fleet = fleet_summary(tmp_path)
    assert [(r["method"], r["drives"], r["rmse"]) for r in fleet.pooled] == [
        ("ours", 1, 1.0),
        ("ours@nearest_face", 1, 2.0),
    ]
    assert [(r["drive"], r["method"]) for r in fleet.drives] == [
        ("centre", "ours"),
        ("face", "ours@nearest_face"),
    ]
    assert [r["method"] for r in fleet.safety_pooled] == ["ours", "ours@nearest_face"]
    assert {r["method"] for r in fleet.by_range} == {"ours", "ours@nearest_face"}


@pytest.mark.parametrize("value", ["1e308", "inf", "-inf"])
def test_an_absurd_distance_is_one_error_naming_file_line_and_field(
    tmp_path: Path, value: str
) -> None:
    """The fleet tables read records.csv with the report's bound: a distance beyond it (a
    corrupt record) is refused, not pooled."""
    drive(tmp_path, "d1", [(0, 1, "m", 11.0, "ok", "", 10.0), (1, 1, "m", value, "ok", "", 9.0)])
    with pytest.raises(InputFileError) as err:
        fleet_summary(tmp_path)
    message = str(err.value)
    assert "records.csv" in message and "line 3" in message and "distance_m" in message


@pytest.mark.parametrize(
    ("status", "reason", "field"),
    [("OK", "", "status"), ("upper_bound", "", "reason"), ("missing", "", "reason")],
)
def test_a_status_the_reason_contradicts_is_not_scored_but_refused(
    tmp_path: Path, status: str, reason: str, field: str
) -> None:
    """Scoring goes by the reason: a hand-edited status (an upper bound whose reason was
    blanked) would be scored as an estimate; it is refused, naming the line and field."""
    drive(
        tmp_path, "d1", [(0, 1, "m", 11.0, "ok", "", 10.0), (1, 1, "m", 9.0, status, reason, 9.0)]
    )
    with pytest.raises(InputFileError, match=rf"records\.csv, line 3, field '{field}'"):
        fleet_summary(tmp_path)


def test_a_drive_at_the_gap_is_scored_at_each_method_s_own_point(tmp_path: Path) -> None:
    """Against a truth the fleet scores ``ours`` at its centre (its own half extent, else half
    the class's length prior) and ``paper`` at its contact row, whatever point the drive was
    run at: the KITTI protocol's comparison."""
    fields = (*FIELDS, "reference", "class", "distance_centre_m", "distance_nearest_face_m")
    folder = tmp_path / "gap"
    folder.mkdir()
    rows = [
        (0, 1, "ours", 18.0, "ok", "", 20.0, "nearest_face", "Car", 20.5, 18.0),
        (1, 1, "ours", 18.0, "ok", "", 20.0, "nearest_face", "Car", "", ""),
        (0, 1, "paper", 18.0, "ok", "", 20.0, "contact", "Car", "", ""),
        (1, 1, "paper", 23.0, "ok", "", 20.0, "centre", "Car", "", ""),
    ]
    write_csv(folder / "records.csv", (dict(zip(fields, r)) for r in rows), fields)
    write_json(folder / "run.json", {"error": None, "batch_inputs": {}})
    by_method = {r["method"]: r for r in fleet_summary(tmp_path).drives}
    car_half = 3.88 / 2
    ours_err = [0.5, 18.0 + car_half - 20.0]
    paper_err = [-2.0, 23.0 - car_half - 20.0]
    for method, err in (("ours", ours_err), ("paper", paper_err)):
        expected = math.sqrt(sum(e * e for e in err) / 2)
        assert by_method[method]["rmse"] == pytest.approx(expected), method
