"""The report shows the runs' per-track summaries (tracks.csv), closest first."""

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
from slopedist.io.detections.boxes import BoxTable
from slopedist.streaming.tracks import TRACKS_NAME, TrackSummaries


def run_folder(
    folder: Path, distances: dict[int, list[float]], ttc: dict[int, list[float]]
) -> None:
    folder.mkdir(parents=True)
    lines = ["frame,track_id,method,distance_m,status,reason"]
    summaries = TrackSummaries()
    n = len(next(iter(distances.values())))
    for k in range(n):
        tids = sorted(distances)
        for t in tids:
            lines.append(f"{k},{t},ours,{distances[t][k]},ok,")
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
        summaries.add(k / 10, boxes, est)
    (folder / "records.csv").write_text("\n".join(lines) + "\n")
    summaries.write(folder / TRACKS_NAME)


def test_track_table_lists_the_closest_tracks_first(tmp_path: Path) -> None:
    run_folder(
        tmp_path / "run",
        {1: [20.0, 19.0, 18.0], 2: [9.0, 8.0, 7.5], 3: [30.0, 31.0, 32.0]},
        {1: [5.0, 1.5, 3.0], 2: [math.nan] * 3, 3: [9.0, 8.0, 7.0]},
    )
    data = run_report_data(tmp_path / "run", ReportOptions())
    (table,) = [t for t in report_tables(data) if t.key == "tracks"]
    assert [r[2] for r in table.rows] == [1, 3, 2]  # by smallest TTC, then distance
    one = table.rows[0]
    assert (one[5], one[6], one[7]) == (18.0, 1.5, 1)
    assert math.isnan(table.rows[2][6])


def test_track_table_title_says_how_the_tracks_were_chosen(tmp_path: Path) -> None:
    # track 2 is the closest (7.5 m) but has no TTC, so it is listed last and, with more
    # tracks than rows, left out: the title must not call the rows "the closest"
    run_folder(
        tmp_path / "run",
        {1: [20.0, 19.0, 18.0], 2: [9.0, 8.0, 7.5]},
        {1: [5.0, 1.5, 3.0], 2: [math.nan] * 3},
    )
    data = run_report_data(tmp_path / "run", ReportOptions())
    (table,) = [t for t in report_tables(data) if t.key == "tracks"]
    assert table.title == "Tracks: 2 of 2, smallest TTC first, then smallest distance"


def test_a_bad_tracks_cell_names_file_line_and_field(tmp_path: Path) -> None:
    run_folder(tmp_path / "run", {1: [20.0]}, {1: [5.0]})
    path = tmp_path / "run" / TRACKS_NAME
    path.write_text(path.read_text().replace("20", "x20", 1))
    with pytest.raises(InputFileError, match=r"tracks\.csv, line 2, field 'min_distance_m'"):
        run_report_data(tmp_path / "run", ReportOptions())
