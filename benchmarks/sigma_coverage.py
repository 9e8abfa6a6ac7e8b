"""How far to trust ``ours``' σ: the coverage of its ``sigma_m`` on every source we have truth for.

For the ``ok`` rows of ``ours`` (and ``ours-offline``) prints the share of errors within 1σ and
2σ (ideal 0.68 / 0.95 for a Gaussian error), the median of |error|/σ (ideal 0.67) and the same
by truth distance (0–20, 20–40, 40+ m), on

- KITTI tracking, the 13 shared sequences, the evaluation's protocol (truth = label z, Car/Van,
  truncated 0, occluded ≤ 1, z ≤ 80 m; detector boxes matched by IoU ≥ 0.5; ORB-SLAM3
  rotations), with the label boxes, PointRCNN (score ≥ 2) and RRC (score ≥ 0.5);
- synthetic traffic (``simulate_traffic``, flat road, 0.5 px box noise, 12 vehicles × 150
  frames, four seeds): all cars; 60 % cars, 25 % vans, 15 % trucks with their true classes;
  the same called ``Car`` (class-blind), read as ``Car`` and with ``generic_classes``.

- ``kitti_raw_lead`` (LiDAR truth, the clusters' nearest face, not cut by the border, z ≤ 40 m)
  from the output folder of ``python benchmarks/kitti_raw_lead.py --out DIR --ours-options
  '{"reference": "nearest_face"}'`` (it runs the visual odometry over the images; here its
  ``lidar_boxes.csv`` and ``ours/records.csv`` are read): ``--raw-lead-out DIR``.

Usage::

    python benchmarks/sigma_coverage.py [--data /work/shared/data/kitti_tracking]
        [--sources gt,pointrcnn,rrc,synthetic] [--methods ours,ours-offline]
        [--ours-options '{"generic_classes": ["Car"], "generic_sigma_only": true}']
        [--raw-lead-out bench_out/kitti_raw_lead ...]
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from kitti_raw_lead import read_estimates, read_sigmas
from numpy.typing import NDArray
from ours_detector_boxes import ROTATION, scenes

from slopedist.core.camera import Camera
from slopedist.estimators import make_estimator
from slopedist.evaluation.metrics import cap_estimates
from slopedist.io.kitti.tracking import BoxSource
from slopedist.odometry.base import RotationTrack
from slopedist.streaming.step import estimate_sequence
from slopedist.synthetic.traffic import simulate_traffic

DEFAULT_DATA = Path("/work/shared/data/kitti_tracking")
BINS_M = ((0.0, 20.0), (20.0, 40.0), (40.0, np.inf))
SIM_CAMERA = Camera(721.5, 609.6, 172.9, 1.65, 0.0)
MIXED_TRAFFIC = {"Car": 0.6, "Van": 0.25, "Truck": 0.15}
SIM_SEEDS = range(4)

Rows = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]
"""Per scored row: the error (m), ``sigma_m`` (m) and the truth (m)."""


def scored_rows(result: Any, truth_m: NDArray[np.float64], order: NDArray[np.intp]) -> Rows:
    """The ok rows of one run (``order``: each truth row's row of the estimates)."""
    est = result.estimates
    capped, ok = cap_estimates(est.distance_m, est.reason)
    ok &= np.asarray(est.status, dtype=object) == "ok"
    d, s, ok = capped[order], np.asarray(est.extra["sigma_m"], dtype=float)[order], ok[order]
    return d[ok] - truth_m[ok], s[ok], truth_m[ok]


def kitti_rows(data: Path, source: BoxSource, method: str, options: dict[str, Any]) -> Rows:
    """``method`` over the 13 sequences with ``source``'s boxes, as the evaluation runs it."""
    parts = []
    for scene in scenes(data, source).values():
        seq = scene.seq
        estimator = make_estimator(method, seq.camera, **options)
        result = estimate_sequence(
            estimator,
            scene.boxes,
            seq.timestamps_s,
            seq.rotations(ROTATION),
            vehicle_classes=set(scene.boxes.cls.tolist()),
        )
        n = len(scene.boxes)
        index = np.full(n, -1)
        index[result.boxes.extra["row"]] = np.arange(len(result.boxes))
        order = index[scene.det_rows]
        keep = order >= 0
        parts.append(scored_rows(result, scene.truth_m[keep], order[keep]))
    return concat(parts)


def synthetic_rows(
    method: str,
    options: dict[str, Any],
    types: dict[str, float] | None,
    labelled: bool,
    quantity: str = "distance",
) -> Rows:
    """``method`` on synthetic flat-road traffic (four seeds); ``types`` the vehicle mix (None:
    all cars), ``labelled``: boxes carry the true class (else every box ``Car``).
    ``quantity``: ``distance`` (``sigma_m``), ``speed`` (``speed_sigma_mps``, m/s) or ``ttc``
    (``ttc_sigma_s``, s, approaching vehicles); the third array is always the true distance."""
    parts = []
    for seed in SIM_SEEDS:
        kw: dict[str, Any] = {"seed": seed, "box_noise_px": 0.5}
        if types is not None:
            kw.update(vehicle_types=types, label_types=labelled)
        sim = simulate_traffic(SIM_CAMERA, 12, 150, **kw)
        n = len(sim.timestamps_s)
        track = RotationTrack(sim.timestamps_s, np.repeat(np.eye(3)[None], n, 0), np.ones(n, bool))
        estimator = make_estimator(method, SIM_CAMERA, **options)
        result = estimate_sequence(
            estimator, sim.boxes, sim.timestamps_s, track, vehicle_classes=set(sim.boxes.cls)
        )
        z = np.asarray(sim.z_m, dtype=float)
        if quantity == "distance":
            parts.append(scored_rows(result, z, np.arange(len(z))))
            continue
        ok = np.asarray(result.estimates.status, dtype=object) == "ok"
        extra = result.estimates.extra
        if quantity == "speed":
            value, sigma, truth = extra["speed_mps"], extra["speed_sigma_mps"], sim.speed_mps
        else:
            with np.errstate(divide="ignore"):
                truth = np.where(sim.speed_mps < 0, -z / sim.speed_mps, np.nan)
            value, sigma = extra["ttc_s"], extra["ttc_sigma_s"]
        err = np.asarray(value, dtype=float) - truth
        ok &= np.isfinite(err) & np.isfinite(np.asarray(sigma, dtype=float))
        parts.append((err[ok], np.asarray(sigma, dtype=float)[ok], z[ok]))
    return concat(parts)


def raw_lead_rows(out: Path, method: str, max_z_m: float = 40.0) -> Rows:
    """The ok rows of ``method`` in a ``benchmarks/kitti_raw_lead.py`` output folder ``out``
    against its LiDAR truth (the nearest face; boxes not cut by the border, z ≤ ``max_z_m``)."""
    records = out / method / "records.csv"
    estimates, sigmas = read_estimates(records), read_sigmas(records)
    with records.open(newline="") as fh:
        ok = {
            (int(r["frame"]), int(r["track_id"])) for r in csv.DictReader(fh) if r["status"] == "ok"
        }
    err, sigma, z = [], [], []
    with (out / "lidar_boxes.csv").open(newline="") as fh:
        for row in csv.DictReader(fh):
            key, truth = (int(row["frame"]), int(row["track_id"])), float(row["z"])
            if int(row["truncated"]) == 0 and truth <= max_z_m and key in ok:
                err.append(estimates[key] - truth)
                sigma.append(sigmas[key])
                z.append(truth)
    return np.array(err), np.array(sigma), np.array(z)


def concat(parts: list[Rows]) -> Rows:
    e, s, z = (np.concatenate([p[i] for p in parts]) for i in range(3))
    return e, s, z


def coverage(
    err: NDArray[np.float64], sigma: NDArray[np.float64]
) -> tuple[int, float, float, float]:
    """n, share within 1σ, within 2σ, median |error|/σ."""
    if not err.size:
        return 0, np.nan, np.nan, np.nan
    r = np.abs(err) / sigma
    return err.size, float(np.mean(r <= 1.0)), float(np.mean(r <= 2.0)), float(np.median(r))


def table_line(label: str, rows: Rows) -> str:
    err, sigma, z = rows
    cells = [f"{label:46s}"]
    for lo, hi in ((0.0, np.inf), *BINS_M):
        sel = (z >= lo) & (z < hi)
        n, c1, c2, med = coverage(err[sel], sigma[sel])
        cells.append(f"{n:6d} {c1:5.2f} {c2:5.2f} {med:5.2f}")
    return " | ".join(cells)


def header() -> str:
    groups = ["all", "0-20 m", "20-40 m", "40+ m"]
    sub = f"{'n':>6s} {'≤1σ':>5s} {'≤2σ':>5s} {'med':>5s}"
    return (
        f"{'source / method':46s} | "
        + " | ".join(f"{g:^{len(sub)}s}" for g in groups)
        + f"\n{'':46s} | "
        + " | ".join(sub for _ in groups)
    )


def runs(args: argparse.Namespace) -> Iterator[tuple[str, Rows]]:
    """(label, rows) of every source × method asked for."""
    sources = args.sources.split(",")
    for out in args.raw_lead_out:
        yield f"kitti_raw_lead {out.name} / ours", raw_lead_rows(out, "ours")
    for method in args.methods.split(","):
        for name in ("gt", "pointrcnn", "rrc"):
            if name in sources:
                yield (
                    f"kitti {name} / {method}",
                    kitti_rows(args.data, BoxSource(name), method, args.ours_options),
                )
        if "synthetic" in sources:
            opts = args.ours_options
            generic = {**opts, "generic_classes": ("Car",)}
            yield f"synthetic cars / {method}", synthetic_rows(method, opts, None, True)
            yield (
                f"synthetic true classes / {method}",
                synthetic_rows(method, opts, MIXED_TRAFFIC, True),
            )
            yield (
                f"synthetic class-blind / {method}",
                synthetic_rows(method, opts, MIXED_TRAFFIC, False),
            )
            yield (
                f"synthetic class-blind generic / {method}",
                synthetic_rows(method, generic, MIXED_TRAFFIC, False),
            )
            for quantity in ("speed", "ttc"):
                yield (
                    f"synthetic true classes {quantity} / {method}",
                    synthetic_rows(method, opts, MIXED_TRAFFIC, True, quantity),
                )
            yield (
                f"synthetic class-blind generic σ / {method}",
                synthetic_rows(
                    method, {**generic, "generic_sigma_only": True}, MIXED_TRAFFIC, False
                ),
            )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--sources", default="gt,pointrcnn,rrc,synthetic")
    parser.add_argument("--methods", default="ours,ours-offline")
    parser.add_argument("--ours-options", type=json.loads, default={})
    parser.add_argument(
        "--raw-lead-out",
        type=Path,
        nargs="*",
        default=[],
        help="output folders of benchmarks/kitti_raw_lead.py to score (its ours records)",
    )
    args = parser.parse_args(argv)
    if any(s in args.sources for s in ("gt", "pointrcnn", "rrc")) and not args.data.is_dir():
        print(f"KITTI tracking data not found at {args.data}", file=sys.stderr)
        return 2
    print(
        "Coverage of ours' sigma_m on its ok rows: share of |error| <= 1σ and <= 2σ "
        "(ideal 0.68 / 0.95), median |error|/σ (ideal 0.67), by truth distance"
    )
    print(header())
    for label, rows in runs(args):
        print(table_line(label, rows), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
