"""What a report shows, whatever its source: :class:`ReportData` and its options."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.batch.fleet import FleetSummary
from slopedist.evaluation.kitti import KittiEvalConfig
from slopedist.evaluation.metrics import PooledScores, compact_names
from slopedist.streaming.tracks import TRACK_FIELDS


class SourceKind(str, Enum):
    """What ``slopedist report`` was pointed at."""

    KITTI_TRACKING = "kitti_tracking"
    RUN = "run"
    SYNTHETIC = "synthetic"
    """A ``slopedist demo`` output folder (the synthetic-hill suite)."""
    FLEET = "fleet"
    """A ``slopedist batch`` output folder (``status.csv`` and one run folder per drive)."""


NEAR_DISTANCE_M = 10.0
"""Default distance threshold of the per-track table's "time closer than" column, metres
(the two-second rule's gap at 18 km/h: a car this close is followed closely at town speeds).
Without the ego speed in the records, a headway in seconds cannot be computed per frame."""


@dataclass
class ReportOptions:
    """Options of a report (KITTI options are those of :class:`KittiEvalConfig`).

    Attributes:
        eval: the KITTI evaluation configuration; ``eval.methods`` empty = every method that
            can run (``depthmap`` only with ``eval.depth_dir``).
        methods: methods to keep when reading run outputs (None = all found).
        tracks: ``(sequence, track_id)`` pairs to plot over time (None = the longest track of
            each of the ``n_tracks`` sequences with the longest tracks).
        n_tracks: number of tracks chosen automatically.
        title: page title (None: :func:`default_title`, what the page holds).
        near_m: the per-track table's distance threshold: how long each track was closer
            than this, metres.
    """

    eval: KittiEvalConfig = field(default_factory=lambda: KittiEvalConfig(methods=()))
    methods: Sequence[str] | None = None
    tracks: Sequence[tuple[str, int]] | None = None
    n_tracks: int = 4
    title: str | None = None
    near_m: float = NEAR_DISTANCE_M


@dataclass
class Columns:
    """A column-oriented table (name → list of values), appended to row by row."""

    names: tuple[str, ...]
    data: dict[str, list[Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for n in self.names:
            self.data.setdefault(n, [])

    def add(self, **row: Any) -> None:
        """Append one row (absent columns get NaN)."""
        for n in self.names:
            self.data[n].append(row.get(n, math.nan))

    def __len__(self) -> int:
        return len(self.data[self.names[0]]) if self.names else 0

    def array(self, name: str, dtype: Any = float) -> NDArray[Any]:
        """Column ``name`` as an array."""
        return np.asarray(self.data[name], dtype=dtype)

    def records(self) -> list[dict[str, Any]]:
        """The rows as ``{column: value}`` records."""
        return [{n: self.data[n][i] for n in self.names} for i in range(len(self))]


RECORD_COLUMNS = (
    "sequence",
    "frame",
    "timestamp_s",
    "track_id",
    "method",
    "rotation",
    "distance_m",
    "gt_distance_m",
    "scored",
    "reason",
    "theta_deg",
    "sigma_m",
    "ttc_s",
    "bound_m",
)
"""Columns of the report's ``records.csv`` (one row per target, frame and method; metres,
seconds, degrees). ``distance_m`` is capped by the KITTI rule where the records are scored
against a truth (and empty for an upper bound); ``sigma_m`` is a method's own 1σ of it,
``ttc_s`` its time to collision (seconds), ``bound_m`` the distance of an ``upper_bound``
record (the true one is at most this)."""
TRACK_COLUMNS = ("sequence", "method", *TRACK_FIELDS)
"""Columns of the per-track summaries of run outputs (``tracks.csv`` of each run, see
:mod:`slopedist.streaming.tracks`, with its sequence and method)."""
THETA_COLUMNS = ("sequence", "frame", "timestamp_s", "source", "theta_deg")
"""Columns of the report's ``theta.csv`` (ego gradient per frame and rotation source, degrees)."""


