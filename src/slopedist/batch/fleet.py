"""Fleet outputs of a batch: the Parquet dataset of all records and the fleet summary.

- ``OUT/records.parquet/drive=<drive>/part-0.parquet``: every drive's ``records.csv`` as one
  Hive-partitioned Parquet dataset (read it with :func:`records_dataset`, whose partition
  column ``drive`` is text: inferred, drive ``007`` would read as the number 7). Written per
  drive, atomically;
  the record columns have fixed types, and a method-specific extra column that is empty in a
  drive is written as float64.
- :func:`fleet_summary`: per-drive and pooled distance metrics (metres) of every method where
  the records carry the true distance ``gt_distance_m``, and the error by true-distance range
  (:data:`~slopedist.evaluation.metrics.DISTANCE_BINS_M`), scored as ``slopedist report`` scores
  runs
  (estimates capped at 80 m, below-horizon counted at the cap). :func:`write_fleet_summary`
  writes them to ``OUT/fleet/{drives,pooled,range}.csv``; with the per-track safety
  summaries of :mod:`~slopedist.batch.safety` per drive and pooled per method
  (``OUT/fleet/safety.csv``, ``OUT/fleet/safety_pooled.csv``), and the options each drive was
  run with (``OUT/fleet/settings.csv``, :func:`settings_rows`).
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from slopedist.batch.drive import completed_stamp
from slopedist.batch.safety import (
    DRIVE_SAFETY_FIELDS,
    POOLED_SAFETY_FIELDS,
    fleet_method,
    fleet_safety,
)
from slopedist.batch.settings import SETTING_COLUMNS, settings_cell
from slopedist.batch.stamp import SETTINGS_KEY
from slopedist.core.errors import OptionalDependencyError
from slopedist.core.limits import MAX_RECORD_MAGNITUDE
from slopedist.core.textfiles import CsvRows, number_cell, read_json
from slopedist.estimators import native_reference
from slopedist.estimators.references import CENTRE_COLUMN, NEAREST_FACE_COLUMN, to_reference
from slopedist.evaluation.metrics import (
    DISTANCE_BINS_M,
    bin_label,
    cap_estimates,
    distance_metrics,
    record_reason,
)
from slopedist.io.detections.readers import CSV_TRUTH_COLUMN
from slopedist.io.formatting import write_csv
from slopedist.streaming.config import RECORDS_NAME, SUMMARY_NAME, summary_method

DATASET_NAME = "records.parquet"
FLEET_DIR = "fleet"
FLEET_NAMES = frozenset({DATASET_NAME, FLEET_DIR, "status.csv"})
"""Names in ``OUT`` that belong to the batch, not to a drive."""

SETTINGS_FIELDS = (
    "drive",
    "method",
    *SETTING_COLUMNS,
    "odometry",
    "height_m",
    "mount_angle_deg",
    "lookback_s",
    "score",
    "fps",
    "frames",
    "boxes",
    "detector",
)
"""Columns of ``OUT/fleet/settings.csv`` (:func:`settings_rows`): the drive, its method and
run settings (:data:`~slopedist.batch.settings.SETTING_COLUMNS`; ``offline`` and ``overlay``
as 0/1), camera (metres, degrees), look-back (s), box score threshold, frame rate and inputs."""

METRICS = ("n", "rmse", "mae", "abs_rel", "delta_1.25")
"""Metrics of the fleet tables (see :func:`slopedist.evaluation.metrics.distance_metrics`)."""

_FLOAT_COLUMNS = (
    "timestamp_s",
    "score",
    "left",
    "top",
    "right",
    "bottom",
    "theta_deg",
    "theta_adj_deg",
    "delta_y_px",
    "v_px",
    "distance_m",
    CSV_TRUTH_COLUMN,
)
_INT_COLUMNS = ("frame", "track_id")
_STRING_COLUMNS = ("class", "method", "reference", "status", "reason", "cut")


def import_pyarrow() -> Any:
    """``pyarrow`` (with its csv and parquet modules), or an OptionalDependencyError."""
    try:
        import pyarrow
        import pyarrow.csv
        import pyarrow.parquet
    except ImportError:
        raise OptionalDependencyError("pyarrow", "batch", "the fleet Parquet dataset") from None
    return pyarrow


def partition_path(out_dir: Path, drive: str) -> Path:
    """Folder of ``drive``'s partition in the fleet dataset."""
    return out_dir / DATASET_NAME / f"drive={drive}"


