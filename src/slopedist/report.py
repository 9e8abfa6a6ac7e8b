"""The comparison report (``slopedist report``): the paper's Tables 1 and 2, extended metrics,
figures, as Markdown, a self-contained HTML page and CSV (Parquet with pyarrow).

Sources:

- a KITTI tracking folder (``label_02/``, ``calib/``, poses): every method is run with the
  protocol of :mod:`slopedist.kitti_eval` (ground-truth boxes by default, 80 m cap, pooled
  overall); the ``imu`` rows are fed OXTS rotations and are missing where a sequence has none;
  ``depthmap`` runs when a depth folder is given;
- a ``slopedist run`` output folder (``records.csv`` + ``frames.csv``), or a folder of such
  folders (one per sequence and method; the sequence is ``run.json``'s ``"sequence"``, else the
  folder name): the records are read back; they are scored when they carry a
  ground-truth column (:data:`TRUTH_COLUMNS`), and ``frames.csv``'s per-frame times give Table 2
  (odometry time only for methods that use rotations). A folder of ``slopedist simulate``
  outputs with the runs made from their frames inside (``SIM/run_paper/``, ...) is read the
  same way, with the true θ of each simulation (``SIM/frames.csv``);
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

import base64
import csv
import html
import importlib.util
import io
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np

from slopedist.datasets.kitti_tracking import (
    BoxSource,
    RotationSource,
    load_sequence,
)
from slopedist.errors import ConfigurationError, InputFileError, MissingInputError
from slopedist.estimators import ESTIMATORS, available_methods
from slopedist.evaluation import (
    DISTANCE_BINS_M,
    ScoredSet,
    cap_estimates,
    compact_names,
    format_table,
)
from slopedist.kitti_eval import (
    KittiEvalConfig,
    SequenceRun,
    build_report,
    check_run,
    run_sequence,
)

TRUTH_COLUMNS = ("gt_distance_m", "gt_z_m", "true_distance_m", "truth_z_m")
"""Columns of a run's ``records.csv`` read as the ground-truth distance (metres), first found."""

THETA_TRUTH_COLUMNS = ("theta_true_deg", "gt_theta_deg")
"""Columns of a run's ``frames.csv`` read as the true ego gradient (degrees), first found."""

ERROR_BIN_M = 5.0
"""Width of the ground-truth distance bins of the error-vs-distance figure, metres."""


class SourceKind(str, Enum):
    """What ``slopedist report`` was pointed at."""

    KITTI_TRACKING = "kitti_tracking"
    RUN = "run"
    SYNTHETIC = "synthetic"
    """A ``slopedist demo`` output folder (the synthetic-hill suite)."""


DEMO_RESULTS = "results.json"
"""File that marks a ``slopedist demo`` output folder (with ``<scenario>/records.csv``)."""


def run_folders(root: Path) -> list[Path]:
    """The run output folders (with ``records.csv``) at ``root``: ``root`` itself, its
    sub-folders, and their sub-folders (e.g. ``slopedist simulate`` outputs holding the runs
    made from their frames)."""
    if (root / "records.csv").is_file():
        return [root]
    return sorted(
        {p.parent for pattern in ("*/records.csv", "*/*/records.csv") for p in root.glob(pattern)}
    )


