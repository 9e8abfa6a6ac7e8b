"""Per-track summaries, hand-computed: first/last time, closest distance, TTC and its events,
headway."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from slopedist.estimators.base import FrameEstimates
from slopedist.io.detections.boxes import BoxTable
from slopedist.streaming.tracks import TRACK_FIELDS, TrackSummaries, read_tracks


def frame(
    track_ids: list[int],
    distances: list[float],
    ttc: list[float],
    reasons=None,
    ttc_sigma: list[float] | None = None,
    status: list[str] | None = None,
):
    n = len(track_ids)
    boxes = BoxTable.build(np.zeros(n), np.tile([0.0, 0.0, 10.0, 10.0], (n, 1)), track_ids)
    extra = {"ttc_s": np.array(ttc, dtype=float)}
    if ttc_sigma is not None:
        extra["ttc_sigma_s"] = np.array(ttc_sigma, dtype=float)
    est = FrameEstimates(
        np.zeros(n),
        np.zeros(n),
        np.zeros(n),
        np.zeros(n),
        np.array(distances, dtype=float),
        np.array(reasons or [""] * n, dtype=object),
        np.array(["contact"] * n, dtype=object),
        extra,
        np.array(status, dtype=object) if status is not None else np.zeros(0, dtype=object),
    )
    return boxes, est


def test_summary_of_two_tracks(tmp_path: Path) -> None:
    s = TrackSummaries(ttc_threshold_s=2.0)
    # track 1 closes in, TTC dips below 2 s twice; track 2 has no TTC; -1 is untracked
    s.add(0.0, *frame([1, 2, -1], [10.0, 30.0, 5.0], [5.0, math.nan, 1.0]), ego_speed_mps=10.0)
    s.add(0.1, *frame([1, 2], [8.0, 29.0], [1.5, math.nan]), ego_speed_mps=10.0)
    s.add(0.2, *frame([1, 2], [7.0, math.nan], [2.5, math.nan], ["", "below_horizon"]))
    s.add(0.3, *frame([1], [6.0], [1.0]), ego_speed_mps=0.2)  # too slow for a headway
    rows = {r["track_id"]: r for r in s.rows()}
    assert set(rows) == {1, 2}
    one, two = rows[1], rows[2]
    assert (one["first_s"], one["last_s"], one["frames"]) == (0.0, 0.3, 4)
    assert (one["min_distance_m"], one["min_distance_s"]) == (6.0, 0.3)
    assert one["min_ttc_s"] == 1.0
    assert (one["ttc_events"], one["first_event_s"]) == (2, 0.1)
    assert one["mean_headway_s"] == pytest.approx((1.0 + 0.8) / 2)
    assert (two["frames"], two["last_s"], two["min_distance_m"]) == (2, 0.1, 29.0)
    assert math.isnan(two["min_ttc_s"]) and two["ttc_events"] == 0
    path = s.write(tmp_path / "tracks.csv")
    with path.open(newline="") as fh:
        table = list(csv.DictReader(fh))
    assert tuple(table[0]) == TRACK_FIELDS
    assert table[1]["min_ttc_s"] == "" and table[1]["mean_headway_s"] == "2.95"


def test_a_ttc_event_needs_an_ok_row_confidently_below_the_threshold() -> None:
    s = TrackSummaries(ttc_threshold_s=2.0)
    # (ttc, σ, status): only 1.0 ± 0.5 (ok) is below 2 s at one σ; 1.5 ± 1.0 may be 2.5 s,
    # a TTC without σ says nothing sure, an upper bound's TTC is not a promise
    for k, (ttc, sigma, status) in enumerate(
        [
            (1.5, 1.0, "ok"),
            (1.8, np.nan, "ok"),
            (0.5, 0.1, "upper_bound"),
            (3.0, 0.2, "ok"),
            (1.0, 0.5, "ok"),
        ]
    ):
        reason = ["cut_bottom"] if status == "upper_bound" else None
        s.add(0.1 * k, *frame([1], [10.0 - k], [ttc], reason, [sigma], [status]))
    row = s.rows()[0]
    assert (row["ttc_events"], row["first_event_s"]) == (1, 0.4)
    assert row["min_ttc_s"] == 1.0 and row["frames"] == 4


def test_a_track_seen_only_as_upper_bounds_has_a_row(tmp_path: Path) -> None:
    s = TrackSummaries()
    ub = ["upper_bound", "upper_bound"]
    s.add(0.0, *frame([7, 8], [6.0, 20.0], [0.5, 3.0], ["cut_bottom", ""], status=[ub[0], "ok"]))
    s.add(0.1, *frame([7, 8], [5.0, 19.0], [0.5, 3.0], ["cut_bottom"] * 2, status=ub))
    s.add(0.2, *frame([7], [np.nan], [0.5], ["too_uncertain"], status=["missing"]))
    rows = {r["track_id"]: r for r in s.rows()}
    truck, car = rows[7], rows[8]
    assert (truck["frames"], truck["bound_frames"]) == (0, 2)
    assert (truck["min_distance_bound_m"], truck["min_distance_bound_s"]) == (5.0, 0.1)
    for name in ("first_s", "last_s", "min_distance_m", "min_distance_s", "min_ttc_s"):
        assert math.isnan(truck[name]), name  # no distance promised
    assert truck["ttc_events"] == 0
    assert (car["frames"], car["min_distance_m"], car["bound_frames"]) == (1, 20.0, 1)
    assert car["min_distance_bound_m"] == 19.0
    path = s.write(tmp_path / "tracks.csv")
    with path.open(newline="") as fh:
        table = list(csv.DictReader(fh))
    assert tuple(table[0])[: len(TRACK_FIELDS)] == TRACK_FIELDS
    assert table[0]["min_distance_m"] == "" and table[0]["min_distance_bound_m"] == "5"
    read = {int(r["track_id"]): r for r in read_tracks(path)}
    assert read[7]["bound_frames"] == 2 and math.isnan(read[7]["min_distance_m"])


def test_an_older_tracks_csv_without_the_bound_columns_reads(tmp_path: Path) -> None:
    path = tmp_path / "tracks.csv"
    old = TRACK_FIELDS[: TRACK_FIELDS.index("bound_frames")]
    path.write_text(",".join(old) + "\n1,0,1,2,3,4,,,0,\n")
    (row,) = read_tracks(path)
    assert row["min_distance_m"] == 3.0 and math.isnan(row["min_distance_bound_m"])
