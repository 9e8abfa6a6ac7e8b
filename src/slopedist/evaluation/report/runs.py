"""The report's data from ``slopedist run`` outputs (``records.csv`` + ``frames.csv``), one
folder or a folder of them (one per sequence and method; the sequence is ``run.json``'s
``"sequence"``, else the folder name), or ``slopedist simulate`` outputs with runs inside.

The records are scored when they carry a ground-truth column (:data:`TRUTH_COLUMNS`), with the
KITTI cap rule; ``frames.csv``'s per-frame times give Table 2 (odometry time only for methods
that use rotations) and its θ, against the true θ when a column of :data:`THETA_TRUTH_COLUMNS`
(or the simulation the run lies in) gives it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from slopedist.core.errors import ConfigurationError, InputFileError
from slopedist.core.limits import MAX_INDEX, MAX_RECORD_MAGNITUDE
from slopedist.core.textfiles import CsvRows, number_cell, read_json
from slopedist.estimators import ESTIMATORS, native_reference, takes_ours_options
from slopedist.estimators.base import EstimateStatus, ReferencePoint
from slopedist.estimators.references import CENTRE_COLUMN, NEAREST_FACE_COLUMN, to_reference
from slopedist.evaluation.metrics import (
    ScoredSet,
    cap_estimates,
    pool_methods,
    record_reason,
    reported_sigma,
)
from slopedist.evaluation.report.data import (
    RECORD_COLUMNS,
    THETA_COLUMNS,
    TRACK_COLUMNS,
    Columns,
    ReportData,
    ReportOptions,
    SourceKind,
    default_title,
)
from slopedist.streaming.config import summary_method
from slopedist.streaming.tracks import TRACKS_NAME, read_tracks

TRUTH_COLUMNS = ("gt_distance_m", "gt_z_m", "true_distance_m", "truth_z_m")
"""Columns of a run's ``records.csv`` read as the ground-truth distance (metres), first found."""

TTC_COLUMN = "ttc_s"
"""The records' column of a method's time to collision (seconds; ``ours``)."""

SIGMA_COLUMN = "sigma_m"
"""The records' column of a method's own 1σ of ``distance_m`` (metres; ``ours``), scored
against its errors (:func:`~slopedist.evaluation.metrics.uncertainty_metrics`)."""

THETA_TRUTH_COLUMNS = ("theta_true_deg", "gt_theta_deg")
"""Columns of a run's ``frames.csv`` read as the true ego gradient (degrees), first found."""

TIME_COLUMNS = ("odometry_ms", "estimation_ms", "depth_ms", "detection_ms")
"""Per-frame times of ``frames.csv`` (milliseconds) that make Table 2 (``detection_ms``: runs
with ``--detector``)."""

NOT_IN_RECORDS = "not in records"


def run_folders(root: Path) -> list[Path]:
    """The run output folders (with ``records.csv``) at ``root``: ``root`` itself, its
    sub-folders, and their sub-folders (e.g. ``slopedist simulate`` outputs holding the runs
    made from their frames)."""
    if (root / "records.csv").is_file():
        return [root]
    return sorted(
        {p.parent for pattern in ("*/records.csv", "*/*/records.csv") for p in root.glob(pattern)}
    )


def _float(value: str | None, path: Path, line: int, name: str) -> float:
    """A CSV cell as a number (empty or ``nan`` = NaN; infinite or beyond ±
    :data:`~slopedist.core.limits.MAX_RECORD_MAGNITUDE` is an error naming file, line and field)."""
    return number_cell(value, path, line, name, bound=MAX_RECORD_MAGNITUDE)


def _index(value: str | None, path: Path, line: int, name: str, lowest: int = 0) -> int:
    """A CSV cell as a frame index (``lowest`` 0) or track id (``lowest`` -1) in
    ``lowest..MAX_INDEX``.

    Raises:
        InputFileError: empty, not a whole number, or out of range (names file, line, field).
    """
    x = _float(value, path, line, name)
    if not (x.is_integer() and lowest <= x <= MAX_INDEX):
        raise InputFileError(
            path, f"'{value}' is not a whole number in {lowest}..{MAX_INDEX}", line=line, field=name
        )
    return int(x)