def detect_source(path: str | Path) -> SourceKind:
    """Tell a KITTI tracking folder from a ``slopedist demo`` output and from a run output (or
    a folder of run outputs, or of ``slopedist simulate`` outputs with runs inside).

    Raises:
        MissingInputError: the folder does not exist or is neither.
    """
    path = Path(path)
    if not path.is_dir():
        raise MissingInputError(f"report source not found (expected a folder): {path}")
    if (path / "label_02").is_dir() and (path / "calib").is_dir():
        return SourceKind.KITTI_TRACKING
    if (path / DEMO_RESULTS).is_file() and any(path.glob("*/records.csv")):
        return SourceKind.SYNTHETIC
    if run_folders(path):
        return SourceKind.RUN
    sims = [
        p.parent
        for p in (path / "truth.csv", *path.glob("*/truth.csv"))
        if p.is_file() and (p.parent / "info.json").is_file()
    ]
    if sims:
        raise MissingInputError(
            f"{sims[0]} is a `slopedist simulate` output, which holds the truth but no estimates: "
            f"run the methods on its frames first, e.g. slopedist run {sims[0]}/image_02 --calib "
            f"{sims[0]}/calib.txt --boxes {sims[0]}/boxes.csv --timestamps {sims[0]}/times.txt "
            f"--method paper --out {sims[0]}/run_paper, then report on {path}"
        )
    raise MissingInputError(
        f"{path} is neither a KITTI tracking folder (label_02/ and calib/), a `slopedist demo` "
        f"output ({DEMO_RESULTS} and <scenario>/records.csv) nor a `slopedist run` output "
        f"(records.csv, or sub-folders with records.csv)"
    )


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
        title: page title.
    """

    eval: KittiEvalConfig = field(default_factory=lambda: KittiEvalConfig(methods=()))
    methods: Sequence[str] | None = None
    tracks: Sequence[tuple[str, int]] | None = None
    n_tracks: int = 4
    title: str = "slopedist comparison report"


@dataclass
class Columns:
    """A column-oriented table (name → list of values), appended to row by row."""

    names: tuple[str, ...]
    data: dict[str, list[Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for n in self.names:
            self.data.setdefault(n, [])

    def add(self, **row: Any) -> None:
        for n in self.names:
            self.data[n].append(row.get(n, math.nan))

    def __len__(self) -> int:
        return len(self.data[self.names[0]]) if self.names else 0

    def array(self, name: str, dtype: Any = float) -> np.ndarray:
        return np.asarray(self.data[name], dtype=dtype)


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
)
THETA_COLUMNS = ("sequence", "frame", "timestamp_s", "source", "theta_deg")


@dataclass
class ReportData:
    """Everything the report shows, source-independent.

    Attributes:
        summaries: ``{sequence: {method: summary}}`` (summary = :meth:`ScoredSet.summary` keys,
            plus ``missing`` when the method has no result there).
        overall: ``{method: summary}`` pooled over ``pooled[method]``.
        common: ``{"sequences": [...], "methods": {method: summary}}`` when the pooled
            sequence sets differ, else None.
        timing: ``{method: {"odometry_ms", "estimation_ms", "depth_ms", "frames"}}``.
        records: per-target rows (:data:`RECORD_COLUMNS`).
        theta: per-frame ego gradients of each rotation source (:data:`THETA_COLUMNS`).
        truth_source: name of the rotation source taken as θ truth (``"oxts"``), if any.
    """

    title: str
    source: Path
    kind: SourceKind
    methods: list[str]
    sequences: list[str]
    summaries: dict[str, dict[str, dict[str, Any]]]
    overall: dict[str, dict[str, Any]]
    pooled: dict[str, list[str]]
    common: dict[str, Any] | None
    timing: dict[str, dict[str, float]]
    records: Columns
    theta: Columns
    protocol: dict[str, Any]
    notes: list[str] = field(default_factory=list)
    truth_source: str | None = None
    has_truth: bool = True


# --- building the data ----------------------------------------------------------------------


def default_kitti_methods(depth: bool) -> list[str]:
    """Every registered method that can run on KITTI tracking (``depthmap`` with depth only)."""
    return [
        m for m in available_methods() if depth or not getattr(ESTIMATORS[m], "needs_depth", False)
    ]


def kitti_report_data(
    root: str | Path, opts: ReportOptions, on_sequence: Callable[[str], None] | None = None
) -> ReportData:
    """Run the methods on the KITTI tracking sequences under ``root`` and collect the data."""
    root = Path(root)
    cfg = opts.eval
    methods = list(cfg.methods) or default_kitti_methods(cfg.depth_dir is not None)
    unknown = [m for m in methods if m not in ESTIMATORS]
    if unknown:
        raise ConfigurationError(
            f"unknown method(s) {', '.join(unknown)}; choose from {', '.join(available_methods())}"
        )
    cfg = KittiEvalConfig(**{**cfg.__dict__, "methods": tuple(methods)})
    names = check_run(root, cfg)
    runs: dict[str, SequenceRun] = {}
    for name in names:
        if on_sequence is not None:
            on_sequence(name)
        seq = load_sequence(root, name, cfg.height_m, cfg.mount_angle_rad)
        runs[name] = run_sequence(seq, cfg)
    per_seq = {s: {m: runs[s].scored(m) for m in methods} for s in names}
    report = build_report(cfg, names, per_seq)
    records = Columns(RECORD_COLUMNS)
    theta = Columns(THETA_COLUMNS)
    for s, run in runs.items():
        gt_z = run.gt.extra["z"][run.gt_rows]
        frames = run.boxes.frame[run.det_rows]
        tids = run.gt.track_id[run.gt_rows]
        for m in methods:
            mr = run.runs[m]
            if mr.missing:
                continue
            d = mr.distance_m[run.det_rows]
            ok = mr.scorable[run.det_rows]
            th = np.degrees(mr.theta_rad[run.det_rows])
            reasons = mr.reason[run.det_rows]
            for i in range(len(run.det_rows)):
                records.add(
                    sequence=s,
                    frame=int(frames[i]),
                    timestamp_s=0.1 * int(frames[i]),
                    track_id=int(tids[i]),
                    method=m,
                    rotation=mr.rotation or "",
                    distance_m=float(d[i]) if ok[i] else math.nan,
                    gt_distance_m=float(gt_z[i]),
                    scored=bool(ok[i]),
                    reason=reasons[i],
                    theta_deg=float(th[i]),
                )
        for source, values in run.theta_rad.items():
            for k, v in enumerate(values):
                theta.add(
                    sequence=s,
                    frame=k,
                    timestamp_s=0.1 * k,
                    source=source,
                    theta_deg=math.degrees(v),
                )
    timing: dict[str, dict[str, float]] = {}
    for m in methods:
        present = [runs[s].runs[m] for s in names if not runs[s].runs[m].missing]
        frames_n = sum(runs[s].n_frames for s in names if not runs[s].runs[m].missing)
        timing[m] = {
            "odometry_ms": math.nan,
            "estimation_ms": 1000 * sum(r.seconds for r in present) / frames_n
            if frames_n
            else math.nan,
            "depth_ms": (
                1000 * sum(r.depth_seconds for r in present) / frames_n
                if frames_n and getattr(ESTIMATORS[m], "needs_depth", False)
                else math.nan
            ),
            "frames": float(frames_n),
        }
    boxes_kind = (
        "ground-truth boxes"
        if BoxSource(cfg.boxes) is BoxSource.GT
        else "PointRCNN detections matched to the truth by IoU"
    )
    notes = [
        f"Protocol: {boxes_kind}; "
        f"ground truth = KITTI label z of Car/Van, truncated 0, occluded <= 1, 0 < z <= 80 m; "
        f"{report['protocol']['cap_rule']}.",
        "Rotation per method: "
        + ", ".join(
            f"{m} = {r or 'none'}" for m, r in report["protocol"]["rotation_per_method"].items()
        )
        + ".",
        "Odometry time is not measured on KITTI tracking: the rotations are precomputed pose "
        "files (ORB-SLAM3, OXTS). Estimation = the estimator's own time; depth = reading the "
        "depth maps (file read, not network inference). The 2D detector is excluded.",
    ]
    return ReportData(
        title=opts.title,
        source=root,
        kind=SourceKind.KITTI_TRACKING,
        methods=methods,
        sequences=names,
        summaries={s: {m: report["methods"][m]["sequences"][s] for m in methods} for s in names},
        overall={m: report["methods"][m]["overall"] for m in methods},
        pooled={m: report["methods"][m]["pooled_sequences"] for m in methods},
        common=report.get("overall_common"),
        timing=timing,
        records=records,
        theta=theta,
        protocol=report["protocol"],
        notes=notes,
        truth_source=RotationSource.OXTS.value
        if any(RotationSource.OXTS.value in r.theta_rad for r in runs.values())
        else None,
    )


def _float(value: str, path: Path, line: int, name: str) -> float:
    if value is None or value.strip() == "":
        return math.nan
    try:
        return float(value)
    except ValueError:
        raise InputFileError(path, f"'{value}' is not a number", line=line, field=name) from None


def _read_csv(path: Path, required: Sequence[str]) -> tuple[list[str], list[dict[str, str]]]:
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        header = list(reader.fieldnames or [])
        absent = [c for c in required if c not in header]
        if absent:
            raise InputFileError(
                path,
                f"missing column(s) {', '.join(absent)} (header: {', '.join(header) or 'none'})",
                line=1,
            )
        return header, list(reader)


def run_sequence_name(folder: Path) -> str:
    """Sequence a run folder belongs to: ``run.json``'s ``"sequence"`` when present, else the
    folder name (runs of different methods on one sequence share the name there)."""
    summary = folder / "run.json"
    if summary.is_file():
        try:
            value = json.loads(summary.read_text()).get("sequence")
        except (json.JSONDecodeError, AttributeError):
            raise InputFileError(summary, "not a JSON object") from None
        if value:
            return str(value)
    return folder.name


def run_report_data(root: str | Path, opts: ReportOptions) -> ReportData:
    """Read one ``slopedist run`` output folder, or a folder of them (one per sequence)."""
    root = Path(root)
    folders = run_folders(root)
    records = Columns(RECORD_COLUMNS)
    theta = Columns(THETA_COLUMNS)
    sets: dict[str, dict[str, ScoredSet]] = {}
    timing_acc: dict[str, list[float]] = {}
    truth_found = False
    theta_truth_seqs: set[str] = set()
    by_seq: dict[str, list[Path]] = {}
    for folder in folders:
        by_seq.setdefault(run_sequence_name(folder), []).append(folder)
    names = list(by_seq)
    for folder in folders:
        seq = run_sequence_name(folder)
        path = folder / "records.csv"
        header, rows = _read_csv(path, ("frame", "method", "distance_m", "status", "reason"))
        truth_col = next((c for c in TRUTH_COLUMNS if c in header), None)
        truth_found |= truth_col is not None
        by_method: dict[str, list[tuple[float, float, str]]] = {}
        for lineno, row in enumerate(rows, start=2):
            method = row["method"]
            if opts.methods and method not in opts.methods:
                continue
            d = _float(row["distance_m"], path, lineno, "distance_m")
            g = _float(row[truth_col], path, lineno, truth_col) if truth_col else math.nan
            frame = int(_float(row["frame"], path, lineno, "frame"))
            reason = row.get("reason", "") or ""
            by_method.setdefault(method, []).append((d, g, reason))
            tid = row.get("track_id", "")
            records.add(
                sequence=seq,
                frame=frame,
                timestamp_s=_float(row.get("timestamp_s", ""), path, lineno, "timestamp_s"),
                track_id=int(_float(tid, path, lineno, "track_id")) if tid else -1,
                method=method,
                rotation="",
                distance_m=d,
                gt_distance_m=g,
                scored=False,
                reason=reason,
                theta_deg=_float(row.get("theta_deg", ""), path, lineno, "theta_deg"),
            )
        sets.setdefault(seq, {})
        for method, vals in by_method.items():
            if method in sets[seq]:
                raise ConfigurationError(
                    f"method {method} appears twice for sequence {seq} (another run folder "
                    f"besides {folder} has it): give one run per method and sequence"
                )
            dist = np.array([v[0] for v in vals])
            gt = np.array([v[1] for v in vals])
            capped, ok = cap_estimates(dist, np.array([v[2] for v in vals], dtype=object))
            ok &= np.isfinite(gt) & (gt > 0)
            sets[seq][method] = ScoredSet(
                capped[ok],
                gt[ok],
                n_gt=int(np.isfinite(gt).sum()),
                n_unscored=int((np.isfinite(gt) & ~ok).sum()),
            )
        _read_frame_log(
            folder, seq, list(by_method), len(by_seq[seq]) > 1, theta, timing_acc, theta_truth_seqs
        )
    methods = sorted({m for s in sets.values() for m in s})
    if not methods:
        raise InputFileError(
            folders[0] / "records.csv",
            "no records" + (f" of method(s) {', '.join(opts.methods)}" if opts.methods else ""),
        )
    # mark which records were scored (same rule as above)
    rec_d, rec_g = records.array("distance_m"), records.array("gt_distance_m")
    capped_all, ok_all = cap_estimates(rec_d, np.asarray(records.data["reason"], dtype=object))
    records.data["distance_m"] = [float(v) if o else math.nan for v, o in zip(capped_all, ok_all)]
    records.data["scored"] = list(ok_all & np.isfinite(rec_g))
    from slopedist.kitti_eval import summarise

    summaries: dict[str, dict[str, dict[str, Any]]] = {}
    pooled: dict[str, list[str]] = {m: [] for m in methods}
    for s in names:
        summaries[s] = {}
        for m in methods:
            if m in sets[s]:
                summaries[s][m] = summarise([sets[s][m]], False)
                pooled[m].append(s)
            else:
                summaries[s][m] = summarise(
                    [ScoredSet(np.zeros(0), np.zeros(0), 0, info={"missing": "not in records"})],
                    False,
                )
    overall = {m: summarise([sets[s][m] for s in pooled[m]], False) for m in methods}
    common = None
    if len({tuple(v) for v in pooled.values()}) > 1:
        shared = [s for s in names if all(s in pooled[m] for m in methods)]
        common = {
            "sequences": shared,
            "methods": {m: summarise([sets[s][m] for s in shared], False) for m in methods},
        }
    timing = {
        m: {
            key: (
                float(np.mean(timing_acc[f"{m}\0{key}"]))
                if f"{m}\0{key}" in timing_acc
                else math.nan
            )
            for key in ("odometry_ms", "estimation_ms", "depth_ms")
        }
        for m in methods
    }
    for m in methods:
        timing[m]["frames"] = float(len(timing_acc.get(f"{m}\0estimation_ms", [])))
    notes = [
        "Source: `slopedist run` output (records.csv, frames.csv) of " + compact_names(names) + ".",
        (
            "Ground truth: column " + ", ".join(TRUTH_COLUMNS) + " of records.csv; the same cap "
            "rule as KITTI (estimates above 80 m count as 80 m, below-horizon targets as 80 m)."
        )
        if truth_found
        else "No ground-truth column in records.csv (" + ", ".join(TRUTH_COLUMNS) + "): "
        "the accuracy tables are empty; distances over time are shown without truth.",
        "Times are the per-frame means of frames.csv (odometry_ms, estimation_ms, depth_ms); "
        "the 2D detector is excluded.",
    ]
    return ReportData(
        title=opts.title,
        source=root,
        kind=SourceKind.RUN,
        methods=methods,
        sequences=names,
        summaries=summaries,
        overall=overall,
        pooled=pooled,
        common=common,
        timing=timing,
        records=records,
        theta=theta,
        protocol={"source": "run", "folders": [str(f) for f in folders]},
        notes=notes,
        truth_source="truth" if theta_truth_seqs else None,
        has_truth=truth_found,
    )


def _uses_rotation(method: str) -> bool:
    """Whether a method uses the camera rotation (its runs are charged the odometry time)."""
    return bool(getattr(ESTIMATORS.get(method), "needs_rotation", True))


def _truth_frame_log(folder: Path) -> Path | None:
    """``frames.csv`` of the ``slopedist simulate`` output a run folder lies in (its true θ),
    if any."""
    parent = folder.parent
    if (
        (parent / "info.json").is_file()
        and (parent / "frames.csv").is_file()
        and (parent / "truth.csv").is_file()
    ):
        return parent / "frames.csv"
    return None


def _read_frame_log(
    folder: Path,
    seq: str,
    methods: list[str],
    shared: bool,
    theta: Columns,
    timing_acc: dict[str, list[float]],
    theta_truth_seqs: set[str],
) -> None:
    """Add a run folder's per-frame θ (source ``run``, or the folder's name when several runs
    share the sequence), the true θ (once per sequence: from the folder's ``frames.csv`` or
    from the simulation it lies in) and the per-frame times of its methods."""
    frames_path = folder / "frames.csv"
    if not frames_path.is_file():
        return
    fheader, frows = _read_csv(frames_path, ("frame",))
    source = folder.name if shared else "run"
    truth_path: Path | None = (
        frames_path if any(c in fheader for c in THETA_TRUTH_COLUMNS) else _truth_frame_log(folder)
    )
    if truth_path is not None and seq not in theta_truth_seqs:
        theader, trows = (
            (fheader, frows) if truth_path == frames_path else _read_csv(truth_path, ("frame",))
        )
        t_col = next((c for c in THETA_TRUTH_COLUMNS if c in theader), None)
        if t_col is not None:
            theta_truth_seqs.add(seq)
            for lineno, row in enumerate(trows, start=2):
                theta.add(
                    sequence=seq,
                    frame=int(_float(row["frame"], truth_path, lineno, "frame")),
                    timestamp_s=_float(
                        row.get("timestamp_s", ""), truth_path, lineno, "timestamp_s"
                    ),
                    source="truth",
                    theta_deg=_float(row[t_col], truth_path, lineno, t_col),
                )
    values = {
        key: [
            _float(row[key], frames_path, lineno, key) for lineno, row in enumerate(frows, start=2)
        ]
        for key in ("theta_deg", "odometry_ms", "estimation_ms", "depth_ms")
        if key in fheader
    }
    if any(math.isfinite(v) for v in values.get("theta_deg", [])):
        for lineno, (row, th) in enumerate(zip(frows, values["theta_deg"]), start=2):
            theta.add(
                sequence=seq,
                frame=int(_float(row["frame"], frames_path, lineno, "frame")),
                timestamp_s=_float(row.get("timestamp_s", ""), frames_path, lineno, "timestamp_s"),
                source=source,
                theta_deg=th,
            )
    for key, column in values.items():
        if key == "theta_deg":
            continue
        finite = [v for v in column if math.isfinite(v)]
        for method in methods if finite else []:
            if key == "odometry_ms" and not _uses_rotation(method):
                continue
            timing_acc.setdefault(f"{method}\0{key}", []).extend(finite)


def _demo_number(results: dict[str, Any], path: Path, *keys: str) -> float:
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


def synthetic_report_data(root: str | Path, opts: ReportOptions) -> ReportData:
    """Read a ``slopedist demo`` output: the per-scenario records (scored against the synthetic
    truth, ``truth_z_m``), θ from ``<scenario>/frames.csv`` against the true θ, and the times
    of ``results.json`` (odometry only for methods fed visual-odometry rotations)."""
    root = Path(root)
    data = run_report_data(root, opts)
    path = root / DEMO_RESULTS
    try:
        results = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise InputFileError(path, f"not valid JSON ({exc})") from None
    if not isinstance(results, dict) or not isinstance(results.get("scenarios"), dict):
        raise InputFileError(path, "lacks 'scenarios' (not a slopedist demo output?)")
    scenarios: dict[str, Any] = results["scenarios"]
    listed = list(results.get("methods") or {})  # the demo's own order of the methods
    data.methods.sort(key=lambda m: listed.index(m) if m in listed else len(listed))
    for m in data.methods:
        est = odo = frames = 0.0
        for name in data.sequences:
            if data.summaries[name][m].get("missing"):
                continue  # no records of m in this scenario
            n = _demo_number(scenarios, path, name, "frames")
            frames += n
            est += n * _demo_number(scenarios, path, name, "methods", m, "estimation_ms_per_frame")
            odo += n * _demo_number(scenarios, path, name, "odometry_ms_per_frame")
        rotation = (results.get("methods") or {}).get(m, {}).get("rotation")
        data.timing[m] = {
            "odometry_ms": odo / frames if frames and rotation == "odometry" else math.nan,
            "estimation_ms": est / frames if frames else math.nan,
            "depth_ms": math.nan,
            "frames": frames,
        }
    config = results.get("config") or {}
    odometry = (
        "the built-in visual odometry on the rendered frames"
        if config.get("odometry", "visual") == "visual"
        else "the TRUE rotations (demo --odometry truth)"
    )
    data.kind = SourceKind.SYNTHETIC
    data.protocol = {
        "source": "synthetic",
        "demo": str(root),
        "config": config,
        "demo_protocol": results.get("protocol"),
    }
    data.notes = [
        "Source: `slopedist demo` output (synthetic hills) of scenarios "
        + compact_names(data.sequences)
        + f"; rotations from {odometry}; noisy detector boxes.",
        "Ground truth: the synthetic targets' KITTI z (camera z of the 3D box's bottom centre); "
        "the same cap rule as KITTI (estimates above 80 m count as 80 m, below-horizon "
        "targets as 80 m).",
        "Methods bound to an IMU get the true rotations with simulated IMU noise; depth-map "
        "methods get the true depth with simulated network noise (no inference, so no depth "
        "time).",
        "Times per frame from results.json: odometry (for methods fed odometry rotations) and "
        "estimation; rendering and the detector are excluded. θ: the odometry's ego gradient "
        "against the true one (frames.csv of each scenario).",
    ]
    return data


def report_data(
    source: str | Path, opts: ReportOptions, on_sequence: Callable[[str], None] | None = None
) -> ReportData:
    """The report's data from any supported source (see :func:`detect_source`)."""
    kind = detect_source(source)
    if kind is SourceKind.KITTI_TRACKING:
        return kitti_report_data(source, opts, on_sequence)
    if kind is SourceKind.SYNTHETIC:
        return synthetic_report_data(source, opts)
    return run_report_data(source, opts)


