"""Distance metrics, detection-to-truth matching and the KITTI tracking evaluation protocol.

Distances in metres. Metrics follow the depth-estimation literature (Eigen et al.): RMSE, MAE,
AbsRel, SqRel, RMSE-log and the δ < 1.25^k accuracies.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.detections.boxes import BoxTable, iou_matrix
from slopedist.estimators.base import MissingReason

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


def cap_estimates(
    distance_m: ArrayLike, reason: ArrayLike, cap_m: float = 80.0
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Apply the published protocol's cap: estimates above ``cap_m`` become ``cap_m`` and a
    target below the horizon (``u ≤ v``, reason ``below_horizon``) counts as ``cap_m``.

    Returns:
        The capped distances and a mask of the entries that can be scored (other missing
        reasons, such as ``no_rotation``, stay unscored and are counted apart).
    """
    d = np.asarray(distance_m, dtype=float).copy()
    r = np.asarray(reason, dtype=object)
    d[r == MissingReason.BELOW_HORIZON.value] = cap_m
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
    """:func:`match_boxes` frame by frame; returns row indices into ``det`` and ``gt``."""
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


@dataclass
class ScoredSet:
    """Paired predictions and truths of one sequence and method, with bookkeeping."""

    pred_m: NDArray[np.float64]
    gt_m: NDArray[np.float64]
    n_gt: int
    n_unscored: int = 0
    seconds: float = 0.0
    frames: int = 0
    info: dict[str, Any] = field(default_factory=dict)

    def summary(self, with_recall: bool) -> dict[str, Any]:
        """Metrics, per-bin metrics, counts and time per frame as a JSON-ready dict."""
        out: dict[str, Any] = dict(distance_metrics(self.pred_m, self.gt_m))
        out["n_gt"] = self.n_gt
        out["n_unscored"] = self.n_unscored
        if with_recall:
            out["recall"] = (len(self.pred_m) + self.n_unscored) / self.n_gt if self.n_gt else 0.0
        out["ms_per_frame"] = 1000.0 * self.seconds / self.frames if self.frames else math.nan
        out["bins"] = binned_metrics(self.pred_m, self.gt_m)
        return out


def pool(sets: Sequence[ScoredSet]) -> ScoredSet:
    """Pool several sequences' pairs into one set (overall = pooled over all targets)."""
    return ScoredSet(
        np.concatenate([s.pred_m for s in sets]) if sets else np.zeros(0),
        np.concatenate([s.gt_m for s in sets]) if sets else np.zeros(0),
        sum(s.n_gt for s in sets),
        sum(s.n_unscored for s in sets),
        sum(s.seconds for s in sets),
        sum(s.frames for s in sets),
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


def format_table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """Plain-text table with right-aligned columns (floats to 2 decimals, NaN as ``-``)."""

    def cell(v: Any) -> str:
        if isinstance(v, float):
            return "-" if not math.isfinite(v) else f"{v:.2f}"
        return str(v)

    cells = [[cell(v) for v in r] for r in rows]
    widths = [max(len(h), *(len(r[i]) for r in cells)) for i, h in enumerate(headers)]
    line = "  ".join(h.rjust(w) for h, w in zip(headers, widths))
    body = ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in cells]
    return "\n".join([line, "-" * len(line), *body])


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


def format_report_tables(report: dict[str, Any]) -> str:
    """The RMSE table (sequence × method) and the overall extended-metrics table of a report."""
    methods = list(report["methods"])
    seqs = list(next(iter(report["methods"].values()))["sequences"]) if methods else []
    rmse_rows: list[list[Any]] = []
    for s in seqs:
        first = report["methods"][methods[0]]["sequences"][s]
        rmse_rows.append(
            [s, first["n"], *(report["methods"][m]["sequences"][s]["rmse"] for m in methods)]
        )
    n_all = report["methods"][methods[0]]["overall"]["n"] if methods else 0
    rmse_rows.append(
        ["overall", n_all, *(report["methods"][m]["overall"]["rmse"] for m in methods)]
    )
    common = report.get("overall_common")
    if common is not None:
        first = common["methods"][methods[0]]
        rmse_rows.append(["common", first["n"], *(common["methods"][m]["rmse"] for m in methods)])
    out = ["RMSE (m) per sequence", format_table(["sequence", "n", *methods], rmse_rows)]
    for m in methods:
        missing = {
            s: v["missing"]
            for s, v in report["methods"][m]["sequences"].items()
            if v.get("missing")
        }
        if missing:
            out.append(
                f"{m}: no result on {', '.join(missing)} "
                f"({next(iter(missing.values()))}); its overall pools "
                f"{compact_names(report['methods'][m].get('pooled_sequences', []))}"
            )
    if common is not None:
        out.append(
            f"common: every method pooled over the sequences all of them ran on "
            f"({compact_names(common['sequences'])})"
        )
    keys = ["n", "rmse", "mae", "abs_rel", "sq_rel", "rmse_log", "delta_1.25"]
    has_recall = "recall" in report["methods"][methods[0]]["overall"] if methods else False
    if has_recall:
        keys.append("recall")
    keys.append("ms_per_frame")
    rows = [[m, *(report["methods"][m]["overall"][k] for k in keys)] for m in methods]
    out += ["", "Overall (pooled)", format_table(["method", *keys], rows)]
    bins = list(report["methods"][methods[0]]["overall"]["bins"]) if methods else []
    bin_rows = [
        [m, *(report["methods"][m]["overall"]["bins"][b]["rmse"] for b in bins)] for m in methods
    ]
    out += [
        "",
        "RMSE (m) per ground-truth distance bin (m)",
        format_table(["method", *bins], bin_rows),
    ]
    return "\n".join(out)
