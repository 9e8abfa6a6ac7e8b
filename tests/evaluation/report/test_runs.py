"""Reading run outputs for the report: every bad records.csv / frames.csv / run.json is one
clear error naming file, line and field."""

from __future__ import annotations

from pathlib import Path

import pytest

from slopedist.core.errors import InputFileError
from slopedist.evaluation.report import ReportOptions, report_data

HEADER = "frame,timestamp_s,track_id,class,method,distance_m,status,reason,theta_deg,gt_distance_m"
GOOD = ["0,0.0,3,Car,paper,10.0,ok,,0.1,11.0", "1,0.1,3,Car,paper,21.0,ok,,0.1,20.0"]


def _run(folder: Path, rows: list[str], frames: str = "frame,estimation_ms\n0,1.0\n") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "records.csv").write_text("\n".join([HEADER, *rows]) + "\n")
    (folder / "frames.csv").write_text(frames)
    return folder


def test_good_run_reads(tmp_path: Path) -> None:
    data = report_data(_run(tmp_path / "r", GOOD), ReportOptions())
    assert data.methods == ["paper"] and data.overall["paper"]["n"] == 2


@pytest.mark.parametrize(
    ("row", "match"),
    [
        ("nan,0.2,3,Car,paper,12.0,ok,,0.1,12.0", r"line 4, field 'frame': 'nan' is not a whole"),
        ("inf,0.2,3,Car,paper,12.0,ok,,0.1,12.0", r"line 4, field 'frame'"),
        ("1e308,0.2,3,Car,paper,12.0,ok,,0.1,12.0", r"line 4, field 'frame'"),
        (",0.2,3,Car,paper,12.0,ok,,0.1,12.0", r"line 4, field 'frame'"),
        ("-1,0.2,3,Car,paper,12.0,ok,,0.1,12.0", r"line 4, field 'frame'"),
        ("2,0.2,1e308,Car,paper,12.0,ok,,0.1,12.0", r"line 4, field 'track_id'"),
        ("2,0.2,3,Car,paper,-3,ok,,0.1,12.0", r"line 4, field 'distance_m': a record of status ok"),
        ("2,0.2,3,Car,paper,inf,ok,,0.1,12.0", r"line 4, field 'distance_m'"),
        ("2,0.2,3,Car,paper,,ok,,0.1,12.0", r"line 4, field 'distance_m'"),
        ("2,0.2,3,Car,paper,12.0", r"line 4: row has 6 fields, the header has 10"),
        ("2,0.2,3,Car,paper,12.0,ok,,0.1,12.0,extra", r"line 4: row has 11 fields"),
        ('2,0.2,3,"Car,paper,12.0,ok,,0.1,12.0', r"line 4: row has 4 fields"),
        ("2,0.2,3,Car,paper,12.0,OK,,0.1,12.0", r"line 4, field 'status': 'OK' is not a record"),
        ("2,0.2,3,Car,paper,12.0,okay,,0.1,12.0", r"line 4, field 'status'"),
        ("2,0.2,3,Car,paper,12.0,upper_bound,,0.1,12.0", r"line 4, field 'reason': a record of"),
        ("2,0.2,3,Car,paper,12.0,missing,,0.1,12.0", r"line 4, field 'reason'"),
        ("2,0.2,3,Car,paper,12.0,ok,cut_bottom,0.1,12.0", r"line 4, field 'reason'"),
    ],
)
def test_bad_records_name_line_and_field(tmp_path: Path, row: str, match: str) -> None:
    with pytest.raises(InputFileError, match=match):
        report_data(_run(tmp_path / "r", [*GOOD, row]), ReportOptions())


def test_a_run_without_boxes_is_one_clear_error(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match=r"records.csv: no records: the run\(s\) had no boxes"):
        report_data(_run(tmp_path / "r", []), ReportOptions())


