"""The report's per-track view of run outputs, read from the records themselves (so it needs
no truth): for each track of each sequence and method, when it was seen, how close it came
(with the method's own 1σ there), how long it stayed closer than a distance threshold, the
least time to collision, and the least upper bound; and the leading tracks, which the page
plots one by one.

Without the ego speed in the records a headway in seconds cannot be taken frame by frame, so
the threshold is a distance (:data:`~slopedist.evaluation.report.data.NEAR_DISTANCE_M` by
default, ``slopedist report --near``); a run made with an ego speed (``--speed-topic``) adds its
mean headway from the run's ``tracks.csv``. Seconds from the start of the run, metres.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from slopedist.evaluation.report.data import ReportData
from slopedist.evaluation.table import Table

TRACK_TABLE_ROWS = 20
"""Tracks listed in the report's track table (the best-ranked; every record is in the
report's ``records.csv``)."""

MIN_PLOTTED_ESTIMATES = 5
"""Distances (records of status ``ok``) a track needs to get its own plot."""


@dataclass(frozen=True)
class TrackSummary:
    """One track of one sequence and method (seconds, metres; NaN where there is none).

    Attributes:
        first_s, last_s: the first and last time the track had a box.
        estimates: records with a distance (status ``ok``); bounds: with an upper bound.
        closest_m: the least of those distances, at ``closest_s``, with the method's own 1σ
            there (``closest_sigma_m``).
        near_s: how long the track was closer than the report's threshold: its distances and
            upper bounds below it times the sequence's frame step.
        least_ttc_s: the smallest positive time to collision the method gave.
        bound_m: the least ``upper_bound`` (the track came at most this close then).
        headway_s: the mean headway (distance over ego speed) of the run's ``tracks.csv``.
    """

    sequence: str
    method: str
    track_id: int
    first_s: float
    last_s: float
    estimates: int
    bounds: int
    closest_m: float
    closest_sigma_m: float
    closest_s: float
    near_s: float
    least_ttc_s: float
    bound_m: float
    headway_s: float = math.nan


def frame_step_s(times_s: NDArray[np.float64]) -> float:
    """The frame step of a sequence: the median step between its distinct record times
    (seconds; NaN with fewer than two)."""
    t = np.unique(times_s[np.isfinite(times_s)])
    return float(np.median(np.diff(t))) if t.size > 1 else math.nan


def _least(values: NDArray[np.float64]) -> float:
    finite = values[np.isfinite(values)]
    return float(finite.min()) if finite.size else math.nan


def _summary(
    data: ReportData, key: tuple[str, str, int], rows: NDArray[np.intp], step_s: float
) -> TrackSummary:
    rec = data.records
    t = rec.array("timestamp_s")[rows]
    d = rec.array("distance_m")[rows]
    sigma = rec.array("sigma_m")[rows]
    ttc = rec.array("ttc_s")[rows]
    bound = rec.array("bound_m")[rows]
    ok = np.isfinite(d)
    at = int(np.argmin(np.where(ok, d, np.inf))) if ok.any() else -1
    near = int(np.sum(np.fmin(d, bound) < data.near_m))  # a bound below it: surely nearer
    return TrackSummary(
        *key,
        first_s=_least(t),
        last_s=-_least(-t),
        estimates=int(ok.sum()),
        bounds=int(np.isfinite(bound).sum()),
        closest_m=float(d[at]) if at >= 0 else math.nan,
        closest_sigma_m=float(sigma[at]) if at >= 0 else math.nan,
        closest_s=float(t[at]) if at >= 0 else math.nan,
        near_s=near * step_s if near else 0.0,
        least_ttc_s=_least(np.where(ttc > 0, ttc, np.nan)),
        bound_m=_least(bound),
    )


def _headways(data: ReportData) -> dict[tuple[str, str, int], float]:
    """``{(sequence, method, track): mean headway}`` of the runs' ``tracks.csv``, seconds."""
    if data.tracks is None:
        return {}
    return {
        (r["sequence"], r["method"], int(r["track_id"])): float(r["mean_headway_s"])
        for r in data.tracks.records()
    }


def track_summaries(data: ReportData) -> list[TrackSummary]:
    """Every track (records with a track id) of every sequence and method, ranked: the tracks
    seen for at least :data:`MIN_PLOTTED_ESTIMATES` frames with a distance or a bound first;
    among them the longest closer than the threshold, then the closest (distance or bound)."""
    rec = data.records
    seq = rec.array("sequence", object)
    method = rec.array("method", object)
    tid = rec.array("track_id", int)
    groups: dict[tuple[str, str, int], list[int]] = {}
    for i in np.flatnonzero(tid >= 0):
        groups.setdefault((str(seq[i]), str(method[i]), int(tid[i])), []).append(int(i))
    times = rec.array("timestamp_s")
    steps = {s: frame_step_s(times[seq == s]) for s in {k[0] for k in groups}}
    headways = _headways(data)
    out = []
    for key, rows in groups.items():
        summary = _summary(data, key, np.asarray(rows, dtype=np.intp), steps[key[0]])
        headway = headways.get(key, math.nan)
        out.append(summary if math.isnan(headway) else replace(summary, headway_s=headway))
    return sorted(out, key=_rank)