def read_csv(
    path: Path, required: Sequence[str]
) -> tuple[list[str], list[dict[str, str]], list[int]]:
    """Header, rows and the file line of each row of a CSV file (every row as wide as the
    header).

    Raises:
        InputFileError: a ``required`` column is absent, a row of the wrong width, bad UTF-8
            or a broken CSV row (naming the line).
    """
    table = CsvRows(path, "CSV file", strict=True)
    header = table.header
    absent = [c for c in required if c not in header]
    if absent:
        raise InputFileError(
            path,
            f"missing column(s) {', '.join(absent)} (header: {', '.join(header) or 'none'})",
            line=1,
        )
    lines: list[int] = []
    rows: list[dict[str, str]] = []
    for line, row in table:
        lines.append(line)
        rows.append({k: v or "" for k, v in row.items()})
    return header, rows, lines


def _run_summary(folder: Path) -> dict[str, Any]:
    """A run folder's ``run.json`` (empty when it has none).

    Raises:
        InputFileError: not valid JSON or not a JSON object.
    """
    summary = folder / "run.json"
    if not summary.is_file():
        return {}
    data = read_json(summary, "run summary")
    if not isinstance(data, dict):
        raise InputFileError(summary, "not a JSON object")
    return data


def _summary_method(folder: Path, records: Path) -> str:
    """The method of a run whose records do not name it (the default columns): its
    ``run.json``'s.

    Raises:
        InputFileError: no ``run.json`` names one.
    """
    method = summary_method(_run_summary(folder))
    if not method:
        raise InputFileError(
            records,
            "the records have no method column and no run.json beside them names the method",
        )
    return method


def run_sequence_name(folder: Path) -> str:
    """Sequence a run folder belongs to: ``run.json``'s ``"sequence"`` when present, else the
    folder name (runs of different methods on one sequence share the name there)."""
    value = _run_summary(folder).get("sequence")
    return str(value) if value else folder.name


def partial_run(folder: Path) -> str | None:
    """Words for a run folder whose ``run.json`` says the run did not complete (stopped by a
    signal or an error after some frames), or None for a complete run (or one without
    ``run.json``)."""
    summary = _run_summary(folder)
    if summary.get("complete") is not False:
        return None
    last = summary.get("last_complete_frame")
    error = summary.get("error")
    return (
        f"{folder} is a partial run: its run.json says it stopped "
        + (f"after frame {last}" if isinstance(last, int) else "before completing a frame")
        + (f" ({error})" if error else "")
        + "; its figures cover only the frames it finished"
    )