def test_missing_distance_is_fine_when_not_ok(tmp_path: Path) -> None:
    rows = [*GOOD, "2,0.2,3,Car,paper,,missing,below_horizon,0.1,30.0"]
    assert report_data(_run(tmp_path / "r", rows), ReportOptions()).overall["paper"]["n"] == 3


def test_non_utf8_records_frames_and_run_json(tmp_path: Path) -> None:
    folder = _run(tmp_path / "r", GOOD)
    (folder / "records.csv").write_bytes(
        (HEADER + "\n" + GOOD[0] + "\n").encode() + b"1,0.1,3,Caf\xe9,paper,2,ok,,0,2\n"
    )
    with pytest.raises(InputFileError, match=r"records\.csv, line 3: not UTF-8"):
        report_data(folder, ReportOptions())
    folder = _run(tmp_path / "f", GOOD, "frame,estimation_ms\n0,1.0\n")
    (folder / "frames.csv").write_bytes(b"frame,estimation_ms\n0,1.0\n1,\xff\n")
    with pytest.raises(InputFileError, match=r"frames\.csv, line 3: not UTF-8"):
        report_data(folder, ReportOptions())
    folder = _run(tmp_path / "j", GOOD)
    (folder / "run.json").write_bytes(b'{"sequence":\n "caf\xe9"}')
    with pytest.raises(InputFileError, match=r"run\.json, line 2: not UTF-8"):
        report_data(folder, ReportOptions())
    (folder / "run.json").write_text('["not", "an object"]')
    with pytest.raises(InputFileError, match=r"run\.json: not a JSON object"):
        report_data(folder, ReportOptions())
    (folder / "run.json").write_text('{"sequence": ')
    with pytest.raises(InputFileError, match=r"run\.json, line 1: not valid JSON"):
        report_data(folder, ReportOptions())


@pytest.mark.parametrize("column", [1, 8, 9])
@pytest.mark.parametrize("value", ["inf", "-inf", "1e308", "-2e12"])
def test_infinite_or_huge_numbers_are_errors(tmp_path: Path, column: int, value: str) -> None:
    cells = GOOD[1].split(",")
    cells[column] = value
    name = HEADER.split(",")[column]
    with pytest.raises(InputFileError, match=rf"line 3, field '{name}'"):
        report_data(_run(tmp_path / "r", [GOOD[0], ",".join(cells)]), ReportOptions())


def test_a_declared_truth_reference_moves_every_method_to_it(tmp_path: Path) -> None:
    """paper's contact distance gains half the car's length prior to meet a centre truth; ours'
    centre distance loses its own half extent to meet a nearest-face truth."""
    from slopedist.estimators.base import ReferencePoint
    from slopedist.evaluation.kitti import KittiEvalConfig

    header = HEADER + ",reference,distance_centre_m,distance_nearest_face_m"
    folder = tmp_path / "r"
    folder.mkdir()
    (folder / "records.csv").write_text(
        "\n".join(
            [
                header,
                "0,0.0,3,Car,paper,10.0,ok,,0.1,11.94,contact,,",
                "0,0.0,3,Car,ours,12.0,ok,,0.1,11.94,centre,12.0,10.0",
            ]
        )
        + "\n"
    )
    (folder / "frames.csv").write_text("frame,estimation_ms\n0,1.0\n")
    as_given = report_data(folder, ReportOptions())
    assert as_given.overall["paper"]["rmse"] == pytest.approx(1.94)
    centre = report_data(
        folder, ReportOptions(eval=KittiEvalConfig(gt_reference=ReferencePoint.CENTRE))
    )
    assert centre.overall["paper"]["rmse"] == pytest.approx(0.0, abs=1e-9)
    assert centre.overall["ours"]["rmse"] == pytest.approx(0.06)
    face = report_data(
        folder, ReportOptions(eval=KittiEvalConfig(gt_reference=ReferencePoint.NEAREST_FACE))
    )
    assert face.overall["ours"]["rmse"] == pytest.approx(1.94)
    assert face.overall["paper"]["rmse"] == pytest.approx(1.94)
    assert "nearest_face" in " ".join(face.notes)