PARTITION_STAMP_KEY = b"slopedist_batch_inputs"
"""Parquet schema metadata of a partition: the input stamp (JSON) of the run it was made from."""


def _partition_stamp(target: Path) -> Any:
    """The input stamp a partition file was written with (None: no file, none recorded)."""
    pa = import_pyarrow()
    try:
        metadata = pa.parquet.read_schema(target).metadata or {}
        return json.loads(metadata[PARTITION_STAMP_KEY])
    except (OSError, KeyError, ValueError, pa.ArrowException):
        return None


def write_partition(out_dir: Path, drive: str, refresh: bool = True) -> Path:
    """Write ``OUT/<drive>/records.csv`` as the drive's partition of the dataset (atomically:
    a temporary file renamed), stamped with the input stamp of ``OUT/<drive>/run.json``; with
    ``refresh`` False, an existing partition of the same stamp is kept (one of another run,
    e.g. left by a batch killed between a drive's run and its partition, is rewritten)."""
    pa = import_pyarrow()
    target = partition_path(out_dir, drive) / "part-0.parquet"
    stamp = completed_stamp(out_dir / drive)
    if not refresh and stamp is not None and _partition_stamp(target) == stamp:
        return target
    types = {c: pa.float64() for c in _FLOAT_COLUMNS}
    types.update({c: pa.int64() for c in _INT_COLUMNS})
    types.update({c: pa.string() for c in _STRING_COLUMNS})
    with (out_dir / drive / RECORDS_NAME).open("rb") as fh:  # (a path of any bytes)
        table = pa.csv.read_csv(fh, convert_options=pa.csv.ConvertOptions(column_types=types))
    for i, column in enumerate(table.schema):  # an extra column empty in this drive: numbers
        if pa.types.is_null(column.type):
            table = table.set_column(i, column.name, table.column(i).cast(pa.float64()))
    if "method" not in table.column_names:  # the default columns: the drive's method
        method = summary_method(read_json(out_dir / drive / SUMMARY_NAME, "run summary"))
        table = table.append_column("method", pa.array([method] * table.num_rows, pa.string()))
    metadata = {PARTITION_STAMP_KEY: json.dumps(stamp, sort_keys=True).encode()}
    table = table.replace_schema_metadata({**(table.schema.metadata or {}), **metadata})
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(".part-0.parquet.tmp")
    with tmp.open("wb") as fh:
        pa.parquet.write_table(table, fh)
    os.replace(tmp, target)
    return target


def records_dataset(out_dir: str | Path) -> Any:
    """The fleet Parquet dataset of the batch output ``out_dir`` (a ``pyarrow.dataset.Dataset``)
    with the partition column ``drive`` as text, the drive names of ``status.csv`` (pyarrow's
    inferred Hive partitioning reads a name such as ``007`` or ``2011`` as a number).

    Raises:
        OptionalDependencyError: pyarrow is not installed.
    """
    pa = import_pyarrow()
    import pyarrow.dataset as ds

    drive = ds.partitioning(pa.schema([("drive", pa.string())]), flavor="hive")
    dataset = ds.dataset(Path(out_dir) / DATASET_NAME, format="parquet", partitioning=drive)
    # every partition's columns (pyarrow takes the first file's schema: a drive without the
    # truth or another method's extra columns would hide them in all drives)
    schemas = [f.physical_schema for f in dataset.get_fragments()]
    if not schemas:
        return dataset
    columns = pa.unify_schemas(schemas, promote_options="permissive").remove_metadata()
    schema = pa.unify_schemas([columns, pa.schema([("drive", pa.string())])])
    return ds.dataset(
        Path(out_dir) / DATASET_NAME, format="parquet", partitioning=drive, schema=schema
    )


