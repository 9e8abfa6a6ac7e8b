"""Distance metrics, detection-to-truth matching, and pooling scores over sequences.

Distances in metres. Metrics follow the depth-estimation literature (Eigen et al.): RMSE, MAE,
AbsRel, SqRel, RMSE-log and the δ < 1.25^k accuracies.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.core.errors import InputFileError
from slopedist.estimators.base import EstimateStatus, MissingReason
from slopedist.io.detections.boxes import BoxTable, iou_matrix

DISTANCE_BINS_M: tuple[tuple[float, float], ...] = (
    (0.0, 10.0),
    (10.0, 20.0),
    (20.0, 30.0),
    (30.0, 40.0),
    (40.0, 80.0),
)
"""Ground-truth distance bins of the per-bin tables, metres (lower bound exclusive)."""

METRIC_KEYS = (
    "n",
    "rmse",
    "mae",
    "abs_rel",
    "sq_rel",
    "rmse_log",
    "delta_1.25",
    "delta_1.25^2",
    "delta_1.25^3",
)


def distance_metrics(pred_m: ArrayLike, gt_m: ArrayLike) -> dict[str, float]:
    """Error metrics of predicted vs. true distances (both metres, same shape, positive).

    Returns a dict with the keys of :data:`METRIC_KEYS`; with no pairs, ``n = 0`` and NaNs.

    Example:
        >>> m = distance_metrics([10.0, 21.0], [10.0, 20.0])
        >>> m["n"], round(m["rmse"], 3), m["mae"]
        (2, 0.707, 0.5)
    """
    p = np.asarray(pred_m, dtype=float).ravel()
    g = np.asarray(gt_m, dtype=float).ravel()
    if p.size == 0:
        return {k: (0 if k == "n" else math.nan) for k in METRIC_KEYS}
    err = p - g
    ratio = np.maximum(p / g, g / p)
    return {
        "n": int(p.size),
        "rmse": float(np.sqrt(np.mean(err**2))),
        "mae": float(np.mean(np.abs(err))),
        "abs_rel": float(np.mean(np.abs(err) / g)),
        "sq_rel": float(np.mean(err**2 / g)),
        "rmse_log": float(np.sqrt(np.mean((np.log(p) - np.log(g)) ** 2))),
        "delta_1.25": float(np.mean(ratio < 1.25)),
        "delta_1.25^2": float(np.mean(ratio < 1.25**2)),
        "delta_1.25^3": float(np.mean(ratio < 1.25**3)),
    }


def bin_label(lo: float, hi: float) -> str:
    """Name of a distance bin, e.g. ``"10-20"``."""
    return f"{lo:g}-{hi:g}"


def binned_metrics(
    pred_m: ArrayLike, gt_m: ArrayLike, bins: Sequence[tuple[float, float]] = DISTANCE_BINS_M
) -> dict[str, dict[str, float]]:
    """:func:`distance_metrics` per ground-truth distance bin ``(lo, hi]``."""
    p = np.asarray(pred_m, dtype=float)
    g = np.asarray(gt_m, dtype=float)
    return {
        bin_label(lo, hi): distance_metrics(p[(g > lo) & (g <= hi)], g[(g > lo) & (g <= hi)])
        for lo, hi in bins
    }


AT_CAP_REASONS = (
    MissingReason.BELOW_HORIZON.value,
    MissingReason.NEAR_HORIZON.value,
    MissingReason.BEYOND_RESOLUTION.value,
)
"""The missing reasons a target is counted at the cap for (:func:`cap_estimates`): its box
bottom at or above the vanishing line, or too near it for eq. 1, or a box or distance beyond
what the image resolves (hundreds of metres: an ``ok`` distance there was capped too)."""


RECORD_STATUSES = tuple(s.value for s in EstimateStatus)
"""The values of a records file's ``status`` column."""


