"""Distances from pixels against LiDAR ground truth on ../shared/data/kitti_raw_lead.

What it does, as a new user would with ``slopedist run``:

1. LiDAR ground truth: vehicle boxes and their distances from the Velodyne scans
   (:func:`slopedist.io.kitti.raw.lidar_vehicle_boxes`; distance = longitudinal z of the
   cluster's nearest face), written to ``OUT/lidar_boxes.csv`` (slopedist box CSV + ``z``).
2. For each method (flat, ego, paper, and ours / ours-selfcal when registered): the streaming run of
   ``slopedist run FRAMES --calib calib.txt --boxes OUT/lidar_boxes.csv --method M`` with the
   built-in visual odometry, written to ``OUT/<method>/``.
3. RMSE of each method against the LiDAR z over the boxes that are scored: not cut by the image
   border (a box whose bottom is cut has no ground-contact row; the ground under a car closer
   than about 5.9 m is below this camera's image) and z ≤ ``--max-z``; also for the lead car (the
   nearest cluster in the ego lane in frame 0) alone.

Usage::

    python benchmarks/kitti_raw_lead.py [--data ../shared/data/kitti_raw_lead]
        [--out bench_out/kitti_raw_lead] [--odometry builtin|orbslam3] [--vocab ORBvoc.txt]
        [--ours-options '{"occlusion_aware": false}']
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from orbslam3_vs_builtin import c_stdout_to_stderr

from slopedist.estimators import available_methods, make_estimator
from slopedist.estimators.base import ReferencePoint
from slopedist.estimators.references import CENTRE_COLUMN, NEAREST_FACE_COLUMN, to_reference
from slopedist.evaluation.metrics import uncertainty_metrics
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.writers import write_box_csv
from slopedist.io.frames import open_frames
from slopedist.io.kitti.raw import KittiRawDrive
from slopedist.odometry.base import OdometryResult, RotationOdometry
from slopedist.streaming.config import RECORDS_NAME, RunConfig, RunningMean
from slopedist.streaming.loop import run_frames
from slopedist.streaming.pipeline import build_odometry

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "kitti_raw_lead"
IMAGE_SIZE = (1242, 375)
METHODS = ("flat", "ego", "paper", "ours", "ours-selfcal")


class RecordingOdometry:
    """Wraps a backend, keeps every result (a 78-frame run) and its time, and replays them."""

    def __init__(self, backend: RotationOdometry) -> None:
        self.backend = backend
        self.results: list[OdometryResult] = []
        self.ms = RunningMean()

    def process(
        self, image_gray: np.ndarray, timestamp_s: float, mask_boxes: np.ndarray | None = None
    ) -> OdometryResult:
        t0 = time.perf_counter()
        res = self.backend.process(image_gray, timestamp_s, mask_boxes)
        self.ms.add(getattr(self.backend, "last_track_ms", (time.perf_counter() - t0) * 1e3))
        self.results.append(res)
        return res

    def reset(self) -> None:
        self.backend.reset()
        self.results.clear()

    def replay(self) -> RotationOdometry:
        results = iter(list(self.results))

        class _Replay:
            def process(
                self,
                image_gray: np.ndarray,
                timestamp_s: float,
                mask_boxes: np.ndarray | None = None,
            ) -> OdometryResult:
                return next(results)

            def reset(self) -> None:
                pass

        return _Replay()


def lead_track(boxes: BoxTable) -> int:
    """Track id of the nearest cluster within 1 m of the camera's axis in the first frame."""
    first = boxes.select((boxes.frame == boxes.frame.min()) & (np.abs(boxes.extra["x"]) < 1.0))
    return int(first.track_id[int(np.argmin(first.extra["z"]))])


TRUTH_REFERENCE = ReferencePoint.NEAREST_FACE
"""The point the LiDAR truth refers to: the cluster's nearest face."""


def _number(cell: str | None) -> float:
    return float(cell) if cell else math.nan


def read_estimates(path: Path) -> dict[tuple[int, int], float]:
    """``{(frame, track_id): distance to the nearest face, m}`` of a records CSV (NaN when
    missing): every method's ``distance_m`` moved from its ``reference`` to the truth's
    (:func:`slopedist.estimators.references.to_reference`; ``ours`` by its own half extent, the
    ground-contact methods' contact point is already at the nearest face)."""
    out = {}
    with path.open(newline="") as fh:
        for row in csv.DictReader(fh):
            half = _number(row.get(CENTRE_COLUMN)) - _number(row.get(NEAREST_FACE_COLUMN))
            d = to_reference(
                [_number(row["distance_m"])],
                [row["reference"]],
                [row["class"]],
                TRUTH_REFERENCE,
                [half],
            )
            out[(int(row["frame"]), int(row["track_id"]))] = float(d[0])
    return out