@dataclass
class _RunReader:
    """What the run folders add up to, folder by folder."""

    methods: Sequence[str] | None
    reference: ReferencePoint | None = None
    """The truth's declared reference point: every distance is moved to it (None: as given)."""
    records: Columns = field(default_factory=lambda: Columns(RECORD_COLUMNS))
    theta: Columns = field(default_factory=lambda: Columns(THETA_COLUMNS))
    tracks: Columns = field(default_factory=lambda: Columns(TRACK_COLUMNS))
    sets: dict[str, dict[str, ScoredSet]] = field(default_factory=dict)
    times: dict[tuple[str, str], list[float]] = field(default_factory=dict)
    truth_found: bool = False
    theta_truth: set[str] = field(default_factory=set)
    references: dict[str, set[str]] = field(default_factory=dict)
    prior_extent: set[str] = field(default_factory=set)

    def read_records(self, folder: Path, seq: str) -> list[str]:
        """Add a folder's records and its methods' scored sets; returns its methods.

        Raises:
            ConfigurationError: a method of this folder already has records for ``seq``.
        """
        path = folder / "records.csv"
        header, rows, lines = read_csv(path, ("frame", "distance_m", "status", "reason"))
        truth_col = next((c for c in TRUTH_COLUMNS if c in header), None)
        self.truth_found |= truth_col is not None
        run_method = "" if "method" in header else _summary_method(folder, path)
        by_method: dict[str, list[tuple[float, float, str, float]]] = {}
        for lineno, row in zip(lines, rows):
            method = row.get("method") or run_method
            if self.methods and method not in self.methods:
                continue
            reason = record_reason(row["status"], row["reason"], path, lineno)
            d = _distance(row, path, lineno)
            wanted = self.reference if self.reference is not None else scored_at(truth_col, method)
            if wanted is not None:
                d = _at_reference(d, row, path, lineno, wanted)
                self._note_prior_extent(method, row, header, wanted)
            g = _float(row[truth_col], path, lineno, truth_col) if truth_col else math.nan
            sigma = _float(row.get(SIGMA_COLUMN, ""), path, lineno, SIGMA_COLUMN)
            by_method.setdefault(method, []).append((d, g, reason, sigma))
            self._note_reference(method, row.get("reference", ""))
            tid = row.get("track_id", "")
            self.records.add(
                sequence=seq,
                frame=_index(row["frame"], path, lineno, "frame"),
                timestamp_s=_float(row.get("timestamp_s", ""), path, lineno, "timestamp_s"),
                track_id=_index(tid, path, lineno, "track_id", -1) if tid else -1,
                method=method,
                rotation="",
                distance_m=d,
                gt_distance_m=g,
                scored=False,
                reason=reason,
                theta_deg=_float(row.get("theta_deg", ""), path, lineno, "theta_deg"),
                sigma_m=sigma,
                ttc_s=_float(row.get(TTC_COLUMN, ""), path, lineno, TTC_COLUMN),
                bound_m=d if row["status"] == EstimateStatus.UPPER_BOUND.value else math.nan,
            )
        seq_sets = self.sets.setdefault(seq, {})
        for method, vals in by_method.items():
            if method in seq_sets:
                raise ConfigurationError(
                    f"method {method} appears twice for sequence {seq} (another run folder "
                    f"besides {folder} has it): give one run per method and sequence"
                )
            seq_sets[method] = _scored_set(vals)
        return list(by_method)

    def _note_prior_extent(
        self, method: str, row: dict[str, str], header: list[str], wanted: ReferencePoint
    ) -> None:
        """Remember a method whose distances were moved to ``wanted`` with the class's length
        prior because its records lack its own extent (``ours``'s, in the full columns only)."""
        moved = row.get("reference", "") not in ("", wanted.value)
        if moved and CENTRE_COLUMN not in header and takes_ours_options(method):
            self.prior_extent.add(method)

    def _note_reference(self, method: str, reference: str) -> None:
        """Remember the point of the vehicle a method's distances refer to (the truth's
        declared point when every distance is moved to it)."""
        point = self.reference.value if self.reference is not None else reference.strip()
        if point:
            self.references.setdefault(method, set()).add(point)

    def read_tracks(self, folder: Path, seq: str, methods: list[str]) -> None:
        """Add a run folder's per-track summaries (``tracks.csv``, if there is one)."""
        for values in read_tracks(folder / TRACKS_NAME):
            self.tracks.add(sequence=seq, method=", ".join(methods), **values)

    def read_frame_log(self, folder: Path, seq: str, methods: list[str], shared: bool) -> None:
        """Add a run folder's per-frame θ (source ``run``, or the folder's name when several
        runs share the sequence), the true θ (once per sequence: from the folder's
        ``frames.csv`` or from the simulation it lies in) and the per-frame times of its
        methods."""
        path = folder / "frames.csv"
        if not path.is_file():
            return
        header, rows, lines = read_csv(path, ("frame",))
        has_truth = any(c in header for c in THETA_TRUTH_COLUMNS)
        truth_path = path if has_truth else _truth_frame_log(folder)
        if truth_path is not None and seq not in self.theta_truth:
            truth = (
                (header, rows, lines) if truth_path == path else read_csv(truth_path, ("frame",))
            )
            self._add_true_theta(truth_path, seq, *truth)
        values = {
            key: [_float(row[key], path, n, key) for n, row in zip(lines, rows)]
            for key in ("theta_deg", *TIME_COLUMNS)
            if key in header
        }
        if any(math.isfinite(v) for v in values.get("theta_deg", [])):
            source = folder.name if shared else "run"
            for lineno, row, th in zip(lines, rows, values["theta_deg"]):
                self._add_theta(path, lineno, row, seq, source, th)
        for key in TIME_COLUMNS:
            finite = [v for v in values.get(key, []) if math.isfinite(v)]
            for method in methods if finite else []:
                if key == "odometry_ms" and not _uses_rotation(method):
                    continue
                self.times.setdefault((method, key), []).extend(finite)

    def _add_true_theta(
        self,
        path: Path,
        seq: str,
        header: list[str],
        rows: list[dict[str, str]],
        lines: list[int],
    ) -> None:
        column = next((c for c in THETA_TRUTH_COLUMNS if c in header), None)
        if column is None:
            return
        self.theta_truth.add(seq)
        for lineno, row in zip(lines, rows):
            th = _float(row[column], path, lineno, column)
            self._add_theta(path, lineno, row, seq, "truth", th)

    def _add_theta(
        self, path: Path, lineno: int, row: dict[str, str], seq: str, source: str, th: float
    ) -> None:
        self.theta.add(
            sequence=seq,
            frame=_index(row["frame"], path, lineno, "frame"),
            timestamp_s=_float(row.get("timestamp_s", ""), path, lineno, "timestamp_s"),
            source=source,
            theta_deg=th,
        )

    def timing(self, method: str) -> dict[str, float]:
        """Table 2's times of ``method``: per-frame means of ``frames.csv`` (ms)."""
        out = {
            key: float(np.mean(self.times[(method, key)]))
            if (method, key) in self.times
            else math.nan
            for key in TIME_COLUMNS
        }
        out["frames"] = float(len(self.times.get((method, "estimation_ms"), [])))
        return out

    def mark_scored(self) -> None:
        """Cap the records' distances and mark the scored ones (the rule of the sets); without
        a truth nothing is scored and the distances stay as the runs wrote them (an upper
        bound's in ``bound_m``)."""
        rec = self.records
        if not self.truth_found:
            reasons = rec.data["reason"]
            rec.data["distance_m"] = [
                d if r == "" else math.nan for d, r in zip(rec.data["distance_m"], reasons)
            ]
            return
        capped, ok = cap_estimates(rec.array("distance_m"), rec.array("reason", object))
        rec.data["distance_m"] = [float(v) if o else math.nan for v, o in zip(capped, ok)]
        rec.data["scored"] = list(ok & np.isfinite(rec.array("gt_distance_m")))


