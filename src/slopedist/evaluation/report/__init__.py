"""The comparison report (``slopedist report``): the paper's Tables 1 and 2, extended metrics,
figures, as Markdown, a self-contained HTML page and CSV (Parquet with pyarrow).

Sources:

- a KITTI tracking folder (``label_02/``, ``calib/``, poses): every method is run with the
  protocol of :mod:`slopedist.evaluation.kitti` (ground-truth boxes by default, 80 m cap, pooled
  overall); the ``imu`` rows are fed OXTS rotations and are missing where a sequence has none;
  ``depthmap`` runs when a depth folder is given;
- a ``slopedist run`` output folder (``records.csv`` + ``frames.csv``), or a folder of such
  folders (one per sequence and method; the sequence is ``run.json``'s ``"sequence"``, else the
  folder name): the records are read back; they are scored when they carry a
  ground-truth column (:data:`TRUTH_COLUMNS`), and ``frames.csv``'s per-frame times give Table 2
  (odometry time only for methods that use rotations). A folder of ``slopedist simulate``
  outputs with the runs made from their frames inside (``SIM/run_paper/``, ...) is read the
  same way, with the true θ of each simulation (``SIM/frames.csv``);
- a ``slopedist batch`` output (``status.csv``): its complete drives are read as run outputs
  (each drive one sequence), and the fleet tables come first: the batch status, the distance
  error pooled over all drives, by true-distance range and per drive (where the records carry
  the truth), and the per-track safety summaries (minimum TTC, TTC events, short headways) per
  drive and pooled (:mod:`slopedist.evaluation.report.fleet`);
- a ``slopedist demo`` output (``results.json``, ``<scenario>/records.csv`` and
  ``<scenario>/frames.csv``): Table 1 per scenario × method against the synthetic truth, θ of
  the odometry against the true θ, times from ``results.json``.

Outputs under the output folder: ``report.md``, ``report.html`` (figures embedded as base64
PNG, no external files), ``figures/*.png``, ``report.json`` and one CSV per table plus the
per-target records (``records.csv``) and ego gradients (``theta.csv``); Parquet copies when
pyarrow is installed. Distances in metres, times in milliseconds per frame, angles in degrees
(this is an edge of the package).

Table 2 follows the paper: time per frame per method, split into odometry, estimation and depth
inference; the 2D detector is shared by every method and is not counted. On KITTI tracking the
rotations are precomputed pose files, so the odometry column is empty there (not timed).
"""

from __future__ import annotations

from slopedist.evaluation.report.data import (
    RECORD_COLUMNS,
    THETA_COLUMNS,
    Columns,
    ReportData,
    ReportOptions,
    SourceKind,
)
from slopedist.evaluation.report.figures import Figure, report_figures
from slopedist.evaluation.report.fleet import fleet_report_data
from slopedist.evaluation.report.kitti import kitti_report_data
from slopedist.evaluation.report.runs import THETA_TRUTH_COLUMNS, TRUTH_COLUMNS, run_report_data
from slopedist.evaluation.report.sources import detect_source, report_data
from slopedist.evaluation.report.synthetic import synthetic_report_data
from slopedist.evaluation.report.tables import SUMMARY_TABLES, report_tables
from slopedist.evaluation.report.writer import WrittenReport, write_report

__all__ = [
    "RECORD_COLUMNS",
    "SUMMARY_TABLES",
    "THETA_COLUMNS",
    "THETA_TRUTH_COLUMNS",
    "TRUTH_COLUMNS",
    "Columns",
    "Figure",
    "ReportData",
    "ReportOptions",
    "SourceKind",
    "WrittenReport",
    "detect_source",
    "fleet_report_data",
    "kitti_report_data",
    "report_data",
    "report_figures",
    "report_tables",
    "run_report_data",
    "synthetic_report_data",
    "write_report",
]
