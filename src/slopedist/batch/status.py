"""The batch status table ``OUT/status.csv``: one row per drive of the batch."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

from slopedist.io.formatting import write_csv

STATUS_NAME = "status.csv"
STATUS_FIELDS = (
    "drive",
    "status",
    "error",
    "frames",
    "records",
    "seconds",
    "cpu_seconds",
    "attempts",
    "worker_peak_rss_mb",
)
"""Columns of ``status.csv``: ``frames`` / ``records`` written by the run, ``seconds`` of wall
time of the drive's task (empty for a drive that did not run), ``attempts`` the task runs (Ray
retries of a worker that died add to it), ``worker_peak_rss_mb`` the peak resident memory (MB)
of the worker process that ran the drive, over its life so far (workers run many drives)."""


class DriveStatus(str, Enum):
    """What became of a drive in a batch."""

    DONE = "done"
    """Ran now and completed; its folder ``OUT/<drive>`` is complete."""
    FAILED = "failed"
    """Ran and failed (error in ``status.csv``); no ``OUT/<drive>`` folder is left."""
    SKIPPED = "skipped"
    """Complete from an earlier batch with unchanged inputs; not run again."""
    CANCELLED = "cancelled"
    """Not run: ``--fail-fast`` stopped the batch at another drive's failure."""


@dataclass
class DriveOutcome:
    """The status row of one drive (see :data:`STATUS_FIELDS`); times in seconds. ``warnings``
    (not in ``status.csv``): the warnings the drive's run logged in its worker, e.g. the rows
    its box file's reader left out, for the batch to print."""

    drive: str
    status: DriveStatus
    error: str = ""
    frames: int = 0
    records: int = 0
    seconds: float = float("nan")
    cpu_seconds: float = float("nan")
    attempts: int = 0
    worker_peak_rss_mb: float = float("nan")
    warnings: tuple[str, ...] = ()


def write_status(out_dir: Path, outcomes: Sequence[DriveOutcome]) -> Path:
    """Write ``OUT/status.csv`` atomically (a temporary file renamed over the old table)."""
    path = out_dir / STATUS_NAME
    tmp = out_dir / f".{STATUS_NAME}.tmp"
    write_csv(tmp, ({f: getattr(o, f) for f in STATUS_FIELDS} for o in outcomes), STATUS_FIELDS)
    os.replace(tmp, path)
    return path
