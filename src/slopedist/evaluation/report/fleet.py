"""The fleet report of a ``slopedist batch`` output folder (``status.csv`` and one run folder
per drive): the run report of its complete drives (each drive one sequence of Table 1), plus
the batch status, the fleet accuracy tables (per drive and pooled where the records carry the
truth, and the error by true-distance range) and the per-track safety summaries per drive and
pooled (:func:`slopedist.batch.fleet_summary`). Metres, seconds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from slopedist.batch.fleet import METRICS, FleetSummary, batch_drive_folders, fleet_summary
from slopedist.batch.safety import SAFETY_FIELDS, SHORT_HEADWAY_S, fleet_base_method
from slopedist.batch.status import STATUS_NAME, DriveStatus
from slopedist.core.errors import InputFileError, MissingInputError
from slopedist.core.textfiles import CsvRows
from slopedist.evaluation.report.data import (
    ReportData,
    ReportOptions,
    SourceKind,
    default_title,
)
from slopedist.evaluation.report.runs import run_report_data
from slopedist.evaluation.table import Table, best_marks

FAILED_ROWS = 20
"""Failed drives listed in the report's status table (all are in ``status.csv``)."""

_METRIC_HEADERS = ("n", "RMSE", "MAE", "AbsRel", "δ<1.25")
_SAFETY_HEADERS = {
    "duration_s": "hours",
    "tracks": "tracks",
    "min_distance_m": "min dist (m)",
    "min_ttc_s": "min TTC (s)",
    "ttc_tracks": "tracks with TTC events",
    "ttc_events": "TTC events",
    "ttc_events_per_h": "events / h",
    "short_headway_tracks": "short-headway tracks",
    "min_headway_s": "min headway (s)",
}
"""Column header of each safety field (:data:`~slopedist.batch.safety.SAFETY_FIELDS`)."""
_SAFETY_FORMATS = {1: "d", 4: "d", 5: "d", 7: "d", 0: ".2f", 2: ".1f", 3: ".2f", 6: ".2f"}


def is_batch_output(path: Path) -> bool:
    """Whether ``path`` is a ``slopedist batch`` output (it has ``status.csv``)."""
    return (path / STATUS_NAME).is_file()


def read_status(out_dir: Path) -> list[dict[str, str]]:
    """The rows of a batch's ``status.csv`` (every cell as text).

    Raises:
        InputFileError: a broken row, bad UTF-8 or no ``drive`` / ``status`` column.
    """
    table = CsvRows(out_dir / STATUS_NAME, "batch status table", strict=True)
    for column in ("drive", "status"):
        if column not in table.header:
            raise InputFileError(table.path, f"missing column '{column}'", line=1)
    return [{k: v or "" for k, v in row.items()} for _, row in table]


def fleet_report_data(root: str | Path, opts: ReportOptions) -> ReportData:
    """The report of a batch output: its complete drives read as run outputs, with the fleet
    tables and the batch status.

    Raises:
        MissingInputError: no drive of the batch is complete.
    """
    root = Path(root)
    status = read_status(root)
    folders = batch_drive_folders(root)
    if not folders:
        raise MissingInputError(
            f"{root} is a `slopedist batch` output without a complete drive "
            f"({len(status)} drives in {STATUS_NAME}, none done): see the errors there"
        )
    data = run_report_data(root, opts, folders)
    data.kind = SourceKind.FLEET
    if opts.title is None:
        data.title = default_title(SourceKind.FLEET, data.sequences, data.methods)
    data.fleet = _keep_methods(fleet_summary(root), opts.methods)
    data.batch_status = status
    counts = _status_counts(status)
    data.notes.insert(
        0,
        f"Batch output: {len(status)} drives ("
        + ", ".join(f"{n} {s}" for s, n in counts.items() if n)
        + f"); {len(folders)} complete drives reported, each drive one sequence.",
    )
    data.protocol["source"] = "batch"
    return data


def _keep_methods(summary: FleetSummary, methods: Sequence[str] | None) -> FleetSummary:
    if not methods:
        return summary
    rows = [
        [r for r in table if fleet_base_method(r["method"]) in methods]
        for table in (
            summary.drives,
            summary.pooled,
            summary.by_range,
            summary.safety,
            summary.safety_pooled,
        )
    ]
    return FleetSummary(*rows)


def _status_counts(status: Sequence[dict[str, str]]) -> dict[str, int]:
    return {s.value: sum(r["status"] == s.value for r in status) for s in DriveStatus}


def _int(text: str) -> int:
    return int(text) if text.strip().isdigit() else 0