def record_reason(status: str | None, reason: str | None, path: Path | str, line: int) -> str:
    """The ``reason`` of one row of a run's ``records.csv``, checked against its ``status``
    (scoring goes by the reason, :func:`cap_estimates`, so the two must agree): ``ok`` has no
    reason, ``upper_bound`` and ``missing`` have one.

    Raises:
        InputFileError: an unknown status (a hand-edited ``OK``), or a status the reason
            contradicts (naming file, line and field).
    """
    status, reason = (status or "").strip(), (reason or "").strip()
    if status not in RECORD_STATUSES:
        raise InputFileError(
            path,
            f"'{status}' is not a record status; expected one of {', '.join(RECORD_STATUSES)}",
            line=line,
            field="status",
        )
    if (status == EstimateStatus.OK.value) != (reason == ""):
        said = f"reason '{reason}'" if reason else "no reason"
        raise InputFileError(
            path,
            f"a record of status {status} has {said} (an ok record has none, an upper_bound "
            "or missing record says why)",
            line=line,
            field="reason",
        )
    return reason


def cap_estimates(
    distance_m: ArrayLike, reason: ArrayLike, cap_m: float = 80.0
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Apply the published protocol's cap: estimates above ``cap_m`` become ``cap_m`` and a
    target below the horizon (``u ≤ v``, reason ``below_horizon``) or too near it for eq. 1 to
    tell its distance (``near_horizon``, hundreds of metres), or beyond what the image resolves
    (``beyond_resolution``: a box under 2 px tall, a distance beyond ``f·h/2``), counts as
    ``cap_m``.

    Returns:
        The capped distances and a mask of the entries that can be scored (other reasons,
        such as ``no_rotation``, stay unscored and are counted apart; so does an
        ``upper_bound``, whose reason ``cut_bottom`` marks a distance that is only a bound).
    """
    d = np.asarray(distance_m, dtype=float).copy()
    r = np.asarray(reason, dtype=object)
    at_cap = np.isin(r, AT_CAP_REASONS)
    d[(r != "") & ~at_cap] = np.nan
    d[at_cap] = cap_m
    d = np.minimum(d, cap_m)
    return d, np.isfinite(d)


def match_boxes(
    det_boxes: ArrayLike, gt_boxes: ArrayLike, min_iou: float = 0.5
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Greedy one-to-one matching by 2D IoU, best pair first.

    All detection–truth pairs with IoU ≥ ``min_iou`` are taken in order of decreasing IoU, each
    box used at most once.

    Returns:
        ``(det_index, gt_index)`` arrays of the matched pairs.
    """
    iou = iou_matrix(det_boxes, gt_boxes)
    if iou.size == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    di, gi = np.nonzero(iou >= min_iou)
    order = np.argsort(-iou[di, gi], kind="stable")
    used_d: set[int] = set()
    used_g: set[int] = set()
    out_d, out_g = [], []
    for k in order:
        d, g = int(di[k]), int(gi[k])
        if d in used_d or g in used_g:
            continue
        used_d.add(d)
        used_g.add(g)
        out_d.append(d)
        out_g.append(g)
    return np.asarray(out_d, np.intp), np.asarray(out_g, np.intp)


def match_by_frame(
    det: BoxTable, gt: BoxTable, min_iou: float = 0.5
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """:func:`match_boxes` frame by frame; returns row indices into ``det`` and ``gt``.

    Example:
        >>> det = BoxTable.build([0, 0], [[0, 0, 10, 10], [50, 50, 60, 60]])
        >>> gt = BoxTable.build([0], [[49, 50, 60, 61]])
        >>> [rows.tolist() for rows in match_by_frame(det, gt)]
        [[1], [0]]
    """
    det_rows: list[NDArray[np.intp]] = []
    gt_rows: list[NDArray[np.intp]] = []
    for k in np.intersect1d(det.frames(), gt.frames()):
        di = np.flatnonzero(det.frame == k)
        gi = np.flatnonzero(gt.frame == k)
        md, mg = match_boxes(det.boxes[di], gt.boxes[gi], min_iou)
        det_rows.append(di[md])
        gt_rows.append(gi[mg])
    if not det_rows:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    return np.concatenate(det_rows), np.concatenate(gt_rows)


SIGMA_LEVELS: tuple[int, ...] = (1, 2, 3)
"""Multiples k of a method's own 1σ whose coverage (share of errors within k·σ) is reported."""

GAUSSIAN_COVERAGE: dict[int, float] = {1: 0.6827, 2: 0.9545, 3: 0.9973}
"""The share of a Gaussian within k σ: what :func:`uncertainty_metrics` gives for a right σ."""

UNCERTAINTY_KEYS = ("n_sigma", *(f"within_{k}sigma" for k in SIGMA_LEVELS), "z_rms")


def uncertainty_metrics(pred_m: ArrayLike, gt_m: ArrayLike, sigma_m: ArrayLike) -> dict[str, float]:
    """How well a method's own 1σ (``sigma_m``, metres, one per prediction) describes its
    errors: ``within_{k}sigma`` = the share of |prediction − truth| ≤ k·σ for k in
    :data:`SIGMA_LEVELS` (a right, Gaussian σ gives :data:`GAUSSIAN_COVERAGE`; less means
    the σ promises more than the estimates keep), and ``z_rms`` = the RMS of (prediction −
    truth)/σ (1 for a right σ). Predictions without a finite positive σ are left out;
    ``n_sigma`` counts the others (0 and NaNs when none)."""
    p = np.asarray(pred_m, dtype=float).ravel()
    g = np.asarray(gt_m, dtype=float).ravel()
    s = np.asarray(sigma_m, dtype=float).ravel()
    keep = np.isfinite(s) & (s > 0)
    if not keep.any():
        return {k: (0 if k == "n_sigma" else math.nan) for k in UNCERTAINTY_KEYS}
    z = (p[keep] - g[keep]) / s[keep]
    out: dict[str, float] = {"n_sigma": int(keep.sum())}
    out.update({f"within_{k}sigma": float(np.mean(np.abs(z) <= k)) for k in SIGMA_LEVELS})
    out["z_rms"] = float(np.sqrt(np.mean(z * z)))
    return out


def reported_sigma(sigma_m: ArrayLike, keep: NDArray[np.bool_]) -> NDArray[np.float64] | None:
    """The σ (m) of the kept predictions for :attr:`ScoredSet.sigma_m`: None when the method
    reports none (no finite value among all of its predictions, e.g. an empty column)."""
    sigma = np.asarray(sigma_m, dtype=float)
    return sigma[keep] if np.isfinite(sigma).any() else None


@dataclass
class ScoredSet:
    """Paired predictions and truths of one sequence and method, with bookkeeping;
    ``sigma_m``: the method's own 1σ of each prediction (metres), None when it reports none."""

    pred_m: NDArray[np.float64]
    gt_m: NDArray[np.float64]
    n_gt: int
    n_unscored: int = 0
    seconds: float = 0.0
    frames: int = 0
    info: dict[str, Any] = field(default_factory=dict)
    sigma_m: NDArray[np.float64] | None = None

    def summary(self, with_recall: bool) -> dict[str, Any]:
        """Metrics, per-bin metrics, counts and time per frame as a JSON-ready dict."""
        out: dict[str, Any] = dict(distance_metrics(self.pred_m, self.gt_m))
        out["n_gt"] = self.n_gt
        out["n_unscored"] = self.n_unscored
        if with_recall:
            out["recall"] = (len(self.pred_m) + self.n_unscored) / self.n_gt if self.n_gt else 0.0
        out["ms_per_frame"] = 1000.0 * self.seconds / self.frames if self.frames else math.nan
        out["bins"] = binned_metrics(self.pred_m, self.gt_m)
        if self.sigma_m is not None:
            out["uncertainty"] = uncertainty_metrics(self.pred_m, self.gt_m, self.sigma_m)
        return out


def pool(sets: Sequence[ScoredSet]) -> ScoredSet:
    """Pool several sequences' pairs into one set (overall = pooled over all targets); with
    σ only when every set has one."""
    with_sigma = bool(sets) and all(s.sigma_m is not None for s in sets)
    return ScoredSet(
        np.concatenate([s.pred_m for s in sets]) if sets else np.zeros(0),
        np.concatenate([s.gt_m for s in sets]) if sets else np.zeros(0),
        sum(s.n_gt for s in sets),
        sum(s.n_unscored for s in sets),
        sum(s.seconds for s in sets),
        sum(s.frames for s in sets),
        sigma_m=np.concatenate([s.sigma_m for s in sets if s.sigma_m is not None])
        if with_sigma
        else None,
    )


class Stopwatch:
    """Accumulates wall time (``time.perf_counter``) over ``with`` blocks, in seconds."""

    def __init__(self) -> None:
        self.seconds = 0.0

    def __enter__(self) -> Stopwatch:
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        self.seconds += time.perf_counter() - self._t0


def compact_names(names: Sequence[str]) -> str:
    """``["0000", "0001", "0002", "0005"]`` → ``"0000-0002, 0005"`` (runs of consecutive
    numbered names collapsed; other names kept as they are)."""
    parts: list[str] = []
    run: list[str] = []

    def flush() -> None:
        if run:
            parts.append(run[0] if len(run) == 1 else f"{run[0]}-{run[-1]}")
            run.clear()

    for name in names:
        if run and name.isdigit() and run[-1].isdigit() and int(name) == int(run[-1]) + 1:
            run.append(name)
            continue
        flush()
        run.append(name)
    flush()
    return ", ".join(parts)


def summarise(sets: Sequence[ScoredSet], with_recall: bool) -> dict[str, Any]:
    """:meth:`ScoredSet.summary` of the pooled ``sets``, with the depth-map time per frame
    (``depth_ms_per_frame``) and, for a single missing set, its ``missing`` reason."""
    present = [s for s in sets if not s.info.get("missing")]
    pooled = pool(present)
    out = pooled.summary(with_recall)
    depth_s = sum(s.info.get("depth_seconds", 0.0) for s in present)
    out["depth_ms_per_frame"] = 1000.0 * depth_s / pooled.frames if pooled.frames else math.nan
    if len(sets) == 1 and not present:
        out["missing"] = sets[0].info["missing"]
    return out


@dataclass
class PooledScores:
    """Every method's summaries per sequence, pooled over the sequences it ran on, and over the
    sequences all of them ran on (summary = :func:`summarise` keys; distances in metres).

    Attributes:
        methods, sequences: in table order.
        summaries: ``{sequence: {method: summary}}`` (``missing`` says why a method has none).
        overall: ``{method: summary}`` pooled over ``pooled[method]``.
        pooled: ``{method: [sequences it ran on]}``.
        common: ``{"sequences": [...], "methods": {method: summary}}``, every method pooled
            over the sequences all of them ran on, when the ``pooled`` lists differ; else None.
    """

    methods: list[str]
    sequences: list[str]
    summaries: dict[str, dict[str, dict[str, Any]]]
    overall: dict[str, dict[str, Any]]
    pooled: dict[str, list[str]]
    common: dict[str, Any] | None = None

    def method_reports(self) -> dict[str, dict[str, Any]]:
        """The ``"methods"`` block of a JSON report: per method its ``overall``,
        ``pooled_sequences`` and per-sequence summaries."""
        return {
            m: {
                "overall": self.overall[m],
                "pooled_sequences": self.pooled[m],
                "sequences": {s: self.summaries[s][m] for s in self.sequences},
            }
            for m in self.methods
        }

    @classmethod
    def from_report(cls, report: Mapping[str, Any]) -> PooledScores:
        """Read back the ``"methods"`` and ``"overall_common"`` blocks of a JSON report."""
        blocks = report["methods"]
        methods = list(blocks)
        sequences = list(blocks[methods[0]]["sequences"]) if methods else []
        return cls(
            methods,
            sequences,
            {s: {m: blocks[m]["sequences"][s] for m in methods} for s in sequences},
            {m: blocks[m]["overall"] for m in methods},
            {m: list(blocks[m].get("pooled_sequences", sequences)) for m in methods},
            report.get("overall_common"),
        )


def pool_methods(
    per_sequence: Mapping[str, Mapping[str, ScoredSet]],
    methods: Sequence[str],
    with_recall: bool = False,
) -> PooledScores:
    """Summarise ``per_sequence[sequence][method]`` (a set with ``info["missing"]`` = the
    method has no result there) per sequence, each method pooled over its own sequences, and,
    when those differ, every method pooled over the sequences all of them ran on."""
    names = list(per_sequence)
    ran = {m: [s for s in names if not per_sequence[s][m].info.get("missing")] for m in methods}
    scores = PooledScores(
        list(methods),
        names,
        {s: {m: summarise([per_sequence[s][m]], with_recall) for m in methods} for s in names},
        {m: summarise([per_sequence[s][m] for s in ran[m]], with_recall) for m in methods},
        ran,
    )
    if len({tuple(r) for r in ran.values()}) > 1:
        common = [s for s in names if all(s in ran[m] for m in methods)]
        scores.common = {
            "sequences": common,
            "methods": {
                m: summarise([per_sequence[s][m] for s in common], with_recall) for m in methods
            },
        }
    return scores
