"""Per-track safety summaries across a fleet: each drive's ``tracks.csv`` (see
:mod:`slopedist.streaming.tracks`) gathered per drive and pooled per method.

Per drive (and its method): the drive's duration (seconds, first to last frame time of its
``frames.csv``), the tracks with a distance, the smallest distance of any track (metres), the
smallest time-to-collision (seconds; only methods that estimate one, e.g. ``ours``), the tracks
with at least one TTC event and the events (the TTC fell below the run's threshold, 2 s by
default), the events per hour of driving, and the tracks whose mean headway time (distance
over ego speed, seconds; only runs with an ego speed) is below :data:`SHORT_HEADWAY_S`, with
the smallest mean headway. Pooled per method: the same over every drive of the method, and
the drive where the smallest TTC happened. Empty cells (NaN) where no track gave the number.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from slopedist.batch.stamp import SETTINGS_KEY
from slopedist.core.limits import MAX_RECORD_MAGNITUDE
from slopedist.core.textfiles import CsvRows, number_cell, read_json
from slopedist.streaming.config import FRAMES_NAME, SUMMARY_NAME
from slopedist.streaming.tracks import TRACKS_NAME, read_tracks

SHORT_HEADWAY_S = 1.0
"""Mean headway time below which a track counts as a short headway, seconds (half the
two-second rule)."""

SECONDS_PER_HOUR = 3600.0

SAFETY_FIELDS = (
    "duration_s",
    "tracks",
    "min_distance_m",
    "min_ttc_s",
    "ttc_tracks",
    "ttc_events",
    "ttc_events_per_h",
    "short_headway_tracks",
    "min_headway_s",
)
"""Safety columns shared by the per-drive and the pooled rows."""

DRIVE_SAFETY_FIELDS = ("drive", "method", *SAFETY_FIELDS)
"""Columns of ``fleet/safety.csv`` (one row per drive)."""

POOLED_SAFETY_FIELDS = ("method", "drives", *SAFETY_FIELDS, "min_ttc_drive")
"""Columns of ``fleet/safety_pooled.csv`` (one row per method)."""


def _finite_min(values: Iterable[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return min(finite) if finite else math.nan


def _per_hour(count: float, duration_s: float) -> float:
    return count * SECONDS_PER_HOUR / duration_s if duration_s > 0 else math.nan


def drive_duration_s(folder: Path) -> float:
    """Seconds from the first to the last frame time of a run's ``frames.csv`` (NaN without
    times)."""
    path = folder / FRAMES_NAME
    if not path.is_file():
        return math.nan
    first = last = math.nan
    for line, row in CsvRows(path, "frame log"):
        t = number_cell(row.get("timestamp_s"), path, line, "timestamp_s", MAX_RECORD_MAGNITUDE)
        if math.isfinite(t):
            first = t if math.isnan(first) else first
            last = t
    return last - first


def safety_values(
    tracks: Sequence[dict[str, float]], duration_s: float, short_headway_s: float
) -> dict[str, Any]:
    """The :data:`SAFETY_FIELDS` of a set of track rows over ``duration_s`` seconds."""
    events = int(sum(t["ttc_events"] for t in tracks if math.isfinite(t["ttc_events"])))
    headways = [t["mean_headway_s"] for t in tracks]
    return {
        "duration_s": duration_s,
        "tracks": sum(t["frames"] > 0 for t in tracks),  # not those seen only as bounds
        "min_distance_m": _finite_min(t["min_distance_m"] for t in tracks),
        "min_ttc_s": _finite_min(t["min_ttc_s"] for t in tracks),
        "ttc_tracks": sum(t["ttc_events"] > 0 for t in tracks),
        "ttc_events": events,
        "ttc_events_per_h": _per_hour(events, duration_s),
        "short_headway_tracks": sum(h < short_headway_s for h in headways),
        "min_headway_s": _finite_min(headways),
    }


def fleet_method(summary: Any, method: str) -> str:
    """The name under which a drive's ``method`` appears in the fleet tables: the method, or
    ``method@reference`` for a drive run at a reference point it was given (its ``run.json``
    ``batch_drive`` ``reference``, e.g. ``ours@nearest_face``), so that no row pools
    distances to different points of the vehicles."""
    options = summary.get(SETTINGS_KEY) if isinstance(summary, dict) else None
    reference = options.get("reference") if isinstance(options, dict) else None
    return f"{method}@{reference}" if reference else method


def fleet_base_method(name: str) -> str:
    """The method of a fleet-table name of :func:`fleet_method` (``ours@nearest_face``:
    ``ours``)."""
    return name.split("@", 1)[0]


def drive_safety(folder: Path, short_headway_s: float = SHORT_HEADWAY_S) -> dict[str, Any]:
    """The safety row of one complete run folder (its method from ``run.json``, named by
    :func:`fleet_method`)."""
    summary = read_json(folder / SUMMARY_NAME, "run summary")
    method = str(summary.get("method") or "") if isinstance(summary, dict) else ""
    method = fleet_method(summary, method)
    tracks = read_tracks(folder / TRACKS_NAME)
    return {
        "drive": folder.name,
        "method": method,
        "_tracks": tracks,
        **safety_values(tracks, drive_duration_s(folder), short_headway_s),
    }


def pooled_safety(
    drive_rows: Sequence[dict[str, Any]], short_headway_s: float = SHORT_HEADWAY_S
) -> list[dict[str, Any]]:
    """One pooled row per method over the :func:`drive_safety` rows (which keep their track
    rows under ``_tracks``)."""
    out = []
    for method in sorted({r["method"] for r in drive_rows}):
        mine = [r for r in drive_rows if r["method"] == method]
        tracks = [t for r in mine for t in r["_tracks"]]
        duration = sum(r["duration_s"] for r in mine if math.isfinite(r["duration_s"]))
        values = safety_values(tracks, duration, short_headway_s)
        worst = min(
            (r for r in mine if math.isfinite(r["min_ttc_s"])),
            key=lambda r: r["min_ttc_s"],
            default=None,
        )
        out.append(
            {
                "method": method,
                "drives": len(mine),
                **values,
                "min_ttc_drive": worst["drive"] if worst is not None else "",
            }
        )
    return out


def fleet_safety(
    folders: Sequence[Path], short_headway_s: float = SHORT_HEADWAY_S
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Per-drive and pooled safety rows of the complete run folders of a batch."""
    rows = [drive_safety(f, short_headway_s) for f in folders]
    pooled = pooled_safety(rows, short_headway_s)
    return [{k: r[k] for k in DRIVE_SAFETY_FIELDS} for r in rows], pooled