# --- tables ---------------------------------------------------------------------------------


@dataclass
class Table:
    """A rendered-anywhere table: header, rows of values, which cells are bold, a note."""

    key: str
    title: str
    headers: list[str]
    rows: list[list[Any]]
    bold: list[list[bool]]
    note: str = ""
    formats: dict[int, str] = field(default_factory=dict)

    def cell(self, i: int, j: int) -> str:
        v = self.rows[i][j]
        if isinstance(v, float):
            return "-" if not math.isfinite(v) else format(v, self.formats.get(j, ".2f"))
        return str(v)


def _best(values: Sequence[Any], larger_is_better: bool = False) -> list[bool]:
    arr = np.array(
        [v if isinstance(v, float) and math.isfinite(v) else np.nan for v in values], dtype=float
    )
    if not np.isfinite(arr).any():
        return [False] * len(values)
    best = np.nanmax(arr) if larger_is_better else np.nanmin(arr)
    return [bool(np.isfinite(a) and abs(a - best) < 5e-3) for a in arr]


def table1(data: ReportData) -> Table:
    """RMSE (m) per sequence × method; best per row in bold."""
    rows: list[list[Any]] = []
    bold: list[list[bool]] = []
    for s in data.sequences:
        ns = [data.summaries[s][m]["n"] for m in data.methods if data.summaries[s][m]["n"]]
        vals = [float(data.summaries[s][m]["rmse"]) for m in data.methods]
        rows.append([s, max(ns) if ns else 0, *vals])
        bold.append([False, False, *_best(vals)])
    vals = [float(data.overall[m]["rmse"]) for m in data.methods]
    rows.append(["overall", max(int(data.overall[m]["n"]) for m in data.methods), *vals])
    # overall rows pooled over different sequences are not compared: no best there
    bold.append([False, False, *(_best(vals) if data.common is None else [False] * len(vals))])
    notes = []
    for m in data.methods:
        miss = {
            s: data.summaries[s][m]["missing"]
            for s in data.sequences
            if data.summaries[s][m].get("missing")
        }
        if miss:
            notes.append(
                f"{m}: no result on {', '.join(miss)} ({next(iter(miss.values()))}); "
                f"its overall pools {compact_names(data.pooled[m]) or 'nothing'}."
            )
    if data.common is not None:
        cm = data.common["methods"]
        vals = [float(cm[m]["rmse"]) for m in data.methods]
        rows.append(["common", max(int(cm[m]["n"]) for m in data.methods), *vals])
        bold.append([False, False, *_best(vals)])
        notes.append(
            "common: every method pooled over the sequences all of them ran on ("
            + (compact_names(data.common["sequences"]) or "none")
            + ")."
        )
    else:
        notes.append("overall: pooled over all targets of " + compact_names(data.sequences) + ".")
    return Table(
        "table1_rmse",
        "Table 1: RMSE (m) per sequence and method",
        ["sequence", "n", *data.methods],
        rows,
        bold,
        "\n".join(notes),
        {1: "d"},
    )