def _distance(row: dict[str, str], path: Path, line: int) -> float:
    """A record's ``distance_m``; a record of status ``ok`` must have a finite one > 0.

    Raises:
        InputFileError: not a number, or an ``ok`` record without a plausible distance.
    """
    d = _float(row["distance_m"], path, line, "distance_m")
    if row["status"] == "ok" and not (math.isfinite(d) and d > 0):
        raise InputFileError(
            path,
            f"a record of status ok has distance '{row['distance_m']}' (expected metres > 0)",
            line=line,
            field="distance_m",
        )
    return d


def _at_reference(
    d: float, row: dict[str, str], path: Path, line: int, wanted: ReferencePoint
) -> float:
    """A record's distance moved from its ``reference`` to ``wanted``
    (:func:`~slopedist.estimators.references.to_reference`; the record's own half extent where
    it has the centre and nearest-face columns)."""
    centre = _float(row.get(CENTRE_COLUMN), path, line, CENTRE_COLUMN)
    face = _float(row.get(NEAREST_FACE_COLUMN), path, line, NEAREST_FACE_COLUMN)
    moved = to_reference(
        [d], [row.get("reference", "")], [row.get("class", "")], wanted, [centre - face]
    )
    return float(moved[0])


def scored_at(truth_column: str | None, method: str) -> ReferencePoint | None:
    """The point a run's record of ``method`` is scored at against a truth column whose point
    is not declared (``--gt-reference``): the method's own (the published protocol, which
    ``eval kitti-tracking`` follows against KITTI's label z), whatever point the run moved it
    to; None without a truth (the records as written) or for an unknown method."""
    return native_reference(method) if truth_column is not None else None


