"""The report's per-track table of run outputs: from the records, followed closely longest
first; the mean headway of the runs' tracks.csv where the run had an ego speed."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from slopedist.core.errors import InputFileError
from slopedist.estimators.base import FrameEstimates
from slopedist.evaluation.report.data import ReportOptions
from slopedist.evaluation.report.runs import run_report_data
from slopedist.evaluation.report.tables import report_tables
from slopedist.evaluation.report.track_summary import TRACK_TABLE_ROWS
from slopedist.io.detections.boxes import BoxTable
from slopedist.streaming.tracks import TRACKS_NAME, TrackSummaries


def run_folder(
    folder: Path,
    distances: dict[int, list[float]],
    ttc: dict[int, list[float]],
    ego_speed_mps: float = math.nan,
) -> None:
    """records.csv (with ``ttc_s`` and times 0.1 s apart) and the tracks.csv the run would
    write."""
    folder.mkdir(parents=True)
    lines = ["frame,timestamp_s,track_id,method,distance_m,ttc_s,status,reason"]
    summaries = TrackSummaries()
    n = len(next(iter(distances.values())))
    for k in range(n):
        tids = sorted(distances)
        for t in tids:
            lines.append(f"{k},{k / 10},{t},ours,{distances[t][k]},{ttc[t][k]},ok,")
        boxes = BoxTable.build(np.full(len(tids), k), np.tile([0.0, 0, 9, 9], (len(tids), 1)), tids)
        m = len(tids)
        est = FrameEstimates(
            np.zeros(m),
            np.zeros(m),
            np.zeros(m),
            np.zeros(m),
            np.array([distances[t][k] for t in tids]),
            np.array([""] * m, dtype=object),
            np.array(["contact"] * m, dtype=object),
            {"ttc_s": np.array([ttc[t][k] for t in tids])},
        )
        summaries.add(k / 10, boxes, est, ego_speed_mps)
    (folder / "records.csv").write_text("\n".join(lines) + "\n")
    summaries.write(folder / TRACKS_NAME)


def test_track_table_lists_the_tracks_followed_closely_longest_first(tmp_path: Path) -> None:
    run_folder(
        tmp_path / "run",
        {1: [20.0, 19.0, 18.0], 2: [11.0, 9.0, 7.5], 3: [30.0, 31.0, 32.0]},
        {1: [5.0, 1.5, 3.0], 2: [math.nan] * 3, 3: [9.0, 8.0, 7.0]},
    )
    data = run_report_data(tmp_path / "run", ReportOptions())
    (table,) = [t for t in report_tables(data) if t.key == "tracks"]
    assert table.headers[-2:] == ["time < 10 m (s)", "least TTC (s)"]  # no headway: no speed
    # track 2 is under 10 m for two frames; then the closest
    assert [r[0] for r in table.rows] == [2, 1, 3]
    assert table.rows[0][-2] == pytest.approx(0.2) and math.isnan(table.rows[0][-1])
    one = table.rows[1]
    assert (one[4], one[5], one[-1]) == (18.0, pytest.approx(0.2), 1.5)
    assert table.title.startswith("Tracks (all 3): longest closer than 10 m first")


def test_track_table_has_the_runs_mean_headway_with_an_ego_speed(tmp_path: Path) -> None:
    run_folder(tmp_path / "run", {1: [20.0, 10.0]}, {1: [5.0, 4.0]}, ego_speed_mps=10.0)
    data = run_report_data(tmp_path / "run", ReportOptions())
    (table,) = [t for t in report_tables(data) if t.key == "tracks"]
    assert table.headers[-1] == "mean headway (s)"
    assert table.rows[0][-1] == pytest.approx(1.5)  # (2 s + 1 s) / 2
    assert "tracks.csv" in table.note


def test_track_table_lists_at_most_its_rows(tmp_path: Path) -> None:
    run_folder(tmp_path / "run", {t: [10.0 + t] for t in range(25)}, {t: [5.0] for t in range(25)})
    data = run_report_data(tmp_path / "run", ReportOptions())
    (table,) = [t for t in report_tables(data) if t.key == "tracks"]
    assert len(table.rows) == TRACK_TABLE_ROWS
    assert table.title.startswith(f"Tracks ({TRACK_TABLE_ROWS} of 25)")


def test_a_bad_tracks_cell_names_file_line_and_field(tmp_path: Path) -> None:
    run_folder(tmp_path / "run", {1: [20.0]}, {1: [5.0]})
    path = tmp_path / "run" / TRACKS_NAME
    path.write_text(path.read_text().replace("20", "x20", 1))
    with pytest.raises(InputFileError, match=r"tracks\.csv, line 2, field 'min_distance_m'"):
        run_report_data(tmp_path / "run", ReportOptions())