def remove_partition(out_dir: Path, drive: str) -> None:
    """Drop ``drive`` from the dataset (its run failed; old records would be stale)."""
    shutil.rmtree(partition_path(out_dir, drive), ignore_errors=True)


@dataclass
class FleetSummary:
    """The fleet tables as lists of rows (dicts), distances in metres.

    Attributes:
        drives: one row per drive and method: ``records``, ``estimated`` (with a distance),
            ``truth`` (with ``gt_distance_m``) and :data:`METRICS` over its scored records.
        pooled: one row per method, all drives pooled (``drives`` = drives with the method).
        by_range: one row per method and true-distance range ``range_m`` (e.g. ``"10-20"``),
            pooled over the drives.
        safety: one row per drive: its per-track safety summary
            (:data:`~slopedist.batch.safety.DRIVE_SAFETY_FIELDS`; seconds, metres).
        safety_pooled: one row per method, every drive's tracks pooled
            (:data:`~slopedist.batch.safety.POOLED_SAFETY_FIELDS`).
    """

    drives: list[dict[str, Any]]
    pooled: list[dict[str, Any]]
    by_range: list[dict[str, Any]]
    safety: list[dict[str, Any]]
    safety_pooled: list[dict[str, Any]]


def batch_drive_folders(out_dir: Path) -> list[Path]:
    """The complete drive folders of a batch output (sorted by name)."""
    return sorted(
        p
        for p in out_dir.iterdir()
        if p.is_dir() and not p.name.startswith(".") and completed_stamp(p) is not None
    )


def _read_pairs(folder: Path) -> dict[str, dict[str, Any]]:
    """Per method (named by :func:`~slopedist.batch.safety.fleet_method`): distances, truths,
    reasons of the folder's ``records.csv`` (NaN where empty); each distance with a truth at
    its method's own point (:func:`_scored_distances`)."""
    summary = read_json(folder / SUMMARY_NAME, "run summary")
    path = folder / RECORDS_NAME
    out: dict[str, dict[str, Any]] = {}
    for line, row in CsvRows(path, "run records"):
        base = row.get("method") or summary_method(summary)
        acc = out.setdefault(fleet_method(summary, base), {"base": base, "d": [], "g": [], "r": []})
        for key, column in (("d", "distance_m"), ("g", CSV_TRUTH_COLUMN), *_EXTENT_CELLS):
            value = number_cell(row.get(column), path, line, column, MAX_RECORD_MAGNITUDE)
            acc.setdefault(key, []).append(value)
        acc.setdefault("ref", []).append(row.get("reference") or "")
        acc.setdefault("cls", []).append(row.get("class") or "")
        acc["r"].append(record_reason(row.get("status"), row.get("reason"), path, line))
    for acc in out.values():
        acc["d"] = _scored_distances(acc)
    return out


_EXTENT_CELLS = (("centre", CENTRE_COLUMN), ("face", NEAREST_FACE_COLUMN))
"""The record cells of a method's own half extent (``ours``: centre and nearest face)."""


def _scored_distances(acc: dict[str, Any]) -> np.ndarray:
    """A method's distances (metres) moved from the point each record names to the method's
    own, where the fleet scores them against the truth (``slopedist report``'s rule,
    :func:`~slopedist.evaluation.report.runs.scored_at`): the rows of a drive run at the nearest
    face (the default) are scored as ``eval kitti-tracking`` scores against KITTI's label z."""
    d = np.asarray(acc["d"], dtype=float)
    native = native_reference(acc["base"])
    if native is None:
        return d
    half = np.asarray(acc["centre"], dtype=float) - np.asarray(acc["face"], dtype=float)
    return to_reference(d, acc["ref"], acc["cls"], native, half)