def _scored_set(vals: list[tuple[float, float, str, float]]) -> ScoredSet:
    """``(distance, truth, reason, σ)`` records scored with the KITTI cap rule (only targets
    with a positive truth count); with the method's own σ when any record has one."""
    dist = np.array([v[0] for v in vals])
    gt = np.array([v[1] for v in vals])
    capped, ok = cap_estimates(dist, np.array([v[2] for v in vals], dtype=object))
    ok &= np.isfinite(gt) & (gt > 0)
    return ScoredSet(
        capped[ok],
        gt[ok],
        n_gt=int(np.isfinite(gt).sum()),
        n_unscored=int((np.isfinite(gt) & ~ok).sum()),
        sigma_m=reported_sigma([v[3] for v in vals], ok),
    )


def _uses_rotation(method: str) -> bool:
    """Whether a method uses the camera rotation (its runs are charged the odometry time)."""
    return bool(getattr(ESTIMATORS.get(method), "needs_rotation", True))


def _truth_frame_log(folder: Path) -> Path | None:
    """``frames.csv`` of the ``slopedist simulate`` output a run folder lies in (its true θ),
    if any."""
    parent = folder.parent
    if all((parent / f).is_file() for f in ("info.json", "frames.csv", "truth.csv")):
        return parent / "frames.csv"
    return None


def _notes(truth_found: bool, reference: ReferencePoint | None) -> list[str]:
    compared = (
        f"declared to refer to the vehicle's {reference.value}, every method's distance moved "
        "to that point"
        if reference is not None
        else "each method scored at its own reference point"
    )
    truth = (
        (
            "Ground truth: column " + ", ".join(TRUTH_COLUMNS) + f" of records.csv, {compared}; "
            "the same cap rule as KITTI (estimates above 80 m count as 80 m, below-horizon "
            "targets as 80 m)."
        )
        if truth_found
        else "No ground truth: the records have none of the columns "
        + ", ".join(TRUTH_COLUMNS)
        + ", so the distances are the methods' estimates, shown as the runs wrote them, "
        "and there is no accuracy table."
    )
    return [
        truth,
        "Times are the per-frame means of frames.csv (odometry_ms, estimation_ms, depth_ms); "
        "the 2D detector is excluded.",
    ]


def _prior_extent_note(methods: set[str]) -> list[str]:
    """A line for the methods moved to the truth's point with a length prior (else none)."""
    if not methods:
        return []
    return [
        f"{', '.join(sorted(methods))}: moved to the truth's point with half the class's "
        f"length, the records lacking the method's own extent ({CENTRE_COLUMN}); run with "
        "--columns all to score with it."
    ]


REFERENCE_WORDS = {
    ReferencePoint.CENTRE.value: "the vehicle's centre",
    ReferencePoint.NEAREST_FACE.value: "the vehicle's nearest face (the gap)",
    ReferencePoint.CONTACT.value: "the ground under the bottom of the vehicle's box",
    ReferencePoint.BOX_CENTRE_PIXEL.value: "the depth at the centre of the vehicle's box",
}
"""What each reference point of the records means, for the report's notes and captions."""


