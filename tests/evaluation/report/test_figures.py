"""The report's figures: a track's records become one distance series on its own time axis,
drawn by the same panel as the demo's plots."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from slopedist.core.errors import ConfigurationError
from slopedist.evaluation.report import ReportOptions, report_data
from slopedist.evaluation.report.figures import choose_tracks, figure_tracks, track_series
from tests.evaluation.report.test_report import _record, write_run


def test_track_series_aligns_methods_on_the_track_times(tmp_path: Path) -> None:
    rows = [_record(0, 10.0, 11.0), _record(2, "", 30.0, "below_horizon"), _record(3, 95.0, 70.0)]
    flat = _record(2, 29.0, 30.0)
    flat["method"] = "flat"
    write_run(tmp_path / "seq", [*rows, flat], [{"frame": 0, "estimation_ms": 1.0}])
    data = report_data(tmp_path / "seq", ReportOptions())
    t_s, series = track_series(data, "seq", 3)
    np.testing.assert_allclose(t_s, [0.0, 0.2, 0.3])
    np.testing.assert_allclose(series.truth, [11.0, 30.0, 70.0])
    # the cap rule: below the horizon and above 80 m both count as 80 m
    np.testing.assert_allclose(series.estimates["paper"], [10.0, 80.0, 80.0])
    assert math.isnan(series.estimates["flat"][0]) and series.estimates["flat"][1] == 29.0
    assert series.below_horizon["paper"].tolist() == [False, True, False]
    figure = figure_tracks(data, [("seq", 3)])
    assert figure is not None and figure.png.startswith(b"\x89PNG")
    with pytest.raises(ConfigurationError, match="track 4 of sequence seq"):
        track_series(data, "seq", 4)


def test_chosen_track_has_something_to_draw_in_a_run_without_truth(tmp_path: Path) -> None:
    # track 0: the longest, but every record an upper bound (no distance in the report) and no
    # truth column; its panel would be empty. Track 5 has estimates in two frames.
    bounds = [
        {
            **_record(k, 5.0, math.nan),
            "track_id": 0,
            "status": "upper_bound",
            "reason": "cut_bottom",
        }
        for k in range(3)
    ]
    ok = [{**_record(k, 20.0 + k, math.nan), "track_id": 5} for k in range(2)]
    for row in (*bounds, *ok):
        del row["gt_distance_m"]
    write_run(tmp_path / "seq", [*bounds, *ok], [{"frame": 0, "estimation_ms": 1.0}], extra=())
    data = report_data(tmp_path / "seq", ReportOptions())
    assert choose_tracks(data, 4) == [("seq", 5)]


@pytest.mark.parametrize("reason", ["near_horizon", "beyond_resolution"])
def test_a_near_horizon_record_is_marked_as_counted_at_the_cap(tmp_path: Path, reason: str) -> None:
    # near_horizon and beyond_resolution are scored at the 80 m cap like below_horizon; the
    # figure marks them all
    rows = [_record(0, 10.0, 11.0), _record(1, "", 30.0, reason)]
    write_run(tmp_path / "seq", rows, [{"frame": 0, "estimation_ms": 1.0}])
    _, series = track_series(report_data(tmp_path / "seq", ReportOptions()), "seq", 3)
    np.testing.assert_allclose(series.estimates["paper"], [10.0, 80.0])
    assert series.below_horizon["paper"].tolist() == [False, True]
