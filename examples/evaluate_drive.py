"""Score methods against the ground truth of a drive, each run into a folder in one call.

Usage::

    python examples/evaluate_drive.py FRAMES CALIB BOXES --out DIR
        [--methods flat,paper,ours] [--reference centre] [--height 1.65] [--mount-angle 0]
        [--timestamps FILE]

BOXES is a box CSV with a ``gt_distance_m`` column (the true distance of each box, metres);
``--reference`` names the point of the vehicle that truth refers to (``centre`` for KITTI
labels, ``nearest_face`` for LiDAR), to which every method's distance is moved. Each
method is run as ``slopedist run`` runs it (:func:`slopedist.run_to_folder`: DIR/<method>/
records.csv, frames.csv, run.json), and its ``ok`` distances are scored against the truth.
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

import slopedist


def scored_pairs(records: Path) -> tuple[list[float], list[float], int]:
    """``ok`` distances and their truths from a records CSV, and the number of rows."""
    with records.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    pairs = [
        (float(r["distance_m"]), float(r["gt_distance_m"]))
        for r in rows
        if r["status"] == "ok"
        and r.get("gt_distance_m")
        and math.isfinite(float(r["gt_distance_m"]))
    ]
    return [p for p, _ in pairs], [g for _, g in pairs], len(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frames", type=Path)
    parser.add_argument("calib", type=Path)
    parser.add_argument("boxes", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--methods", default="flat,paper,ours")
    parser.add_argument("--reference", default="centre")
    parser.add_argument("--height", type=float, default=1.65)
    parser.add_argument("--mount-angle", type=float, default=0.0)
    parser.add_argument("--timestamps", type=Path, default=None)
    args = parser.parse_args()

    print(f"{'method':8s} {'rows':>6s} {'ok':>6s} {'RMSE m':>8s} {'MAE m':>8s} {'δ<1.25':>7s}")
    for method in args.methods.split(","):
        options = slopedist.RunOptions(
            args.frames,
            args.out / method,
            args.calib,
            boxes=args.boxes,
            timestamps=args.timestamps,
            height_m=args.height,
            mount_angle_deg=args.mount_angle,
            estimator=slopedist.EstimatorConfig(method=method),
            reference=slopedist.ReferencePoint(args.reference),
            progress=False,
        )
        result = slopedist.run_to_folder(options)
        predicted, truth, rows = scored_pairs(Path(result.out_dir) / "records.csv")
        m = slopedist.distance_metrics(predicted, truth)
        print(
            f"{method:8s} {rows:6d} {m['n']:6d} {m['rmse']:8.2f} {m['mae']:8.2f} "
            f"{m['delta_1.25']:7.2f}"
        )


if __name__ == "__main__":
    main()
