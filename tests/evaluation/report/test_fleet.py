"""The fleet report of a batch output, on hand-made drive folders: status, accuracy pooled,
by range and per drive, and the per-track safety summaries, checked by hand."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest

from slopedist.batch.fleet import fleet_summary
from slopedist.batch.status import STATUS_FIELDS
from slopedist.cli import main
from slopedist.core.errors import InputFileError, MissingInputError
from slopedist.evaluation.report import (
    ReportOptions,
    SourceKind,
    detect_source,
    report_data,
    write_report,
)
from slopedist.evaluation.report.fleet import accuracy_tables
from slopedist.io.formatting import write_csv, write_json
from slopedist.streaming.tracks import TRACK_FIELDS

RECORD_FIELDS = ("frame", "timestamp_s", "track_id", "method", "distance_m", "status", "reason")
nan = math.nan


def drive(
    out: Path,
    name: str,
    records: list[tuple[object, ...]],
    tracks: list[tuple[float, ...]],
    truth: list[float] | None = None,
    method: str = "ours",
) -> None:
    """A complete, stamped drive folder: records (RECORD_FIELDS order, plus the truth),
    tracks.csv rows (TRACK_FIELDS order) and a frame log from 0 to 3600 s."""
    folder = out / name
    folder.mkdir(parents=True)
    fields = RECORD_FIELDS + (("gt_distance_m",) if truth is not None else ())
    rows = [r + ((g,) if truth is not None else ()) for r, g in zip(records, truth or records)]
    write_csv(folder / "records.csv", (dict(zip(fields, r)) for r in rows), fields)
    write_csv(folder / "tracks.csv", (dict(zip(TRACK_FIELDS, t)) for t in tracks), TRACK_FIELDS)
    times = [{"frame": 0, "timestamp_s": 0.0}, {"frame": 1, "timestamp_s": 3600.0}]
    write_csv(folder / "frames.csv", times, ("frame", "timestamp_s"))
    write_json(folder / "run.json", {"method": method, "error": None, "batch_inputs": {"x": 1}})


def status(out: Path, rows: list[dict[str, object]]) -> None:
    write_csv(out / "status.csv", rows, STATUS_FIELDS)


@pytest.fixture
def batch_out(tmp_path: Path) -> Path:
    out = tmp_path / "out"
    drive(
        out,
        "a",
        [(0, 0.0, 1, "ours", 11.0, "ok", ""), (1, 0.1, 1, "ours", 18.0, "ok", "")],
        [(1, 0, 0.1, 2, 11.0, 0.0, 1.2, 0.7, 3, 0.0)],
        truth=[10.0, 20.0],
    )
    drive(
        out,
        "b",
        [(0, 0.0, 4, "ours", 33.0, "ok", "")],
        [(4, 0, 0, 1, 33.0, 0.0, 0.8, nan, 1, 0.0), (5, 0, 0, 1, 50.0, 0.0, nan, nan, 0, nan)],
        truth=[30.0],
    )
    (out / ".tmp-c-1").mkdir()  # a killed task's leftover: not a drive
    (out / ".tmp-c-1" / "records.csv").write_text("frame\n")
    status(
        out,
        [
            {"drive": "a", "status": "done", "frames": 2, "records": 2},
            {"drive": "b", "status": "skipped", "frames": 1, "records": 1},
            {"drive": "c", "status": "failed", "error": "boxes.csv, line 3: oops"},
        ],
    )
    return out


def by_key(tables: list, key: str) -> list[list[object]]:
    return next(t for t in tables if t.key == key).rows


def test_fleet_report_tables_by_hand(batch_out: Path, tmp_path: Path) -> None:
    assert detect_source(batch_out) is SourceKind.FLEET
    data = report_data(batch_out, ReportOptions())
    assert data.sequences == ["a", "b"]
    written = write_report(data, tmp_path / "rep", parquet=False)
    tables = written.tables
    assert [t.key for t in tables][:8] == [
        "fleet_status",
        "fleet_failed",
        "fleet_pooled",
        "fleet_range",
        "fleet_drives",
        "fleet_safety_pooled",
        "fleet_safety",
        "table1_rmse",
    ]
    assert by_key(tables, "fleet_status")[:3] == [
        ["done", 1, 2, 2],
        ["failed", 1, 0, 0],
        ["skipped", 1, 1, 1],
    ]
    assert by_key(tables, "fleet_failed") == [["c", "boxes.csv, line 3: oops"]]
    pooled = by_key(tables, "fleet_pooled")[0]
    assert pooled[:3] == ["ours", 2, 3]
    assert pooled[3] == pytest.approx(math.sqrt((1 + 4 + 9) / 3))  # RMSE over both drives
    ranges = {r[1]: r for r in by_key(tables, "fleet_range")}
    assert (ranges["10-20"][2], ranges["10-20"][3]) == (1, pytest.approx(2.0))
    assert (ranges["20-30"][2], ranges["20-30"][3]) == (1, pytest.approx(3.0))  # 30 m is in 20-30
    safety = by_key(tables, "fleet_safety_pooled")[0]
    # method, drives, hours, tracks, min dist, min TTC, TTC tracks, events, /h, short hw, min hw
    assert safety[:2] == ["ours", 2]
    assert safety[2] == pytest.approx(2.0)
    assert safety[3:10] == [3, 11.0, 0.8, 2, 4, pytest.approx(2.0), 1]
    assert (safety[10], safety[11]) == (0.7, "b")
    per_drive = {r[0]: r for r in by_key(tables, "fleet_safety")}
    assert per_drive["a"][5:8] == [1.2, 1, 3]
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "Fleet: distance error pooled over all drives" in md and "boxes.csv, line 3" in md
    with (tmp_path / "rep" / "fleet_safety.csv").open(newline="") as fh:
        assert [r["drive"] for r in csv.DictReader(fh)] == ["a", "b"]


def test_report_command_prints_the_fleet_tables(
    batch_out: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["report", str(batch_out), "--out", str(tmp_path / "rep"), "--no-parquet"]) == 0
    out = capsys.readouterr().out
    assert "Fleet: distance error pooled" in out and "Fleet: safety summary pooled" in out
    assert "Table 1" in out


def test_a_batch_without_a_complete_drive(tmp_path: Path) -> None:
    status(tmp_path, [{"drive": "c", "status": "failed", "error": "x"}])
    with pytest.raises(MissingInputError, match="without a complete drive"):
        report_data(tmp_path, ReportOptions())


def test_a_status_table_without_its_columns(tmp_path: Path) -> None:
    (tmp_path / "status.csv").write_text("name\nc\n")
    with pytest.raises(InputFileError, match=r"status.csv, line 1: missing column 'drive'"):
        report_data(tmp_path, ReportOptions())


def test_pooled_rmse_of_methods_on_different_drives_is_not_compared(tmp_path: Path) -> None:
    """Each method pooled over its own drives scores other targets: no best in bold (as
    Table 1's overall row); on the same drives the best is bold."""
    out = tmp_path / "out"
    drive(out, "a", [(0, 0.0, 1, "flat", 11.0, "ok", "")], [], truth=[10.0], method="flat")
    drive(out, "b", [(0, 0.0, 1, "paper", 40.0, "ok", "")], [], truth=[30.0], method="paper")
    (pooled,) = [t for t in accuracy_tables(fleet_summary(out)) if t.key == "fleet_pooled"]
    assert [r[0] for r in pooled.rows] == ["flat", "paper"]
    assert not any(any(row) for row in pooled.bold)
    assert "different drives: not compared" in pooled.note
    both = [(0, 0.0, 1, "flat", 11.0, "ok", ""), (0, 0.0, 1, "paper", 12.0, "ok", "")]
    drive(out / "same", "c", both, [], truth=[10.0, 10.0])
    (pooled,) = [t for t in accuracy_tables(fleet_summary(out / "same")) if t.key == "fleet_pooled"]
    assert [row[3] for row in pooled.bold] == [True, False]  # flat: RMSE 1 m against 2 m
    assert "not compared" not in pooled.note