EXT_KEYS = (
    ("n", "n", None),
    ("rmse", "RMSE", False),
    ("mae", "MAE", False),
    ("abs_rel", "AbsRel", False),
    ("sq_rel", "SqRel", False),
    ("rmse_log", "RMSElog", False),
    ("delta_1.25", "δ<1.25", True),
    ("delta_1.25^2", "δ<1.25²", True),
    ("delta_1.25^3", "δ<1.25³", True),
)


def extended_table(
    data: ReportData, scope: dict[str, dict[str, Any]], title: str, key: str, compare: bool = True
) -> Table:
    """Overall metrics per method (errors: lower is better; δ: higher is better); best in bold
    when ``compare`` (the methods were scored on the same targets)."""
    rows = [
        [m, *(float(scope[m][k]) if k != "n" else int(scope[m][k]) for k, _, _ in EXT_KEYS)]
        for m in data.methods
    ]
    bold = [[False] * (len(EXT_KEYS) + 1) for _ in rows]
    for j, (_, _, larger) in enumerate(EXT_KEYS, start=1):
        if larger is None or not compare:
            continue
        for i, b in enumerate(_best([r[j] for r in rows], larger)):
            bold[i][j] = b
    fmts = {1: "d", 4: ".3f", 5: ".3f", 6: ".3f", 7: ".3f", 8: ".3f", 9: ".3f"}
    return Table(
        key, title, ["method", *(label for _, label, _ in EXT_KEYS)], rows, bold, formats=fmts
    )


