"""Per-track summary of a run (``tracks.csv``): when a target was seen, how close it came, how
soon it could have been hit.

Accumulated frame by frame in constant memory per track (:class:`TrackSummaries`), written at
the end of a run. The distances and TTCs are those of ``ok`` estimates; the ``upper_bound``
ones (a box cut by the image, e.g. a truck right in front) count apart, as bounds; ``missing``
ones not at all. Boxes without a track id are not summarised.

Columns (:data:`TRACK_FIELDS`): ``track_id``; ``first_s`` / ``last_s``: first and last frame
time with a distance, seconds; ``frames``: frames with a distance; ``min_distance_m`` and the
time it happened ``min_distance_s``; ``min_ttc_s``: smallest positive time-to-collision
(seconds; empty when the method gives none, e.g. every method but ``ours``); ``mean_headway_s``:
mean of distance over ego speed (seconds) over the frames where the ego speed is known and above
:data:`MIN_EGO_SPEED_MPS` (empty without an ego speed); ``ttc_events``: how many times the TTC
fell confidently below the threshold (:func:`confidently_below`; an event starts when a frame
confidently below follows one that was not); ``first_event_s``, the time of the first;
``bound_frames``: frames with only an upper bound; ``min_distance_bound_m``: the least of those
bounds (the track came at most this close in those frames), at ``min_distance_bound_s``. A track
seen only as upper bounds has a row: ``frames`` 0, the distance, time and TTC columns empty,
the bound columns filled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from slopedist.core.errors import InputFileError
from slopedist.core.limits import MAX_RECORD_MAGNITUDE
from slopedist.core.textfiles import CsvRows, number_cell
from slopedist.estimators.base import EstimateStatus, FrameEstimates
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.formatting import write_csv

TRACKS_NAME = "tracks.csv"
"""File name of the summary in a run's output folder."""

TTC_THRESHOLD_S = 2.0
"""Default time-to-collision below which a track has an event, seconds."""

MIN_EGO_SPEED_MPS = 0.5
"""Ego speed below which the headway time (distance / speed) is not averaged, m/s."""

TRACK_FIELDS = (
    "track_id",
    "first_s",
    "last_s",
    "frames",
    "min_distance_m",
    "min_distance_s",
    "min_ttc_s",
    "mean_headway_s",
    "ttc_events",
    "first_event_s",
    "bound_frames",
    "min_distance_bound_m",
    "min_distance_bound_s",
)
"""Columns of ``tracks.csv``."""

BOUND_FIELDS = ("bound_frames", "min_distance_bound_m", "min_distance_bound_s")
"""The columns of the ``upper_bound`` estimates (appended; an older ``tracks.csv`` has none)."""


def confidently_below(ttc_s: float, ttc_sigma_s: float, threshold_s: float) -> bool:
    """Whether a positive time-to-collision ``ttc_s`` is below ``threshold_s`` at one σ: the
    TTC one ``ttc_sigma_s`` later still is (about 84 % sure for a Gaussian error). A TTC
    without a finite σ is not confident; seconds."""
    return (
        math.isfinite(ttc_s)
        and math.isfinite(ttc_sigma_s)
        and ttc_s > 0
        and ttc_s + max(ttc_sigma_s, 0.0) < threshold_s
    )