def test_methods_scored_against_other_targets_are_not_compared(tmp_path: Path) -> None:
    """Two runs of one sequence over different frames score different targets: Table 1 and
    the metrics tables show both but mark no best (flat's one target is not a win)."""
    from slopedist.evaluation.accuracy_tables import score_tables

    paper = _run(tmp_path / "runs" / "paper", GOOD)
    flat = _run(tmp_path / "runs" / "flat", ["0,0.0,3,Car,flat,11.0,ok,,0.1,11.0"])
    for folder in (paper, flat):
        (folder / "run.json").write_text('{"sequence": "s"}')
    data = report_data(tmp_path / "runs", ReportOptions())
    assert data.sequences == ["s"] and data.overall["flat"]["rmse"] == 0.0
    table1, metrics, bins = score_tables(data.scores)
    assert not any(any(row) for row in table1.bold)
    assert "s (n: flat 1, paper 2), overall (n: flat 1, paper 2): the methods were" in table1.note
    assert not any(any(row) for row in metrics.bold) and not any(any(row) for row in bins.bold)
    _run(flat, ["0,0.0,3,Car,flat,11.0,ok,,0.1,11.0", "1,0.1,3,Car,flat,20.0,ok,,0.1,20.0"])
    table1 = score_tables(report_data(tmp_path / "runs", ReportOptions()).scores)[0]
    assert table1.bold[0] == [False, False, True, False]  # the same targets: flat is best


def test_a_partial_run_is_named_in_the_notes_and_printed(tmp_path: Path) -> None:
    """A run stopped half way (run.json: complete false) is scored on the frames it finished;
    the report says so instead of passing its figures off as the whole sequence's."""
    from click.testing import CliRunner

    from slopedist.cli import cli

    folder = _run(tmp_path / "r", GOOD)
    (folder / "run.json").write_text(
        '{"sequence": "s", "complete": false, "last_complete_frame": 1, "error": null}'
    )
    data = report_data(folder, ReportOptions())
    assert (
        data.warnings and "partial run" in data.warnings[0] and "after frame 1" in data.warnings[0]
    )
    assert data.warnings[0] in data.notes
    result = CliRunner().invoke(cli, ["report", str(folder), "--out", str(tmp_path / "rep")])
    assert result.exit_code == 0, result.output
    assert "warning:" in result.output and "partial run" in result.output
    assert "partial run" in (tmp_path / "rep" / "report.md").read_text()
    (folder / "run.json").write_text('{"sequence": "s", "complete": true}')
    assert report_data(folder, ReportOptions()).warnings == []


def test_table2_compares_no_totals_when_a_rotation_was_not_timed(tmp_path: Path) -> None:
    """``paper`` timed its built-in odometry; ``ours`` ran on a pose file (odometry '-'): its
    smaller total lacks a part, so no total is marked best; ``flat``, which needs no rotation,
    is compared."""
    from slopedist.evaluation.report.tables import table2

    def run(method: str, frames: str) -> None:
        rows = [r.replace(",paper,", f",{method},") for r in GOOD]
        folder = _run(tmp_path / "runs" / method, rows, frames)
        (folder / "run.json").write_text('{"sequence": "s"}')

    run("paper", "frame,odometry_ms,estimation_ms\n0,5.0,1.0\n1,5.0,1.0\n")
    run("flat", "frame,estimation_ms\n0,0.1\n1,0.1\n")
    table = table2(report_data(tmp_path / "runs", ReportOptions()))
    assert [r[0] for r in table.rows] == ["flat", "paper"] and table.bold[0][4]
    run("ours", "frame,estimation_ms\n0,0.5\n1,0.5\n")
    table = table2(report_data(tmp_path / "runs", ReportOptions()))
    assert not any(b[4] for b in table.bold)
    assert "Totals not compared: ours took rotations from elsewhere" in table.note