def bins_table(data: ReportData, scope: dict[str, dict[str, Any]], pooled_note: str) -> Table:
    """RMSE, AbsRel and δ<1.25 per ground-truth distance bin and method."""
    rows: list[list[Any]] = []
    bold: list[list[bool]] = []
    for lo, hi in DISTANCE_BINS_M:
        label = f"{lo:g}-{hi:g}"
        block = [
            [
                label,
                m,
                int(scope[m]["bins"][label]["n"]),
                float(scope[m]["bins"][label]["rmse"]),
                float(scope[m]["bins"][label]["abs_rel"]),
                float(scope[m]["bins"][label]["delta_1.25"]),
            ]
            for m in data.methods
        ]
        marks = [[False] * 6 for _ in block]
        for j, larger in ((3, False), (4, False), (5, True)):
            for i, b in enumerate(_best([r[j] for r in block], larger)):
                marks[i][j] = b
        rows += block
        bold += marks
    return Table(
        "metrics_by_distance",
        "Metrics per ground-truth distance bin (m)",
        ["bin (m)", "method", "n", "RMSE", "AbsRel", "δ<1.25"],
        rows,
        bold,
        pooled_note,
        {2: "d", 4: ".3f", 5: ".3f"},
    )


def table2(data: ReportData) -> Table:
    """Time per frame per method (ms): odometry, estimation, depth; detector excluded."""
    rows = []
    for m in data.methods:
        t = data.timing[m]
        parts = [t["odometry_ms"], t["estimation_ms"], t["depth_ms"]]
        finite = [p for p in parts if math.isfinite(p)]
        rows.append([m, *parts, float(sum(finite)) if finite else math.nan])
    bold = [[False, False, False, False, b] for b in _best([r[4] for r in rows])]
    note = (
        "Time per frame in milliseconds, averaged over every frame of the sequences each "
        "method ran on; '-' = not applicable or not measured. The 2D detector is excluded "
        "(shared by every method)."
    )
    return Table(
        "table2_time",
        "Table 2: time per frame (ms)",
        ["method", "odometry", "estimation", "depth", "total"],
        rows,
        bold,
        note,
        {1: ".3f", 2: ".3f", 3: ".3f", 4: ".3f"},
    )