def read_sigmas(path: Path) -> dict[tuple[int, int], float]:
    """``{(frame, track_id): the method's own 1σ, m}`` of a records CSV (its ``sigma_m``
    column; empty when it has none)."""
    with path.open(newline="") as fh:
        return {
            (int(row["frame"]), int(row["track_id"])): _number(row.get("sigma_m"))
            for row in csv.DictReader(fh)
        }


def print_uncertainty(
    errors: dict[str, NDArray[np.float64]],
    sigmas: dict[str, NDArray[np.float64]],
    common: NDArray[np.bool_],
) -> None:
    """How well each method's own σ covers its errors on the common boxes
    (:func:`slopedist.evaluation.metrics.uncertainty_metrics`; methods without a σ are left out)."""
    lines = []
    for m, err in errors.items():
        u = uncertainty_metrics(err[common], np.zeros(int(common.sum())), sigmas[m][common])
        if u["n_sigma"]:
            lines.append(
                f"{m:12s} {u['n_sigma']:5d} {u['within_1sigma']:10.3f} "
                f"{u['within_2sigma']:10.3f} {u['within_3sigma']:10.3f} {u['z_rms']:8.2f}"
            )
    if lines:
        print(
            "\nErrors within the method's own σ (a right Gaussian σ: 0.683, 0.954, 0.997; RMS 1):"
        )
        print(
            f"{'method':12s} {'n':>5s} {'within 1σ':>10s} {'within 2σ':>10s} "
            f"{'within 3σ':>10s} {'RMS e/σ':>8s}"
        )
        print("\n".join(lines))


def rmse(errors: list[float]) -> float:
    return float(np.sqrt(np.mean(np.square(errors)))) if errors else math.nan


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--out", type=Path, default=REPO / "bench_out" / "kitti_raw_lead")
    parser.add_argument("--odometry", default="builtin", choices=("builtin", "orbslam3"))
    parser.add_argument("--vocab", type=Path, default=None)
    parser.add_argument(
        "--max-z", type=float, default=40.0, help="score boxes with LiDAR z up to this, metres"
    )
    parser.add_argument(
        "--ours-options",
        type=json.loads,
        default={},
        help="options of ours and ours-selfcal as JSON, e.g. "
        "'{\"occlusion_aware\": false}' (default: none)",
    )
    parser.add_argument(
        "--top-clusters", type=int, default=8, help="clusters listed by share of ours' error"
    )
    args = parser.parse_args(argv)
    if not args.data.is_dir():
        print(f"kitti_raw_lead data not found at {args.data}", file=sys.stderr)
        return 2

    drive = KittiRawDrive.open(args.data)
    t0 = time.perf_counter()
    truth = drive.lidar_boxes(IMAGE_SIZE)
    lidar_s = time.perf_counter() - t0
    boxes_csv = write_box_csv(
        truth, args.out / "lidar_boxes.csv", ("z", "z_median", "x", "n_points", "truncated")
    )
    lead = lead_track(truth)
    scored = (truth.extra["truncated"] == 0) & (truth.extra["z"] <= args.max_z)
    key = list(zip(truth.frame.tolist(), truth.track_id.tolist()))
    z = truth.extra["z"]
    print(
        f"LiDAR boxes: {len(truth)} in {len(drive.frames())} frames ({lidar_s:.1f} s), "
        f"{int(scored.sum())} scored (not cut by the image border, z <= {args.max_z:g} m); "
        f"lead car track {lead}: {int(np.sum(scored & (truth.track_id == lead)))} scored "
        f"frames, z {z[truth.track_id == lead].max():.2f} → "
        f"{z[truth.track_id == lead].min():.2f} m"
    )
    print(f"boxes written to {boxes_csv}")

    camera = drive.calib.camera()
    methods = [m for m in METHODS if m in available_methods()]
    # the odometry runs once; every method is fed the same rotations (ORB-SLAM3 is not
    # deterministic, so separate runs would compare different rotations)
    recorder = RecordingOdometry(build_odometry(args.odometry, camera, args.vocab))
    estimates, results, sigmas = {}, {}, {}
    for n_run, method in enumerate(methods):
        out = args.out / method
        odometry = recorder if n_run == 0 else recorder.replay()
        with c_stdout_to_stderr():
            results[method] = run_frames(
                open_frames(drive.image_dir),
                truth,
                odometry,
                make_estimator(
                    method, camera, **(args.ours_options if method.startswith("ours") else {})
                ),
                RunConfig(out, progress=False),
            )
        estimates[method] = read_estimates(out / RECORDS_NAME)
        sigmas[method] = read_sigmas(out / RECORDS_NAME)
        print(
            f"  ran {method}: {results[method].records} records, odometry "
            f"{results[method].odometry_states} → {out}",
            file=sys.stderr,
        )
    close = getattr(recorder.backend, "close", None)
    if close is not None:
        with c_stdout_to_stderr():
            close()
    ok = {m: np.array([math.isfinite(estimates[m].get(k, math.nan)) for k in key]) for m in methods}
    common = scored & np.logical_and.reduce([ok[m] for m in methods])
    is_lead = truth.track_id == lead
    rows = []
    bins = [(0.0, 10.0), (10.0, 20.0), (20.0, 30.0), (30.0, args.max_z)]
    binned: dict[str, list[float]] = {}
    for m in methods:
        d = np.array([estimates[m].get(k, math.nan) for k in key])
        err = d - z
        binned[m] = [rmse(list(err[common & (z >= lo) & (z < hi)])) for lo, hi in bins]
        rows.append(
            (
                m,
                rmse(list(err[common])),
                int(common.sum()),
                float(np.mean(err[common])) if common.any() else math.nan,
                rmse(list(err[common & is_lead])),
                int(np.sum(common & is_lead)),
                rmse(list(err[scored & ok[m]])),
                int(np.sum(scored & ok[m])),
                recorder.ms.mean() if recorder.ms.count else math.nan,
                results[m].frames_per_s,
            )
        )

    print()
    print(
        f"RMSE against LiDAR z (nearest face), {args.odometry} visual odometry, from pixels, "
        f"on the {int(common.sum())} scored boxes every method estimates (of {int(scored.sum())}"
        f"); 'own' = each method over all the scored boxes it estimates; every method's "
        f"distance is moved to the truth's reference ({TRUTH_REFERENCE.value}):"
    )
    print(
        f"{'method':12s} {'RMSE m':>8s} {'n':>5s} {'bias m':>8s} {'lead RMSE':>10s} "
        f"{'lead n':>7s} {'own RMSE':>9s} {'own n':>6s} {'VO ms':>7s} {'frames/s':>9s}"
    )
    for m, r, n, b, lr, ln, own, own_n, vo_ms, fps in rows:
        print(
            f"{m:12s} {r:8.2f} {n:5d} {b:+8.2f} {lr:10.2f} {ln:7d} {own:9.2f} {own_n:6d} "
            f"{vo_ms:7.1f} {fps:9.1f}"
        )
    counts = [int(np.sum(common & (z >= lo) & (z < hi))) for lo, hi in bins]
    print()
    print("RMSE (m) by LiDAR distance, same boxes:")
    print(
        f"{'method':12s} "
        + " ".join(f"{f'{lo:g}-{hi:g} m (n={c})':>16s}" for (lo, hi), c in zip(bins, counts))
    )
    for m in methods:
        print(f"{m:12s} " + " ".join(f"{v:16.2f}" for v in binned[m]))
    errors = {m: np.array([estimates[m].get(k, math.nan) for k in key]) - z for m in methods}
    sigma = {m: np.array([sigmas[m].get(k, math.nan) for k in key]) for m in methods}
    print_uncertainty(errors, sigma, common)
    print_clusters(truth, errors, common, args.top_clusters)
    return 0


