"""Per-track summaries, hand-computed: first/last time, closest distance, TTC and its events,
headway."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from slopedist.detections.boxes import BoxTable
from slopedist.estimators.base import FrameEstimates
from slopedist.tracks import TRACK_FIELDS, TrackSummaries


def frame(track_ids: list[int], distances: list[float], ttc: list[float], reasons=None):
    n = len(track_ids)
    boxes = BoxTable.build(np.zeros(n), np.tile([0.0, 0.0, 10.0, 10.0], (n, 1)), track_ids)
    est = FrameEstimates(
        np.zeros(n),
        np.zeros(n),
        np.zeros(n),
        np.zeros(n),
        np.array(distances, dtype=float),
        np.array(reasons or [""] * n, dtype=object),
        np.array(["contact"] * n, dtype=object),
        {"ttc_s": np.array(ttc, dtype=float)},
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