def theta_table(data: ReportData) -> Table | None:
    """RMS and largest difference between each rotation source's θ and the truth's (deg)."""
    if data.truth_source is None or not len(data.theta):
        return None
    seq = np.asarray(data.theta.data["sequence"], dtype=object)
    src = np.asarray(data.theta.data["source"], dtype=object)
    frame = data.theta.array("frame", int)
    th = data.theta.array("theta_deg")
    others = sorted(set(src) - {data.truth_source})
    rows: list[list[Any]] = []
    for s in data.sequences:
        truth = (seq == s) & (src == data.truth_source)
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
                rows.append(
                    [
                        s,
                        o,
                        int(diffs.size),
                        float(np.sqrt(np.mean(diffs**2))),
                        float(np.max(np.abs(diffs))),
                        float(np.sqrt(np.mean(th[truth] ** 2))),
                    ]
                )
    if not rows:
        return None
    return Table(
        "theta_agreement",
        f"Ego gradient θ against {_truth_name(data)} (deg)",
        ["sequence", "source", "frames", "RMS diff", "max |diff|", "RMS θ truth"],
        rows,
        [[False] * 6 for _ in rows],
        "θ of eq. 4 over the 1 s look-back, per frame, in degrees.",
        {2: "d", 3: ".3f", 4: ".3f", 5: ".3f"},
    )


def _truth_name(data: ReportData) -> str:
    """Words for the θ truth source: the OXTS (IMU) truth, or the true θ of a simulation."""
    if data.truth_source == "truth":
        return "the true θ" + (" of the simulation" if data.kind is SourceKind.SYNTHETIC else "")
    return f"the {data.truth_source} (IMU) truth"


def report_tables(data: ReportData) -> list[Table]:
    """Every table of the report, in page order."""
    tables: list[Table] = []
    if data.has_truth:
        tables.append(table1(data))
        if data.common is not None:
            tables.append(
                extended_table(
                    data,
                    data.common["methods"],
                    "Extended metrics, every method on the common sequences ("
                    + compact_names(data.common["sequences"])
                    + ")",
                    "metrics_common",
                )
            )
            tables.append(
                bins_table(data, data.common["methods"], "Pooled over the common sequences.")
            )
        tables.append(
            extended_table(
                data,
                data.overall,
                "Extended metrics, overall (each method pooled over the sequences it ran on)",
                "metrics_overall",
                compare=data.common is None,
            )
        )
        if data.common is None:
            tables.append(bins_table(data, data.overall, "Pooled over all sequences."))
    tables.append(table2(data))
    th = theta_table(data)
    if th is not None:
        tables.append(th)
    return tables


def format_text(table: Table) -> str:
    """Plain text, best values marked with ``*``."""
    rows = [
        [table.cell(i, j) + ("*" if table.bold[i][j] else "") for j in range(len(table.headers))]
        for i in range(len(table.rows))
    ]
    return (
        table.title
        + "\n"
        + format_table(table.headers, rows)
        + ("\n" + table.note if table.note else "")
    )


def format_markdown(table: Table) -> str:
    """GitHub Markdown, best values in bold."""

    def md(i: int, j: int) -> str:
        c = table.cell(i, j)
        return f"**{c}**" if table.bold[i][j] else c

    lines = [
        f"### {table.title}",
        "",
        "| " + " | ".join(table.headers) + " |",
        "|" + "|".join("---:" if j else ":---" for j in range(len(table.headers))) + "|",
    ]
    lines += [
        "| " + " | ".join(md(i, j) for j in range(len(table.headers))) + " |"
        for i in range(len(table.rows))
    ]
    if table.note:
        lines += ["", *(f"{n}  " for n in table.note.splitlines())]
    return "\n".join(lines)


def format_html(table: Table) -> str:
    """An HTML ``<table>`` with a caption; best values in ``<b>``."""

    def td(i: int, j: int) -> str:
        c = html.escape(table.cell(i, j))
        return f"<td><b>{c}</b></td>" if table.bold[i][j] else f"<td>{c}</td>"

    head = "".join(f"<th>{html.escape(h)}</th>" for h in table.headers)
    body = "\n".join(
        "<tr>" + "".join(td(i, j) for j in range(len(table.headers))) + "</tr>"
        for i in range(len(table.rows))
    )
    note = (
        ('<p class="note">' + "<br>".join(html.escape(n) for n in table.note.splitlines()) + "</p>")
        if table.note
        else ""
    )
    return (
        f'<section id="{table.key}"><h2>{html.escape(table.title)}</h2>\n'
        f"<table><thead><tr>{head}</tr></thead><tbody>\n{body}\n</tbody></table>{note}"
        f"</section>"
    )


# --- figures --------------------------------------------------------------------------------


@dataclass
class Figure:
    """A figure: file name, caption, PNG bytes."""

    name: str
    caption: str
    png: bytes


def _png(fig: Any) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return buf.getvalue()


def choose_tracks(data: ReportData, n: int) -> list[tuple[str, int]]:
    """The longest track (most frames with truth) of each of the ``n`` sequences whose longest
    tracks are longest."""
    seq = np.asarray(data.records.data["sequence"], dtype=object)
    tid = data.records.array("track_id", int)
    best: dict[str, tuple[int, int]] = {}
    for s in data.sequences:
        sel = (seq == s) & (tid >= 0)
        if not sel.any():
            continue
        ids, counts = np.unique(tid[sel], return_counts=True)
        k = int(np.argmax(counts))
        best[s] = (int(counts[k]), int(ids[k]))
    ranked = sorted(best.items(), key=lambda kv: -kv[1][0])[:n]
    return [(s, t) for s, (_, t) in sorted(ranked)]


def _colors(methods: Sequence[str]) -> dict[str, Any]:
    import matplotlib

    cmap = matplotlib.colormaps["tab10"]
    return {m: cmap(i % 10) for i, m in enumerate(methods)}