@dataclass
class _Track:
    first_s: float = math.nan
    last_s: float = math.nan
    frames: int = 0
    min_distance_m: float = math.inf
    min_distance_s: float = math.nan
    min_ttc_s: float = math.inf
    headway_sum_s: float = 0.0
    headway_count: int = 0
    events: int = 0
    first_event_s: float = math.nan
    below: bool = False
    bound_frames: int = 0
    min_bound_m: float = math.inf
    min_bound_s: float = math.nan

    def add(self, t_s: float, distance_m: float, ttc_s: float, ego_speed_mps: float) -> None:
        if not self.frames:
            self.first_s = t_s
        self.last_s = t_s
        self.frames += 1
        if distance_m < self.min_distance_m:
            self.min_distance_m, self.min_distance_s = distance_m, t_s
        if math.isfinite(ego_speed_mps) and ego_speed_mps > MIN_EGO_SPEED_MPS:
            self.headway_sum_s += distance_m / ego_speed_mps
            self.headway_count += 1
        if math.isfinite(ttc_s) and ttc_s > 0:
            self.min_ttc_s = min(self.min_ttc_s, ttc_s)

    def add_bound(self, t_s: float, bound_m: float) -> None:
        self.bound_frames += 1
        if bound_m < self.min_bound_m:
            self.min_bound_m, self.min_bound_s = bound_m, t_s

    def ttc_state(self, t_s: float, below: bool) -> None:
        if below and not self.below:
            self.events += 1
            if self.events == 1:
                self.first_event_s = t_s
        self.below = below

    def row(self, track_id: int) -> dict[str, Any]:
        return {
            "track_id": track_id,
            "first_s": self.first_s,
            "last_s": self.last_s,
            "frames": self.frames,
            "min_distance_m": self.min_distance_m if self.frames else math.nan,
            "min_distance_s": self.min_distance_s,
            "min_ttc_s": self.min_ttc_s if math.isfinite(self.min_ttc_s) else math.nan,
            "mean_headway_s": (
                self.headway_sum_s / self.headway_count if self.headway_count else math.nan
            ),
            "ttc_events": self.events,
            "first_event_s": self.first_event_s,
            "bound_frames": self.bound_frames,
            "min_distance_bound_m": self.min_bound_m if self.bound_frames else math.nan,
            "min_distance_bound_s": self.min_bound_s,
        }


class TrackSummaries:
    """Running per-track summaries (see the module docstring).

    Args:
        ttc_threshold_s: TTC below which a track has an event, seconds.
    """

    def __init__(self, ttc_threshold_s: float = TTC_THRESHOLD_S) -> None:
        self.ttc_threshold_s = ttc_threshold_s
        self.tracks: dict[int, _Track] = {}

    def add(
        self,
        timestamp_s: float,
        boxes: BoxTable,
        estimates: FrameEstimates,
        ego_speed_mps: float = math.nan,
    ) -> None:
        """One frame's estimates (``ego_speed_mps``: the ego vehicle's speed, m/s, if known).
        A method without a ``ttc_sigma_s`` column states its TTC as exact (σ 0)."""
        n = len(boxes)
        ttc = estimates.extra.get("ttc_s", np.full(n, np.nan))
        ttc_sigma = estimates.extra.get("ttc_sigma_s", np.zeros(n))
        for i in range(n):
            tid = int(boxes.track_id[i])
            z = float(estimates.distance_m[i])
            status = estimates.status[i]
            if tid < 0 or not math.isfinite(z):
                continue
            if status == EstimateStatus.UPPER_BOUND.value:
                self.tracks.setdefault(tid, _Track()).add_bound(timestamp_s, z)
                continue
            if status != EstimateStatus.OK.value:
                continue
            track = self.tracks.setdefault(tid, _Track())
            t_i = float(ttc[i])
            track.add(timestamp_s, z, t_i, ego_speed_mps)
            below = confidently_below(t_i, float(ttc_sigma[i]), self.ttc_threshold_s)
            track.ttc_state(timestamp_s, below)

    def rows(self) -> list[dict[str, Any]]:
        """One row per track (:data:`TRACK_FIELDS`), by track id."""
        return [self.tracks[t].row(t) for t in sorted(self.tracks)]

    def write(self, path: str | Path) -> Path:
        """Write ``tracks.csv`` (via :func:`slopedist.io.formatting.write_csv`)."""
        return write_csv(path, self.rows(), TRACK_FIELDS)


def read_tracks(path: Path) -> list[dict[str, float]]:
    """The rows of a run's ``tracks.csv`` as numbers (NaN where empty or, for the
    :data:`BOUND_FIELDS` of an older file, absent); no file = no tracks.

    Raises:
        InputFileError: bad UTF-8, a broken row, a missing column, or a cell that is not a
            number, infinite or beyond ±:data:`~slopedist.core.limits.MAX_RECORD_MAGNITUDE`
            (naming file, line and field).
    """
    if not path.is_file():
        return []
    table = CsvRows(path, "track summary", strict=True)
    absent = [c for c in TRACK_FIELDS if c not in table.header and c not in BOUND_FIELDS]
    if absent:
        raise InputFileError(path, f"missing column(s) {', '.join(absent)}", line=1)
    return [
        {
            k: number_cell(row.get(k), path, line, k, bound=MAX_RECORD_MAGNITUDE)
            for k in TRACK_FIELDS
        }
        for line, row in table
    ]