def _nan_last(x: float) -> float:
    return x if math.isfinite(x) else math.inf


def _followed(s: TrackSummary) -> bool:
    """Whether a track was seen long enough to rank and plot (a box seen in a frame or two is
    a car passing by, or a detector's flicker)."""
    return s.estimates + s.bounds >= MIN_PLOTTED_ESTIMATES


def _rank(s: TrackSummary) -> tuple[bool, float, float, float, str, str, int]:
    near = s.near_s if math.isfinite(s.near_s) else 0.0
    closest = min(_nan_last(s.closest_m), _nan_last(s.bound_m))
    return (not _followed(s), -near, closest, -s.estimates, s.sequence, s.method, s.track_id)


def leading_tracks(data: ReportData, n: int) -> list[tuple[str, int]]:
    """The ``n`` best-ranked tracks (:func:`track_summaries`) with at least
    :data:`MIN_PLOTTED_ESTIMATES` distances or bounds, as ``(sequence, track_id)``: the ones
    followed closely for longest, then the closest. Whether a track is in the ego lane is not
    in the records, so a car passed close beside can rank high; ``slopedist report --tracks``
    chooses others."""
    chosen: list[tuple[str, int]] = []
    for s in track_summaries(data):
        pair = (s.sequence, s.track_id)
        if _followed(s) and pair not in chosen:
            chosen.append(pair)
    return chosen[:n]


@dataclass(frozen=True)
class _Column:
    header: str
    value: str
    format: str = ".2f"


def _columns(data: ReportData, summaries: Sequence[TrackSummary]) -> list[_Column]:
    """The table's columns: sequence and method only when there are several, the 1σ, TTC,
    bound and headway columns only when some track has one."""

    def some(name: str) -> bool:
        return any(math.isfinite(getattr(s, name)) for s in summaries)

    columns = [
        *([_Column("sequence", "sequence", "")] if len(data.sequences) > 1 else []),
        *([_Column("method", "method", "")] if len(data.methods) > 1 else []),
        _Column("track", "track_id", "d"),
        _Column("first seen (s)", "first_s", ".1f"),
        _Column("last seen (s)", "last_s", ".1f"),
        _Column("frames estimated", "estimates", "d"),
        _Column("closest (m)", "closest_m"),
        *([_Column("1σ there (m)", "closest_sigma_m")] if some("closest_sigma_m") else []),
        _Column("at (s)", "closest_s", ".1f"),
        _Column(f"time < {data.near_m:g} m (s)", "near_s", ".1f"),
        *([_Column("least TTC (s)", "least_ttc_s", ".1f")] if some("least_ttc_s") else []),
        *([_Column("closest bound (m)", "bound_m")] if some("bound_m") else []),
        *([_Column("mean headway (s)", "headway_s")] if some("headway_s") else []),
    ]
    return columns


def _note(data: ReportData, summaries: Sequence[TrackSummary], columns: list[_Column]) -> str:
    shown = {c.value for c in columns}
    steps = {s.sequence for s in summaries}
    step = frame_step_s(data.records.array("timestamp_s")) if len(steps) == 1 else math.nan
    parts = [
        f"Tracks seen in fewer than {MIN_PLOTTED_ESTIMATES} frames are listed last. "
        "Seconds from the start of the run, metres. Seen: the first and last frame with a box "
        "of the track; frames estimated: its frames with a distance (status ok); closest: the "
        "least of them"
        + (", with the method's own 1σ there" if "closest_sigma_m" in shown else "")
        + ".",
        f"Time < {data.near_m:g} m: its distances and upper bounds below {data.near_m:g} m "
        "times the frame step"
        + (f" ({step:.3g} s)" if math.isfinite(step) else "")
        + "; `slopedist report --near` sets the threshold.",
    ]
    if "least_ttc_s" in shown:
        parts.append("Least TTC: the smallest positive time to collision (methods that give one).")
    if "bound_m" in shown:
        parts.append(
            "Closest bound: the least upper bound, for a box cut by the bottom of the image "
            "(the vehicle was at most this far)."
        )
    if "headway_s" in shown:
        parts.append("Mean headway: distance over the ego speed, from the run's tracks.csv.")
    return " ".join(parts)


def tracks_table(data: ReportData) -> Table | None:
    """The per-track table of run outputs (:func:`track_summaries`), best-ranked first."""
    summaries = track_summaries(data)
    if not summaries:
        return None
    shown = summaries[:TRACK_TABLE_ROWS]
    columns = _columns(data, summaries)
    rows = [[getattr(s, c.value) for c in columns] for s in shown]
    count = (
        f"{len(shown)} of {len(summaries)}" if len(shown) < len(summaries) else f"all {len(shown)}"
    )
    return Table(
        "tracks",
        f"Tracks ({count}): longest closer than {data.near_m:g} m first, then the closest",
        [c.header for c in columns],
        rows,
        [[False] * len(columns) for _ in shown],
        _note(data, summaries, columns),
        {j: c.format for j, c in enumerate(columns) if c.format},
    )