def figure_tracks(data: ReportData, tracks: Sequence[tuple[str, int]]) -> Figure | None:
    """Distance vs. truth over time for the chosen tracks."""
    import matplotlib.pyplot as plt

    if not tracks:
        return None
    seq = np.asarray(data.records.data["sequence"], dtype=object)
    tid = data.records.array("track_id", int)
    meth = np.asarray(data.records.data["method"], dtype=object)
    t = data.records.array("timestamp_s")
    d = data.records.array("distance_m")
    g = data.records.array("gt_distance_m")
    colors = _colors(data.methods)
    fig, axes = plt.subplots(len(tracks), 1, figsize=(9, 2.6 * len(tracks)), squeeze=False)
    for ax, (s, track) in zip(axes[:, 0], tracks):
        sel = (seq == s) & (tid == track)
        if not sel.any():
            raise ConfigurationError(f"track {track} of sequence {s} has no records to plot")
        for m in data.methods:
            ms = sel & (meth == m)
            order = np.argsort(t[ms])
            ax.plot(t[ms][order], d[ms][order], ".-", ms=3, lw=1, color=colors[m], label=m)
        first = sel & (meth == data.methods[0]) if (sel & (meth == data.methods[0])).any() else sel
        order = np.argsort(t[first])
        if np.isfinite(g[first]).any():
            ax.plot(t[first][order], g[first][order], "k-", lw=2, label="truth")
        ax.set_title(f"sequence {s}, track {track}", fontsize=9)
        ax.set_ylabel("distance (m)")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time (s)")
    axes[0, 0].legend(fontsize=7, ncol=min(len(data.methods) + 1, 7), loc="upper right")
    fig.tight_layout()
    return Figure(
        "distance_over_time.png",
        "Estimated distance against the truth over time for chosen tracks "
        "(capped at 80 m; gaps are frames without an estimate).",
        _png(fig),
    )


def figure_error_vs_distance(data: ReportData) -> Figure | None:
    """RMSE and mean signed error per 5 m ground-truth bin, per method."""
    import matplotlib.pyplot as plt

    meth = np.asarray(data.records.data["method"], dtype=object)
    d = data.records.array("distance_m")
    g = data.records.array("gt_distance_m")
    scored = np.asarray(data.records.data["scored"], dtype=bool)
    where = "every sequence"
    if data.common is not None:
        scored &= np.isin(
            np.asarray(data.records.data["sequence"], dtype=object), data.common["sequences"]
        )
        where = (
            "the sequences every method ran on (" + compact_names(data.common["sequences"]) + ")"
        )
    if not (scored & np.isfinite(g)).any():
        return None
    edges = np.arange(0.0, 80.0 + ERROR_BIN_M, ERROR_BIN_M)
    centres = 0.5 * (edges[1:] + edges[:-1])
    colors = _colors(data.methods)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.6))
    for m in data.methods:
        sel = scored & (meth == m)
        err = d[sel] - g[sel]
        idx = np.digitize(g[sel], edges, right=True) - 1
        rmse = [
            np.sqrt(np.mean(err[idx == b] ** 2)) if (idx == b).sum() >= 5 else np.nan
            for b in range(len(centres))
        ]
        bias = [
            np.mean(err[idx == b]) if (idx == b).sum() >= 5 else np.nan for b in range(len(centres))
        ]
        a1.plot(centres, rmse, "o-", ms=3, color=colors[m], label=m)
        a2.plot(centres, bias, "o-", ms=3, color=colors[m], label=m)
    a1.set(xlabel="true distance (m)", ylabel="RMSE (m)", title="RMSE per 5 m bin")
    a2.set(
        xlabel="true distance (m)",
        ylabel="mean error (m)",
        title="mean signed error (estimate - truth)",
    )
    a2.axhline(0, color="k", lw=0.8)
    for a in (a1, a2):
        a.grid(alpha=0.3)
    a1.legend(fontsize=7)
    fig.tight_layout()
    return Figure(
        "error_vs_distance.png",
        f"Error against the true distance per method, pooled over {where} (bins "
        f"with at least 5 targets).",
        _png(fig),
    )