def print_clusters(
    truth: BoxTable, errors: dict[str, np.ndarray], common: np.ndarray, top: int
) -> None:
    """The clusters (tracks) that hold most of the last method's squared error on the scored
    boxes: their size, mean LiDAR z and lateral x, each method's bias and RMSE there; then every
    method's RMSE without the two largest (a diagnostic of where an error comes from, not a
    figure to report as the benchmark's)."""
    worst = list(errors)[-1] if "ours" not in errors else "ours"
    tids = np.unique(truth.track_id[common])
    sq = {t: float(np.sum(errors[worst][common & (truth.track_id == t)] ** 2)) for t in tids}
    order = sorted(tids, key=lambda t: -sq[t])[:top]
    total = sum(sq.values())
    print()
    print(f"Clusters with the largest share of {worst}'s squared error (bias / RMSE, m):")
    print(
        f"{'track':>5s} {'n':>4s} {'z m':>6s} {'x m':>6s} {'share':>6s} "
        + " ".join(f"{m:>14s}" for m in errors)
    )
    for t in order:
        sel = common & (truth.track_id == t)
        cells = " ".join(
            f"{np.mean(e[sel]):+6.2f}/{rmse(list(e[sel])):6.2f} " for e in errors.values()
        )
        print(
            f"{int(t):5d} {int(sel.sum()):4d} {np.mean(truth.extra['z'][sel]):6.1f} "
            f"{np.mean(truth.extra['x'][sel]):6.1f} {sq[t] / total:6.1%} {cells}"
        )
    rest = common & ~np.isin(truth.track_id, order[:2])
    print(
        f"without tracks {', '.join(str(int(t)) for t in order[:2])} (n = {int(rest.sum())}): "
        + ", ".join(f"{m} {rmse(list(e[rest])):.2f}" for m, e in errors.items())
    )


if __name__ == "__main__":
    sys.exit(main())
