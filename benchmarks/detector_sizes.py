"""What a vehicle size from the detector is worth to ``ours`` on KITTI tracking.

The protocol of ``slopedist eval kitti-tracking --boxes pointrcnn --score 2`` (ORB-SLAM3
rotations, the 13 shared sequences, detections matched to the Car/Van labels by IoU ≥ 0.5,
truth = label z, estimates capped at 80 m), ``ours`` only. Prints

1. PointRCNN's own size error: its h, w, l against the matched labels' (robust σ = 1.4826 ×
   MAD and RMS of the log ratio, median bias, per dimension). PointRCNN measures the size in a
   LiDAR point cloud: a camera detector's sizes are worse.
2. ``ours`` (pooled RMSE, m, and the share of errors within its own 1σ, right: 0.683) with
   - its class prior (no sizes: the published figure),
   - PointRCNN's sizes at the default σ (10 %) and at a σ set to PointRCNN's measured error,
   - PointRCNN's sizes perturbed as a monocular 3D detector's would be: each dimension times
     ``exp(ε)``, ε ~ N(0, s²), s = 5 % and 10 %, either drawn anew for every box (independent)
     or once per vehicle (persistent: the detections matched to one label track share it, the
     others independent), seeds 0, 1, 2 (mean over seeds, and the range), the size σ set to
     match the sizes' total error, √(s² + PointRCNN's measured RMS²) per dimension (the
     largest of the three).
3. On the labels' own boxes: ``ours`` with its class prior and with the labels' true sizes
   (σ 2 %): what an exact size is worth without a detector's box noise.

The perturbed PointRCNN files are written to a temporary copy of the data root (the other
folders linked), and every row is a plain ``evaluate_kitti_tracking`` run with ``box_sizes``,
as ``slopedist eval kitti-tracking --boxes pointrcnn --score 2 --box-sizes --box-size-sigma S``
runs it.

Usage::

    python benchmarks/detector_sizes.py [--data ../shared/data/kitti_tracking] [--seeds 0,1,2]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.evaluation.kitti import KittiEvalConfig, evaluate_kitti_tracking
from slopedist.evaluation.metrics import match_by_frame
from slopedist.evaluation.table import format_table
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.readers import read_pointrcnn
from slopedist.io.detections.sizes import MAX_SIZE_M, MIN_SIZE_M, SIZE_COLUMNS
from slopedist.io.kitti.tracking import (
    DETECTION_FOLDERS,
    BoxSource,
    list_sequences,
    load_sequence,
    protocol_mask,
)

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kitti_tracking"
MIN_SCORE = 2.0
LEVELS = (0.05, 0.10)
"""The monocular detector's relative size errors s (σ of the log of each dimension)."""
LABEL_SIZE_SIGMA_PCT = 2.0
"""The σ given to the labels' own sizes (they are exact up to the labelling)."""
H_W_L_FIELDS = (7, 8, 9)
"""Positions of h, w, l among a PointRCNN line's comma-separated fields."""


def ours_config(boxes: BoxSource, sizes: bool, sigma_pct: float | None) -> KittiEvalConfig:
    """``ours`` on ``boxes`` (PointRCNN at score ≥ 2) with or without the boxes' sizes."""
    return KittiEvalConfig(
        methods=("ours",),
        boxes=boxes,
        min_score=MIN_SCORE if boxes is BoxSource.POINTRCNN else None,
        box_sizes=sizes,
        box_size_sigma_pct=sigma_pct if sizes else None,
    )


def scores(root: Path, cfg: KittiEvalConfig) -> tuple[float, float, int]:
    """Pooled RMSE (m), 1σ coverage and n of ``ours``."""
    overall = evaluate_kitti_tracking(root, cfg)["methods"]["ours"]["overall"]
    return float(overall["rmse"]), float(overall["uncertainty"]["within_1sigma"]), overall["n"]


def robust_sigma(x: NDArray[np.float64]) -> float:
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def pointrcnn_size_error(data: Path) -> NDArray[np.float64]:
    """Print PointRCNN's size error against the matched labels; return the RMS of the log
    ratio per dimension ``(3,)``."""
    ratios = []
    for name in list_sequences(data):
        seq = load_sequence(data, name)
        gt = seq.labels.select(protocol_mask(seq.labels))
        det = seq.detections(MIN_SCORE, BoxSource.POINTRCNN, sizes=True)
        det_rows, gt_rows = match_by_frame(det, gt, 0.5)
        dims = np.stack([det.extra[c] for c in SIZE_COLUMNS], axis=1)[det_rows]
        ratios.append(np.log(dims / gt.extra["dims_hwl"][gt_rows]))
    log_ratio = np.concatenate(ratios)
    rms = np.sqrt(np.mean(log_ratio**2, axis=0))
    rows = [
        [
            dim,
            f"{100 * float(np.median(log_ratio[:, k])):+.1f}",
            f"{100 * robust_sigma(log_ratio[:, k]):.1f}",
            f"{100 * rms[k]:.1f}",
        ]
        for k, dim in enumerate(("height", "width", "length"))
    ]
    print(f"1. PointRCNN's sizes against the matched labels ({len(log_ratio)} boxes), % of log")
    print(format_table(["dimension", "median", "robust σ", "RMS"], rows))
    return np.asarray(rms, dtype=float)


def vehicle_keys(seq_labels: BoxTable, det: BoxTable) -> NDArray[np.int64]:
    """Per detection, the label track it is matched to (IoU ≥ 0.5), else a key of its own."""
    keys = -1 - np.arange(len(det), dtype=np.int64)  # unmatched: one key per box
    det_rows, gt_rows = match_by_frame(det, seq_labels, 0.5)
    keys[det_rows] = seq_labels.track_id[gt_rows]
    return keys


