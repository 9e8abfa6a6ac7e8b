"""The report's tables: the accuracy tables of :mod:`slopedist.evaluation.accuracy_tables`, Table 2
(time per
frame) and the agreement of θ with its truth; and every metric in long form for CSV."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from slopedist.estimators import ESTIMATORS
from slopedist.evaluation.accuracy_tables import score_tables
from slopedist.evaluation.report.data import ReportData, SourceKind
from slopedist.evaluation.report.fleet import fleet_tables
from slopedist.evaluation.report.track_summary import tracks_table
from slopedist.evaluation.table import Table, best_marks


def table2(data: ReportData) -> Table:
    """Time per frame per method (ms): odometry, estimation, depth, and the 2D detector when the
    runs ran one (its own column, outside the total: it is shared by every method)."""
    rows = []
    for m in data.methods:
        t = data.timing[m]
        parts = [t["odometry_ms"], t["estimation_ms"], t["depth_ms"]]
        finite = [p for p in parts if math.isfinite(p)]
        rows.append([m, *parts, float(sum(finite)) if finite else math.nan])
    untimed = _untimed_rotations(data)
    totals = best_marks([r[4] for r in rows]) if not untimed else [False] * len(rows)
    bold = [[False, False, False, False, b] for b in totals]
    headers = ["method", "odometry", "estimation", "depth", "total"]
    detection = [data.timing[m].get("detection_ms", math.nan) for m in data.methods]
    note = (
        "Time per frame in milliseconds, averaged over every frame of the sequences each "
        "method ran on; '-' = not applicable or not measured. The 2D detector is excluded "
        "(shared by every method)."
    )
    if untimed:
        note += (
            f" Totals not compared: {', '.join(untimed)} took rotations from elsewhere (a pose "
            "file or an IMU), untimed, while another method's odometry was timed."
        )
    if any(math.isfinite(d) for d in detection):
        headers.append("detection")
        rows = [[*r, d] for r, d in zip(rows, detection)]
        bold = [[*b, False] for b in bold]
        note = note.replace(
            "is excluded", "(runs with --detector) has its own column, not in the total"
        )
    return Table(
        "table2_time",
        "Table 2: time per frame (ms)",
        headers,
        rows,
        bold,
        note,
        {i: ".3f" for i in range(1, len(headers))},
    )


def _untimed_rotations(data: ReportData) -> list[str]:
    """The methods that need a rotation but whose odometry time is not measured, when another
    method's is: their totals lack a part the others' hold (empty when nothing is timed, or
    everything that needs a rotation is)."""
    odometry_ms = [data.timing[m]["odometry_ms"] for m in data.methods]
    if not any(math.isfinite(t) for t in odometry_ms):
        return []
    return [
        m
        for m, t in zip(data.methods, odometry_ms)
        if not math.isfinite(t) and getattr(ESTIMATORS.get(m), "needs_rotation", False)
    ]


def _theta_rows(data: ReportData, truth_source: str) -> list[list[Any]]:
    """Per sequence and rotation source: frames compared, RMS and largest difference to the
    truth's θ, RMS of the truth's θ (degrees)."""
    seq = data.theta.array("sequence", object)
    src = data.theta.array("source", object)
    frame = data.theta.array("frame", int)
    th = data.theta.array("theta_deg")
    others = sorted(set(src) - {truth_source})
    rows: list[list[Any]] = []
    for s in data.sequences:
        truth = (seq == s) & (src == truth_source)
        if not truth.any():
            continue
        t_by_frame = dict(zip(frame[truth], th[truth]))
        for o in others:
            sel = (seq == s) & (src == o)
            diffs = np.array(
                [
                    v - t_by_frame[k]
                    for k, v in zip(frame[sel], th[sel])
                    if k in t_by_frame and math.isfinite(v) and math.isfinite(t_by_frame[k])
                ]
            )
            if diffs.size:
                rms_truth = float(np.sqrt(np.mean(th[truth] ** 2)))
                rms = float(np.sqrt(np.mean(diffs**2)))
                rows.append([s, o, int(diffs.size), rms, float(np.max(np.abs(diffs))), rms_truth])
    return rows


def theta_table(data: ReportData) -> Table | None:
    """RMS and largest difference between each rotation source's θ and the truth's (deg)."""
    if data.truth_source is None or not len(data.theta):
        return None
    rows = _theta_rows(data, data.truth_source)
    if not rows:
        return None
    return Table(
        "theta_agreement",
        f"Ego gradient θ against {data.truth_name()} (deg)",
        ["sequence", "source", "frames", "RMS diff", "max |diff|", "RMS θ truth"],
        rows,
        [[False] * 6 for _ in rows],
        "θ of eq. 4 over the 1 s look-back, per frame, in degrees.",
        {2: "d", 3: ".3f", 4: ".3f", 5: ".3f"},
    )


SUMMARY_TABLES = ("fleet_pooled", "fleet_safety_pooled", "table1_rmse", "table2_time")
"""Keys of the tables ``slopedist report`` prints (the others are on the page and in CSV)."""


def report_tables(data: ReportData) -> list[Table]:
    """Every table of the report, in page order: a batch output's fleet tables first; with a
    truth the accuracy tables, Table 2, θ and the tracks of run outputs; without one the
    tracks first (what such a page is read for), then Table 2 and θ."""
    tables = fleet_tables(data)
    tracks = tracks_table(data) if data.kind in (SourceKind.RUN, SourceKind.FLEET) else None
    if data.has_truth:
        tables += [*score_tables(data.scores), table2(data)]
    else:
        tables += [*([tracks] if tracks is not None else []), table2(data)]
    theta = theta_table(data)
    tables += [theta] if theta is not None else []
    if data.has_truth and tracks is not None:
        tables.append(tracks)
    return tables


METRIC_RECORD_FIELDS = ("scope", "sequence", "method", "bin_m", "metric", "value")
"""Columns of the report's ``metrics.csv`` (every number of every scope in long form)."""


def _summary_records(scope: str, seq: str, m: str, summary: dict[str, Any]) -> list[dict[str, Any]]:
    out = []
    for k, v in summary.items():
        if k == "bins":
            out += [
                dict(zip(METRIC_RECORD_FIELDS, (scope, seq, m, b, bk, float(bv))))
                for b, bm in v.items()
                for bk, bv in bm.items()
            ]
        elif k == "uncertainty":  # the method's own σ against its errors
            out += [
                dict(zip(METRIC_RECORD_FIELDS, (scope, seq, m, "all", uk, float(uv))))
                for uk, uv in v.items()
            ]
        elif isinstance(v, (int, float)):
            out.append(dict(zip(METRIC_RECORD_FIELDS, (scope, seq, m, "all", k, float(v)))))
    return out


def metric_records(data: ReportData) -> list[dict[str, Any]]:
    """Every metric of every scope (sequence, overall, common, timing) in long form."""
    out: list[dict[str, Any]] = []
    for s in data.sequences:
        for m in data.methods:
            out += _summary_records("sequence", s, m, data.summaries[s][m])
    for m in data.methods:
        out += _summary_records("overall", ",".join(data.pooled[m]), m, data.overall[m])
    if data.common is not None:
        shared = ",".join(data.common["sequences"])
        for m in data.methods:
            out += _summary_records("common", shared, m, data.common["methods"][m])
    for m in data.methods:
        out += _summary_records("timing", "", m, data.timing[m])
    return out