def reference_words(reference: str) -> str:
    """Words for a records' ``reference`` value (several joined by ``/``)."""
    return " or ".join(REFERENCE_WORDS.get(r, r) for r in reference.split("/"))


def _reference_note(references: dict[str, str]) -> list[str]:
    """One line saying which point of the vehicle the distances refer to (none when the
    records do not say)."""
    if not references:
        return []
    points = set(references.values())
    if len(points) == 1:
        return [f"Distances refer to {reference_words(points.pop())}."]
    return [
        "Distances refer to: "
        + "; ".join(f"{m}, {reference_words(r)}" for m, r in sorted(references.items()))
        + "."
    ]


def run_report_data(
    root: str | Path, opts: ReportOptions, folders: Sequence[Path] | None = None
) -> ReportData:
    """Read one ``slopedist run`` output folder, or a folder of them (one per sequence);
    ``folders``: the run folders to read (default: :func:`run_folders` of ``root``).

    Raises:
        InputFileError: a bad cell or a missing column (file, line, field), or no records.
        ConfigurationError: two runs of one method on one sequence.
    """
    root = Path(root)
    folders = list(folders) if folders is not None else run_folders(root)
    by_seq: dict[str, list[Path]] = {}
    for folder in folders:
        by_seq.setdefault(run_sequence_name(folder), []).append(folder)
    reference = opts.eval.gt_reference
    reader = _RunReader(opts.methods, ReferencePoint(reference) if reference else None)
    for folder in folders:
        seq = run_sequence_name(folder)
        methods = reader.read_records(folder, seq)
        reader.read_frame_log(folder, seq, methods, len(by_seq[seq]) > 1)
        reader.read_tracks(folder, seq, methods)
    partial = [w for w in map(partial_run, folders) if w is not None]
    methods = sorted({m for s in reader.sets.values() for m in s})
    if not methods:
        wanted = f" of method(s) {', '.join(opts.methods)}" if opts.methods else ""
        raise InputFileError(
            folders[0] / "records.csv",
            f"no records{wanted}: the run(s) had no boxes to estimate, so there is nothing to "
            "score or plot (frames.csv has the per-frame log)",
        )
    reader.mark_scored()
    missing = ScoredSet(np.zeros(0), np.zeros(0), 0, info={"missing": NOT_IN_RECORDS})
    per_seq = {s: {m: reader.sets[s].get(m, missing) for m in methods} for s in by_seq}
    references = {m: "/".join(sorted(r)) for m, r in reader.references.items()}
    return ReportData(
        title=opts.title or default_title(SourceKind.RUN, list(by_seq), methods),
        source=root,
        kind=SourceKind.RUN,
        scores=pool_methods(per_seq, methods),
        timing={m: reader.timing(m) for m in methods},
        records=reader.records,
        theta=reader.theta,
        protocol={
            "source": "run",
            "folders": [str(f) for f in folders],
            "gt_reference": reader.reference.value if reader.reference else None,
        },
        notes=[
            *_reference_note(references),
            *_notes(reader.truth_found, reader.reference),
            *_prior_extent_note(reader.prior_extent),
            *partial,
        ],
        warnings=partial,
        truth_source="truth" if reader.theta_truth else None,
        has_truth=reader.truth_found,
        tracks=reader.tracks if len(reader.tracks) else None,
        references=references,
        near_m=opts.near_m,
    )


def demo_number(results: dict[str, Any], path: Path, *keys: str) -> float:
    """The number at ``results[keys[0]][keys[1]]...`` of a demo's ``results.json`` (null =
    NaN).

    Raises:
        InputFileError: a key is absent or the value is not a number.
    """
    value: Any = results
    for k in keys:
        if not isinstance(value, dict) or k not in value:
            raise InputFileError(path, f"lacks {'.'.join(keys)} (not a slopedist demo output?)")
        value = value[k]
    if value is None:
        return math.nan
    if not isinstance(value, (int, float)):
        raise InputFileError(path, f"{'.'.join(keys)} is not a number: {value!r}")
    return float(value)
