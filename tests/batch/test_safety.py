"""Per-track safety summaries across a fleet, on hand-made run folders."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from slopedist.batch.safety import drive_duration_s, fleet_safety
from slopedist.core.errors import InputFileError
from slopedist.io.formatting import write_csv, write_json
from slopedist.streaming.tracks import TRACK_FIELDS, read_tracks

nan = math.nan


def run_folder(
    root: Path, name: str, method: str, tracks: list[tuple[float, ...]], times: list[float]
) -> Path:
    """A run folder with ``tracks.csv`` rows (:data:`TRACK_FIELDS` order) and a frame log."""
    folder = root / name
    folder.mkdir()
    write_csv(folder / "tracks.csv", (dict(zip(TRACK_FIELDS, t)) for t in tracks), TRACK_FIELDS)
    frames = ({"frame": k, "timestamp_s": t} for k, t in enumerate(times))
    write_csv(folder / "frames.csv", frames, ("frame", "timestamp_s"))
    write_json(folder / "run.json", {"method": method, "error": None})
    return folder


def test_fleet_safety_by_hand(tmp_path: Path) -> None:
    # track_id, first_s, last_s, frames, min_d, min_d_s, min_ttc, headway, events, first_event
    a = run_folder(
        tmp_path,
        "a",
        "ours",
        [
            (1, 0, 9, 90, 12.0, 4.0, 1.5, 0.8, 2, 3.0),
            (2, 0, 9, 90, 30.0, 9.0, 6.0, 2.5, 0, nan),
        ],
        [0.0, 0.1, 1800.0],
    )
    b = run_folder(
        tmp_path,
        "b",
        "ours",
        [(7, 1, 2, 10, 8.0, 2.0, 0.9, nan, 1, 1.5)],
        [10.0, 1810.0],
    )
    c = run_folder(tmp_path, "c", "paper", [(1, 0, 1, 10, 20.0, 1.0, nan, nan, 0, nan)], [0, 360])
    rows, pooled = fleet_safety([a, b, c])
    ra, rb, rc = rows
    assert (ra["drive"], ra["method"], ra["duration_s"], ra["tracks"]) == ("a", "ours", 1800, 2)
    assert (ra["min_distance_m"], ra["min_ttc_s"], ra["ttc_tracks"], ra["ttc_events"]) == (
        12.0,
        1.5,
        1,
        2,
    )
    assert ra["ttc_events_per_h"] == pytest.approx(4.0)  # 2 events in half an hour
    assert (ra["short_headway_tracks"], ra["min_headway_s"]) == (1, 0.8)
    assert (rb["short_headway_tracks"], math.isnan(rb["min_headway_s"])) == (0, True)
    assert math.isnan(rc["min_ttc_s"]) and rc["ttc_events"] == 0 and rc["ttc_events_per_h"] == 0
    ours, paper = pooled
    assert (ours["method"], ours["drives"], ours["tracks"], ours["duration_s"]) == (
        "ours",
        2,
        3,
        3600,
    )
    assert (ours["min_ttc_s"], ours["min_ttc_drive"], ours["min_distance_m"]) == (0.9, "b", 8.0)
    assert (ours["ttc_tracks"], ours["ttc_events"], ours["ttc_events_per_h"]) == (2, 3, 3.0)
    assert (paper["method"], paper["min_ttc_drive"], paper["tracks"]) == ("paper", "", 1)


def test_a_run_without_tracks_or_times(tmp_path: Path) -> None:
    folder = tmp_path / "x"
    folder.mkdir()
    assert read_tracks(folder / "tracks.csv") == []
    assert math.isnan(drive_duration_s(folder))


def test_a_bad_track_cell_names_file_line_and_field(tmp_path: Path) -> None:
    path = tmp_path / "tracks.csv"
    path.write_text(",".join(TRACK_FIELDS) + "\n1,0,1,2,3,4,oops,,0,,,,\n")
    with pytest.raises(InputFileError, match=r"tracks.csv, line 2, field 'min_ttc_s'"):
        read_tracks(path)
    path.write_text("track_id,first_s\n1,0\n")
    with pytest.raises(InputFileError, match="missing column"):
        read_tracks(path)
    path.write_text(",".join(TRACK_FIELDS) + "\n1,0,1,2,3,4,inf,,0,,,,\n")
    with pytest.raises(InputFileError, match=r"line 2, field 'min_ttc_s'.*corrupt record"):
        read_tracks(path)


def test_a_track_seen_only_as_upper_bounds_is_not_a_track_with_a_distance(
    tmp_path: Path,
) -> None:
    d = run_folder(
        tmp_path,
        "d",
        "ours",
        [
            (1, 0, 9, 90, 12.0, 4.0, 6.0, nan, 0, nan, 0, nan, nan),
            (2, nan, nan, 0, nan, nan, nan, nan, 0, nan, 5, 4.0, 3.0),  # a truck, cut
        ],
        [0.0, 10.0],
    )
    (row,), _ = fleet_safety([d])
    assert (row["tracks"], row["min_distance_m"]) == (1, 12.0)