def status_tables(status: Sequence[dict[str, str]]) -> list[Table]:
    """Drives, frames and records per batch status; the first failed drives with their
    error."""
    rows: list[list[Any]] = []
    for s, n in _status_counts(status).items():
        mine = [r for r in status if r["status"] == s]
        frames = sum(_int(r.get("frames", "")) for r in mine)
        rows.append([s, n, frames, sum(_int(r.get("records", "")) for r in mine)])
    tables = [
        Table(
            "fleet_status",
            f"Fleet: {len(status)} drives in the batch",
            ["status", "drives", "frames", "records"],
            rows,
            [],
            f"From {STATUS_NAME}; done = ran in the last batch, skipped = complete from an "
            "earlier one (both are reported below).",
            {1: "d", 2: "d", 3: "d"},
        )
    ]
    failed = [
        [r["drive"], r.get("error", "")] for r in status if r["status"] == DriveStatus.FAILED.value
    ]
    if failed:
        shown = failed[:FAILED_ROWS]
        tables.append(
            Table(
                "fleet_failed",
                f"Fleet: {len(shown)} of {len(failed)} failed drives",
                ["drive", "error"],
                shown,
                [],
                f"Every failed drive and its error is in {STATUS_NAME}.",
            )
        )
    return tables


def _metric_cells(row: dict[str, Any]) -> list[Any]:
    return [int(row["n"]), *(float(row[k]) for k in METRICS[1:])]


def accuracy_tables(summary: FleetSummary) -> list[Table]:
    """The fleet's pooled accuracy per method, by true-distance range, and per drive; the
    best pooled RMSE in bold only when every method ran on the same drives."""
    formats = {1: "d", 2: "d", 5: ".3f", 6: ".3f"}
    pooled = [[r["method"], r["drives"], *_metric_cells(r)] for r in summary.pooled]
    drive_sets = {
        frozenset(d["drive"] for d in summary.drives if d["method"] == r["method"])
        for r in summary.pooled
    }
    same_drives = len(drive_sets) <= 1  # else each pools other targets: not compared
    best = best_marks([r[3] for r in pooled]) if same_drives else [False] * len(pooled)
    ranges = [[r["method"], r["range_m"], *_metric_cells(r)] for r in summary.by_range]
    drives = [
        [r["drive"], r["method"], r["records"], r["estimated"], *_metric_cells(r)]
        for r in summary.drives
    ]
    cap = "Estimates above 80 m count as 80 m, a target below the horizon as 80 m."
    return [
        Table(
            "fleet_pooled",
            "Fleet: distance error pooled over all drives (m)",
            ["method", "drives", *_METRIC_HEADERS],
            pooled,
            [[False, False, False, b, False, False, False] for b in best],
            f"Every record with a true distance (gt_distance_m) of every drive. {cap}"
            + ("" if same_drives else " The methods ran on different drives: not compared."),
            {**formats, 2: "d"},
        ),
        Table(
            "fleet_range",
            "Fleet: distance error by true distance (m)",
            ["method", "range (m)", *_METRIC_HEADERS],
            ranges,
            [],
            "Pooled over all drives; a range holds the targets with lo < true distance <= hi.",
            {2: "d", 5: ".3f", 6: ".3f"},
        ),
        Table(
            "fleet_drives",
            "Fleet: distance error per drive (m)",
            ["drive", "method", "records", "estimated", *_METRIC_HEADERS],
            drives,
            [],
            f"records = targets, estimated = with a distance, n = scored against the truth. {cap}",
            {2: "d", 3: "d", 4: "d", 7: ".3f", 8: ".3f"},
        ),
    ]


def _safety_cells(row: dict[str, Any]) -> list[Any]:
    values = [row[k] for k in SAFETY_FIELDS]
    duration = float(values[0])
    return [duration / 3600 if math.isfinite(duration) else math.nan, *values[1:]]


def safety_tables(summary: FleetSummary) -> list[Table]:
    """The per-track safety summaries pooled per method and per drive."""
    shift = {i + 2: f for i, f in _SAFETY_FORMATS.items()}
    pooled = [
        [r["method"], r["drives"], *_safety_cells(r), r["min_ttc_drive"]]
        for r in summary.safety_pooled
    ]
    drives = [[r["drive"], r["method"], *_safety_cells(r)] for r in summary.safety]
    note = (
        "From each drive's tracks.csv: TTC from methods that estimate it (ours); a TTC event = "
        "the TTC of a track fell below the run's threshold (2 s by default); a short headway = "
        f"a track's mean headway time below {SHORT_HEADWAY_S:g} s (runs with an ego speed, "
        "--speed-topic); '-' = no track gave the number."
    )
    return [
        Table(
            "fleet_safety_pooled",
            "Fleet: safety summary pooled over all drives",
            ["method", "drives", *(_SAFETY_HEADERS[f] for f in SAFETY_FIELDS), "min TTC drive"],
            pooled,
            [],
            note,
            {1: "d", **shift},
        ),
        Table(
            "fleet_safety",
            "Fleet: safety summary per drive",
            ["drive", "method", *(_SAFETY_HEADERS[f] for f in SAFETY_FIELDS)],
            drives,
            [],
            note,
            shift,
        ),
    ]


def fleet_tables(data: ReportData) -> list[Table]:
    """The fleet report's own tables (none for another source)."""
    if data.fleet is None:
        return []
    tables = status_tables(data.batch_status or [])
    if data.has_truth:
        tables += accuracy_tables(data.fleet)
    return tables + safety_tables(data.fleet)
