"""Many drives at once: ``slopedist batch`` on Ray (optional extra ``batch``).

- :mod:`~slopedist.batch.manifest`: the drives (CSV / TOML manifest or a folder of drives);
- :mod:`~slopedist.batch.settings`: a drive's run settings (reference point, ``ours`` options,
  vehicle classes, offline mode, overlay, exports) from its cells and the batch-wide values;
- :mod:`~slopedist.batch.drive`: one drive, run atomically into ``OUT/<drive>``;
- :mod:`~slopedist.batch.stamp`: input stamps that make a re-run skip unchanged drives;
- :mod:`~slopedist.batch.engine`: Ray tasks, retries, progress, ``OUT/status.csv``;
- :mod:`~slopedist.batch.fleet`: the Parquet dataset and the fleet summary tables.

Internal: the names a user needs are those of :mod:`slopedist` itself (docs/python.md).
"""

from __future__ import annotations

from slopedist.batch.engine import BatchOptions, BatchResult, run_batch
from slopedist.batch.fleet import (
    FleetSummary,
    fleet_summary,
    records_dataset,
    write_fleet_summary,
)
from slopedist.batch.manifest import DriveDefaults, DriveSpec, load_drives
from slopedist.batch.settings import RunSettings
from slopedist.batch.status import DriveOutcome, DriveStatus

__all__ = [
    "BatchOptions",
    "BatchResult",
    "DriveDefaults",
    "DriveOutcome",
    "DriveSpec",
    "DriveStatus",
    "FleetSummary",
    "RunSettings",
    "fleet_summary",
    "load_drives",
    "records_dataset",
    "run_batch",
    "write_fleet_summary",
]