@dataclass
class ReportData:
    """Everything the report shows, source-independent.

    Attributes:
        scores: every method's summaries per sequence, pooled over its own sequences and over
            the common ones (:class:`~slopedist.evaluation.metrics.PooledScores`).
        timing: ``{method: {"odometry_ms", "estimation_ms", "depth_ms", "frames"}}``.
        records: per-target rows (:data:`RECORD_COLUMNS`).
        theta: per-frame ego gradients of each rotation source (:data:`THETA_COLUMNS`).
        protocol: the JSON block that says how the numbers were made.
        notes: lines shown under the title.
        warnings: what a reader of the printed tables must know (a partial run), also in
            ``notes``; the command prints them.
        truth_source: name of the rotation source taken as θ truth (``"oxts"``), if any.
        has_truth: whether the records carry a ground-truth distance.
        tracks: per-track summaries of run outputs (:data:`TRACK_COLUMNS`), or None.
        fleet: the fleet tables of a batch output (per drive, pooled, by range, safety), or
            None.
        batch_status: the rows of a batch output's ``status.csv`` (``drive``, ``status``,
            ``error``, ``frames``, ...), or None.
        references: ``{method: point of the vehicle its distances refer to}`` (``centre``,
            ``nearest_face``, ``contact``; several joined by ``/``), where the records say.
        near_m: the per-track table's distance threshold, metres.
    """

    title: str
    source: Path
    kind: SourceKind
    scores: PooledScores
    timing: dict[str, dict[str, float]]
    records: Columns
    theta: Columns
    protocol: dict[str, Any]
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    truth_source: str | None = None
    has_truth: bool = True
    tracks: Columns | None = None
    fleet: FleetSummary | None = None
    batch_status: list[dict[str, str]] | None = None
    references: dict[str, str] = field(default_factory=dict)
    near_m: float = NEAR_DISTANCE_M

    @property
    def methods(self) -> list[str]:
        """The methods, in table order."""
        return self.scores.methods

    @property
    def sequences(self) -> list[str]:
        """The sequences (or scenarios), in table order."""
        return self.scores.sequences

    @property
    def summaries(self) -> dict[str, dict[str, dict[str, Any]]]:
        """``{sequence: {method: summary}}``."""
        return self.scores.summaries

    @property
    def overall(self) -> dict[str, dict[str, Any]]:
        """``{method: summary}`` pooled over the sequences each method ran on."""
        return self.scores.overall

    @property
    def pooled(self) -> dict[str, list[str]]:
        """``{method: sequences it ran on}``."""
        return self.scores.pooled

    @property
    def common(self) -> dict[str, Any] | None:
        """Every method pooled over the sequences all of them ran on, when those differ."""
        return self.scores.common

    def truth_name(self) -> str:
        """Words for the θ truth source: the OXTS (IMU) truth, or the true θ of a simulation."""
        if self.truth_source == "truth":
            return "the true θ" + (
                " of the simulation" if self.kind is SourceKind.SYNTHETIC else ""
            )
        return f"the {self.truth_source} (IMU) truth"


SOURCE_WORDS = {
    SourceKind.KITTI_TRACKING: "a KITTI tracking folder",
    SourceKind.RUN: "`slopedist run` output (records.csv, frames.csv)",
    SourceKind.SYNTHETIC: "`slopedist demo` output (synthetic hills)",
    SourceKind.FLEET: "`slopedist batch` output",
}
"""What each kind of source is, in words for the report's first line."""


def default_title(kind: SourceKind, sequences: Sequence[str], methods: Sequence[str]) -> str:
    """A page title that says what the page holds: ``Run report: <sequences>`` for runs of one
    method, ``Method comparison: <sequences>`` for several; the KITTI, demo and batch pages by
    their source."""
    if kind is SourceKind.KITTI_TRACKING:
        return "Method comparison on KITTI tracking"
    if kind is SourceKind.SYNTHETIC:
        return "Method comparison on the synthetic hills (slopedist demo)"
    if kind is SourceKind.FLEET:
        return f"Fleet report: {len(sequences)} drive{'s' * (len(sequences) != 1)}"
    what = "Run report" if len(methods) == 1 else "Method comparison"
    return f"{what}: {compact_names(list(sequences))}"