def _metrics(pred: np.ndarray, gt: np.ndarray) -> dict[str, Any]:
    m = distance_metrics(pred, gt)
    return {k: m[k] for k in METRICS}


def fleet_summary(out_dir: str | Path) -> FleetSummary:
    """The fleet tables over every complete drive of the batch output ``out_dir``."""
    out = Path(out_dir)
    folders = batch_drive_folders(out)
    drives: list[dict[str, Any]] = []
    pooled: dict[str, dict[str, list[np.ndarray]]] = {}
    for folder in folders:
        for method, acc in _read_pairs(folder).items():
            d, g = np.asarray(acc["d"], float), np.asarray(acc["g"], float)
            capped, ok = cap_estimates(d, np.asarray(acc["r"], dtype=object))
            ok &= np.isfinite(g) & (g > 0)
            drives.append(
                {
                    "drive": folder.name,
                    "method": method,
                    "records": len(d),
                    "estimated": int(np.isfinite(d).sum()),
                    "truth": int(np.isfinite(g).sum()),
                    **_metrics(capped[ok], g[ok]),
                }
            )
            acc_m = pooled.setdefault(method, {"p": [], "g": []})
            acc_m["p"].append(capped[ok])
            acc_m["g"].append(g[ok])
    pooled_rows, range_rows = [], []
    for method, acc_m in sorted(pooled.items()):
        p, g = np.concatenate(acc_m["p"]), np.concatenate(acc_m["g"])
        n_drives = sum(r["method"] == method for r in drives)
        pooled_rows.append({"method": method, "drives": n_drives, **_metrics(p, g)})
        for lo, hi in DISTANCE_BINS_M:
            sel = (g > lo) & (g <= hi)
            range_rows.append(
                {"method": method, "range_m": bin_label(lo, hi), **_metrics(p[sel], g[sel])}
            )
    return FleetSummary(drives, pooled_rows, range_rows, *fleet_safety(folders))


def settings_rows(out_dir: str | Path) -> list[dict[str, Any]]:
    """One row per complete drive of the batch output ``out_dir``: the options it was run with
    (:data:`SETTINGS_FIELDS`, from the ``batch_drive`` entry of its ``run.json``; lists and the
    ``ours`` options as manifest cells, items joined by ``;``). A drive completed by a batch
    that did not record them has its name only."""
    rows = []
    for folder in batch_drive_folders(Path(out_dir)):
        summary = read_json(folder / SUMMARY_NAME, "run summary")
        options = summary.get(SETTINGS_KEY) if isinstance(summary, dict) else None
        options = options if isinstance(options, dict) else {}
        cells = {k: settings_cell(options.get(k)) for k in SETTINGS_FIELDS[1:]}
        rows.append({"drive": folder.name, **cells})
    return rows


def write_fleet_summary(out_dir: str | Path, summary: FleetSummary | None = None) -> list[Path]:
    """Write :func:`fleet_summary` to ``OUT/fleet/{drives,pooled,range,safety,
    safety_pooled}.csv`` and :func:`settings_rows` to ``OUT/fleet/settings.csv``."""
    out = Path(out_dir)
    summary = summary if summary is not None else fleet_summary(out)
    folder = out / FLEET_DIR
    folder.mkdir(exist_ok=True)
    drive_fields = ("drive", "method", "records", "estimated", "truth", *METRICS)
    return [
        write_csv(folder / "drives.csv", summary.drives, drive_fields),
        write_csv(folder / "pooled.csv", summary.pooled, ("method", "drives", *METRICS)),
        write_csv(folder / "range.csv", summary.by_range, ("method", "range_m", *METRICS)),
        write_csv(folder / "safety.csv", summary.safety, DRIVE_SAFETY_FIELDS),
        write_csv(folder / "safety_pooled.csv", summary.safety_pooled, POOLED_SAFETY_FIELDS),
        write_csv(folder / "settings.csv", settings_rows(out), SETTINGS_FIELDS),
    ]