def figure_theta(data: ReportData, max_panels: int = 12) -> Figure | None:
    """θ over time per sequence: every rotation source, the truth source in black."""
    import matplotlib.pyplot as plt

    if not len(data.theta):
        return None
    seq = np.asarray(data.theta.data["sequence"], dtype=object)
    src = np.asarray(data.theta.data["source"], dtype=object)
    t = data.theta.array("timestamp_s")
    th = data.theta.array("theta_deg")
    shown = [s for s in data.sequences if (seq == s).any()]
    if data.truth_source is not None:
        with_truth = [s for s in shown if ((seq == s) & (src == data.truth_source)).any()]
        shown = with_truth or shown
    shown = shown[:max_panels]
    cols = min(3, len(shown))
    rows = math.ceil(len(shown) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 2.3 * rows), squeeze=False)
    for ax in axes.ravel()[len(shown) :]:
        ax.axis("off")
    for ax, s in zip(axes.ravel(), shown):
        # the truth first, wide and grey, so that the sources drawn over it stay visible
        for source in sorted(set(src[seq == s]), key=lambda x: x != data.truth_source):
            sel = (seq == s) & (src == source)
            truth = source == data.truth_source
            ax.plot(
                t[sel],
                th[sel],
                "-",
                lw=3.0 if truth else 1.0,
                color="0.6" if truth else None,
                label=(source if source == "truth" else f"{source} (truth)") if truth else source,
            )
        ax.set_title(f"sequence {s}", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("θ (deg)")
    axes[0, 0].legend(fontsize=7)
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    what = f"against {_truth_name(data)}" if data.truth_source else "(no IMU truth in this source)"
    return Figure(
        "theta_over_time.png",
        f"Ego road gradient θ (eq. 4, 1 s look-back) over time {what}.",
        _png(fig),
    )


def report_figures(
    data: ReportData, tracks: Sequence[tuple[str, int]] | None, n_tracks: int
) -> list[Figure]:
    """Every figure of the report (matplotlib, Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")
    chosen = list(tracks) if tracks else choose_tracks(data, n_tracks)
    figs = [figure_tracks(data, chosen), figure_error_vs_distance(data), figure_theta(data)]
    return [f for f in figs if f is not None]


# --- writing --------------------------------------------------------------------------------

HTML_SCRIPT = """<script>
window.addEventListener('load', function () {
  var imgs = document.querySelectorAll('img.figure');
  var ok = 0;
  imgs.forEach(function (im) { if (im.complete && im.naturalWidth > 0) { ok += 1; } });
  document.body.setAttribute('data-figures-total', String(imgs.length));
  document.body.setAttribute('data-figures-loaded', String(ok));
});
</script>"""
"""Sets ``data-figures-loaded`` / ``data-figures-total`` on ``<body>`` once the page has loaded:
the number of embedded figures that decoded (``naturalWidth > 0``), for automated checks."""

HTML_STYLE = """<style>
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1100px; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
thead { background: #f0f0f0; } .note { font-size: 0.85em; color: #555; max-width: 60em; }
figure { margin: 1em 0; } img.figure { max-width: 100%; border: 1px solid #ddd; }
</style>"""


def write_columns(columns: Columns, path: Path, parquet: bool) -> list[Path]:
    """Write a column table as CSV (and Parquet when ``parquet``); returns the files."""
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(columns.names)
        for i in range(len(columns)):
            w.writerow([_csv_value(columns.data[n][i]) for n in columns.names])
    written = [path]
    if parquet:
        import pyarrow as pa
        import pyarrow.parquet as pq

        pq.write_table(
            pa.table({n: columns.data[n] for n in columns.names}), path.with_suffix(".parquet")
        )
        written.append(path.with_suffix(".parquet"))
    return written


def _csv_value(v: Any) -> Any:
    if isinstance(v, (float, np.floating)):
        return "" if not math.isfinite(float(v)) else f"{float(v):.6g}"
    if isinstance(v, (bool, np.bool_)):
        return int(v)
    return v


def table_columns(table: Table) -> Columns:
    """A table's numbers as columns (bold marks dropped)."""
    cols = Columns(tuple(table.headers))
    for row in table.rows:
        cols.add(**dict(zip(table.headers, row)))
    return cols


def metrics_columns(data: ReportData) -> Columns:
    """Every metric of every scope in long form: scope, sequence, method, bin, metric, value."""
    cols = Columns(("scope", "sequence", "method", "bin_m", "metric", "value"))

    def emit(scope: str, seq: str, m: str, summary: dict[str, Any]) -> None:
        for k, v in summary.items():
            if k == "bins":
                for b, bm in v.items():
                    for bk, bv in bm.items():
                        cols.add(
                            scope=scope, sequence=seq, method=m, bin_m=b, metric=bk, value=float(bv)
                        )
            elif isinstance(v, (int, float)):
                cols.add(scope=scope, sequence=seq, method=m, bin_m="all", metric=k, value=float(v))

    for s in data.sequences:
        for m in data.methods:
            emit("sequence", s, m, data.summaries[s][m])
    for m in data.methods:
        emit("overall", ",".join(data.pooled[m]), m, data.overall[m])
    if data.common is not None:
        for m in data.methods:
            emit("common", ",".join(data.common["sequences"]), m, data.common["methods"][m])
    for m in data.methods:
        for k, v in data.timing[m].items():
            cols.add(scope="timing", sequence="", method=m, bin_m="all", metric=k, value=float(v))
    return cols


def parquet_available() -> bool:
    """Whether pyarrow (optional extra ``parquet``) is installed."""
    return importlib.util.find_spec("pyarrow") is not None


@dataclass
class WrittenReport:
    """What :func:`write_report` produced."""

    out_dir: Path
    tables: list[Table]
    figures: list[Figure]
    files: list[Path]


def write_report(
    data: ReportData,
    out_dir: str | Path,
    tracks: Sequence[tuple[str, int]] | None = None,
    n_tracks: int = 4,
    parquet: bool | None = None,
) -> WrittenReport:
    """Write ``report.md``, ``report.html``, figures, JSON, CSV (and Parquet) under ``out_dir``.

    Files are written one by one as soon as each is ready.
    """
    out = Path(out_dir)
    (out / "figures").mkdir(parents=True, exist_ok=True)
    use_parquet = parquet_available() if parquet is None else parquet
    files: list[Path] = []
    tables = report_tables(data)
    for t in tables:
        files += write_columns(table_columns(t), out / f"{t.key}.csv", use_parquet)
    files += write_columns(metrics_columns(data), out / "metrics.csv", use_parquet)
    files += write_columns(data.records, out / "records.csv", use_parquet)
    if len(data.theta):
        files += write_columns(data.theta, out / "theta.csv", use_parquet)
    (out / "report.json").write_text(
        json.dumps(
            _json_ready(
                {
                    "title": data.title,
                    "source": str(data.source),
                    "kind": data.kind.value,
                    "protocol": data.protocol,
                    "methods": data.methods,
                    "sequences": data.sequences,
                    "sequence_summaries": data.summaries,
                    "overall": data.overall,
                    "pooled": data.pooled,
                    "overall_common": data.common,
                    "timing": data.timing,
                    "notes": data.notes,
                }
            ),
            indent=1,
            allow_nan=False,
        )
        + "\n"
    )
    files.append(out / "report.json")
    figures = report_figures(data, tracks, n_tracks)
    for f in figures:
        (out / "figures" / f.name).write_bytes(f.png)
        files.append(out / "figures" / f.name)
    intro = [
        f"Source: `{data.source}` ({data.kind.value}); methods: "
        f"{', '.join(data.methods)}; sequences: {compact_names(data.sequences)}.",
        *data.notes,
    ]
    md = [f"# {data.title}", "", *[f"- {n}" for n in intro], ""]
    for t in tables:
        md += [format_markdown(t), ""]
    for f in figures:
        md += [f"![{f.caption}](figures/{f.name})", "", f"*{f.caption}*", ""]
    (out / "report.md").write_text("\n".join(md))
    files.append(out / "report.md")
    body = [
        f"<h1>{html.escape(data.title)}</h1>",
        "<ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in intro) + "</ul>",
    ]
    body += [format_html(t) for t in tables]
    for f in figures:
        b64 = base64.b64encode(f.png).decode("ascii")
        body.append(
            f'<figure><img class="figure" alt="{html.escape(f.caption)}" '
            f'src="data:image/png;base64,{b64}"><figcaption>{html.escape(f.caption)}'
            f"</figcaption></figure>"
        )
    page = (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{html.escape(data.title)}</title>{HTML_STYLE}</head>\n<body>\n"
        + "\n".join(body)
        + f"\n{HTML_SCRIPT}\n</body></html>\n"
    )
    (out / "report.html").write_text(page)
    files.append(out / "report.html")
    return WrittenReport(out, tables, figures, files)


def _json_ready(value: Any) -> Any:
    """Plain JSON types, NaN/inf as null."""
    if isinstance(value, dict):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        value = value.item()
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    return value
