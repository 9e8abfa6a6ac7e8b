"""The summary lines about records: `estimate` said only how many it wrote, and a detector's
class ids (`2`) made every row missing, not_a_vehicle, without a word."""

from __future__ import annotations

from pathlib import Path

import pytest

from slopedist.cli import main
from slopedist.cli.record_summary import RecordTally, not_vehicles_line


def _row(status: str, reason: str = "", cls: str = "Car") -> dict[str, str]:
    return {"status": status, "reason": reason, "class": cls}


def test_tally_counts_rows_and_names_the_classes_that_are_not_vehicles() -> None:
    tally = RecordTally()
    rows = [_row("ok"), _row("upper_bound", "cut_bottom"), _row("missing", "not_a_vehicle", "2")]
    assert list(tally.count(rows)) == rows
    lines = tally.lines("r.csv")
    assert lines[0] == "wrote 3 records (1 ok, 1 upper bounds) to r.csv"
    assert lines[1].startswith("1 boxes are not of a vehicle class ('2' (1); missing")
    assert RecordTally().lines(None) == []


def test_no_distance_at_all_is_a_warning_naming_the_most_frequent_classes() -> None:
    classes = {f"c{k}": k for k in range(1, 8)}
    line = not_vehicles_line(classes, records=40, with_distance=0)
    assert line.startswith("warning: no box got a distance; 28 of 40 are of a class that is not")
    assert "'c7' (7), 'c6' (6), 'c5' (5), 'c4' (4), 'c3' (3) and 2 more" in line
    # 12 rows of vehicle classes got no distance either: --vehicle-classes is not their fix
    assert line.endswith("; the reasons of the other 12 rows say what they lacked")
    line = not_vehicles_line({"2": 40}, records=40, with_distance=0)
    assert line.endswith("; name the vehicle classes with --vehicle-classes")


def test_estimate_warns_when_every_box_is_of_another_class(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    calib = tmp_path / "calib.txt"
    calib.write_text("P2: 700 0 600 0 0 700 180 0 0 0 1 0\n")
    poses = tmp_path / "poses.txt"
    poses.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n" * 2)
    boxes = tmp_path / "boxes.csv"
    boxes.write_text(
        "frame,left,top,right,bottom,class\n0,500,200,600,260,2\n1,500,200,600,260,2\n"
    )
    args = ["estimate", "--calib", str(calib), "--poses", str(poses), "--boxes", str(boxes)]
    assert main([*args, "--out", str(tmp_path / "r.csv")]) == 0
    err = capsys.readouterr().err
    assert "wrote 2 records (0 ok, 0 upper bounds)" in err
    assert (
        "warning: no box got a distance; 2 of 2 are of a class that is not a vehicle: '2' (2)"
        in err
    )