def perturbed_lines(
    lines: list[str], keys: NDArray[np.int64], level: float, rng: np.random.Generator
) -> list[str]:
    """PointRCNN ``lines`` with h, w, l each times ``exp(ε)``, ε ~ N(0, level²) drawn once per
    key (``keys``: one per line), clipped to the sizes a box file accepts."""
    unique, inverse = np.unique(keys, return_inverse=True)
    eps = rng.normal(0.0, level, size=(unique.size, 3))[inverse]
    out = []
    for i, line in enumerate(lines):
        fields = line.split(",")
        for k, pos in enumerate(H_W_L_FIELDS):
            value = float(fields[pos]) * math.exp(eps[i, k])
            fields[pos] = f"{min(max(value, MIN_SIZE_M), MAX_SIZE_M):.4f}"
        out.append(",".join(fields))
    return out


def perturbed_root(data: Path, out: Path, level: float, persistent: bool, seed: int) -> Path:
    """A data root under ``out`` whose PointRCNN files have perturbed sizes (the other
    folders linked to ``data``'s)."""
    folder = DETECTION_FOLDERS[BoxSource.POINTRCNN]
    out.mkdir(parents=True, exist_ok=True)
    for child in data.iterdir():
        if child.name != folder and not (out / child.name).exists():
            (out / child.name).symlink_to(child.resolve())
    (out / folder).mkdir(exist_ok=True)
    for name in list_sequences(data):
        path = data / folder / f"{name}.txt"
        lines = [ln for ln in path.read_text().splitlines() if ln.strip()]
        det = read_pointrcnn(path)
        if len(det) != len(lines):
            raise RuntimeError(f"{path}: {len(lines)} lines but {len(det)} boxes")
        labels = load_sequence(data, name).labels
        keys = vehicle_keys(labels, det) if persistent else np.arange(len(det), dtype=np.int64)
        rng = np.random.default_rng([seed, int(name), int(persistent)])
        text = "\n".join(perturbed_lines(lines, keys, level, rng)) + "\n"
        (out / folder / f"{name}.txt").write_text(text)
    return out


def mean_and_range(values: Sequence[float], digits: int) -> str:
    """``mean (min–max)`` of per-seed values."""
    return f"{np.mean(values):.{digits}f} ({min(values):.{digits}f}–{max(values):.{digits}f})"


def detector_rows(data: Path, own_rms: NDArray[np.float64], seeds: Sequence[int]) -> None:
    """Section 2: ``ours`` on PointRCNN's boxes without, with and with perturbed sizes."""
    own_pct = round(100 * float(own_rms.max()), 1)
    rows: list[list[Any]] = []
    base = scores(data, ours_config(BoxSource.POINTRCNN, False, None))
    rows.append(["class prior (no sizes)", "–", f"{base[0]:.3f}", f"{base[1]:.3f}", base[2]])
    for sigma in (10.0, own_pct):
        r = scores(data, ours_config(BoxSource.POINTRCNN, True, sigma))
        label = "PointRCNN's sizes" + (" (σ = its error)" if sigma == own_pct else "")
        rows.append([label, f"{sigma:g}", f"{r[0]:.3f}", f"{r[1]:.3f}", r[2]])
    with tempfile.TemporaryDirectory(prefix="detector_sizes_") as tmp:
        for level in LEVELS:
            sigma = round(100 * math.sqrt(level**2 + float(own_rms.max()) ** 2), 1)
            for persistent in (False, True):
                runs = []
                for seed in seeds:
                    root = perturbed_root(
                        data, Path(tmp) / f"{level}_{persistent}_{seed}", level, persistent, seed
                    )
                    runs.append(scores(root, ours_config(BoxSource.POINTRCNN, True, sigma)))
                kind = "per vehicle" if persistent else "per box"
                rows.append(
                    [
                        f"sizes × exp(N(0, {100 * level:g} %²)), {kind}",
                        f"{sigma:g}",
                        mean_and_range([r[0] for r in runs], 3),
                        mean_and_range([r[1] for r in runs], 3),
                        runs[0][2],
                    ]
                )
    print(
        f"\n2. ours on PointRCNN's boxes (score >= {MIN_SCORE:g}): pooled RMSE (m) and 1σ "
        f"coverage (right: 0.683); perturbed rows: mean (range) over seeds {list(seeds)}"
    )
    print(format_table(["sizes", "σ (%)", "RMSE", "within 1σ", "n"], rows))


def label_rows(data: Path) -> None:
    """Section 3: ``ours`` on the labels' boxes with its class prior and the true sizes."""
    rows = []
    for sizes in (False, True):
        r = scores(data, ours_config(BoxSource.GT, sizes, LABEL_SIZE_SIGMA_PCT))
        label = f"labels' sizes (σ {LABEL_SIZE_SIGMA_PCT:g} %)" if sizes else "class prior"
        rows.append([label, f"{r[0]:.3f}", f"{r[1]:.3f}", r[2]])
    print("\n3. ours on the labels' boxes: pooled RMSE (m) and 1σ coverage")
    print(format_table(["sizes", "RMSE", "within 1σ", "n"], rows))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--seeds", default="0,1,2", help="comma-separated seeds of the perturbations")
    args = ap.parse_args(argv)
    if not (args.data / "label_02").is_dir():
        print(f"KITTI tracking data not found at {args.data}; pass --data", file=sys.stderr)
        return 2
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    t0 = time.perf_counter()
    own_rms = pointrcnn_size_error(args.data)
    detector_rows(args.data, own_rms, seeds)
    label_rows(args.data)
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
