"""Cost of ``ours`` per target and per frame on one core.

Only the estimator is timed (``Estimator.estimate`` on prepared frames: boxes, θ, rotation),
in process CPU time with numpy/BLAS limited to one thread; the detector and the odometry are
not counted (as in the paper's comparison). Two workloads:

1. KITTI tracking label boxes of every road-user class (Car, Van, Truck, Pedestrian, Cyclist,
   Tram, Misc, Person_sitting — not only the protocol's evaluated ones), ORB-SLAM3 rotations,
   all 13 sequences: the traffic density of real urban scenes.
2. Simulated traffic (:func:`slopedist.synthetic.traffic.simulate_traffic`) with a fixed
   number of vehicles per frame, to show the fixed per-frame cost and the cost per extra target.
3. Scaling: the same traffic at 10, 100 and 1000 vehicles per frame (``--targets``: any
   counts, e.g. ``--targets 300,3000``), with track ids and without (id-less boxes are
   associated by IoU; ``--association ids`` or ``iou`` for one of them): the median wall and
   CPU time per frame over ``--repeats`` runs, each over the cost at the previous count, and
   the peak memory the estimator allocates over a run (``tracemalloc``, a run of its own).
   The scene keeps its size, so at 1000 vehicles the boxes crowd the image: the overlapping
   box pairs per frame are printed too (the occlusion check and the IoU association are built
   not to visit them all).

Usage::

    python benchmarks/ours_speed.py [--data ../shared/data/kitti_tracking] [--repeats 3]
                                    [--scaling-frames 40] [--targets 10,100,1000]
                                    [--skip kitti,simulated]
                                    [--association ids,iou]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from slopedist.core.camera import Camera  # noqa: E402
from slopedist.estimators import make_estimator  # noqa: E402
from slopedist.estimators.base import FrameInput  # noqa: E402
from slopedist.evaluation.table import format_table  # noqa: E402
from slopedist.io.detections.boxes import overlapping_pairs  # noqa: E402
from slopedist.io.kitti.tracking import (  # noqa: E402
    RotationSource,
    list_sequences,
    load_sequence,
)
from slopedist.streaming.step import ego_gradients  # noqa: E402
from slopedist.synthetic.traffic import simulate_traffic  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kitti_tracking"
METHODS = ("paper", "ours", "ours-selfcal")


def cpu_time(method: str, camera: Camera, frames: list[FrameInput], repeats: int) -> float:
    """Best of ``repeats`` runs of the estimator over ``frames``, CPU seconds."""
    best = float("inf")
    for _ in range(repeats):
        est = make_estimator(method, camera)
        est.reset()
        t0 = time.process_time()
        for fr in frames:
            est.estimate(fr)
        best = min(best, time.process_time() - t0)
    return best


def kitti(data: Path, repeats: int) -> None:
    print("1. KITTI tracking label boxes of all road-user classes, ORB-SLAM3 rotations")
    totals = {m: 0.0 for m in METHODS}
    n_targets = n_frames = 0
    for name in list_sequences(data):
        seq = load_sequence(data, name)
        labels = seq.labels.select(seq.labels.cls != "DontCare")
        track = seq.rotations(RotationSource.ORBSLAM3)
        theta = ego_gradients(track)
        frames = [
            FrameInput(
                k, float(seq.timestamps_s[k]), float(theta[k]), b, R_world_cam=track.R_world_cam[k]
            )
            for k, b in labels.by_frame()
        ]
        n_targets += len(labels)
        n_frames += len(frames)
        for m in METHODS:
            totals[m] += cpu_time(m, seq.camera, frames, repeats)
    rows = [[m, 1e3 * totals[m] / n_frames, 1e3 * totals[m] / n_targets] for m in METHODS]
    print(f"   {n_targets} targets in {n_frames} frames ({n_targets / n_frames:.1f} per frame)")
    print(format_table(["method", "ms/frame", "ms/target"], rows) + "\n")


def traffic_frames(
    cam: Camera, n: int, n_frames: int, with_ids: bool = True
) -> tuple[list[FrameInput], int]:
    """Frames of simulated traffic with ``n`` vehicles, and their number of boxes."""
    sim = simulate_traffic(
        cam,
        n,
        n_frames,
        seed=n,
        z_range_m=(10.0, 60.0),
        speed_range_mps=(-2.0, 2.0),
        box_noise_px=0.5,
        with_ids=with_ids,
    )
    eye = np.eye(3)
    frames = [
        FrameInput(k, float(sim.timestamps_s[k]), 0.0, b, R_world_cam=eye)
        for k, b in sim.boxes.by_frame()
    ]
    return frames, len(sim.boxes)


def simulated(repeats: int) -> None:
    print("2. Simulated traffic, N vehicles per frame (200 frames)")
    cam = Camera(721.5, 609.6, 172.9, 1.65, 0.0)
    rows = []
    for n in (1, 5, 10, 20, 30, 60):
        frames, n_boxes = traffic_frames(cam, n, 200)
        row: list[object] = [n, n_boxes / len(frames)]
        for m in ("ours", "ours-selfcal"):
            sec = cpu_time(m, cam, frames, repeats)
            row += [1e3 * sec / len(frames), 1e3 * sec / n_boxes]
        rows.append(row)
    print(
        format_table(
            [
                "N",
                "targets/frame",
                "ours ms/frame",
                "ours ms/target",
                "selfcal ms/frame",
                "selfcal ms/target",
            ],
            rows,
        )
    )


def overlapping_pairs_per_frame(frames: list[FrameInput]) -> float:
    """Mean number of box pairs per frame whose interiors overlap."""
    return (
        float(
            np.mean([overlapping_pairs(fr.boxes.boxes, fr.boxes.boxes)[0].size for fr in frames])
            - np.mean([len(fr.boxes) for fr in frames])  # each box overlaps itself
        )
        / 2.0
    )


def peak_memory_mb(method: str, camera: Camera, frames: list[FrameInput]) -> float:
    """Peak memory the estimator allocates over a run of ``frames`` (MB, ``tracemalloc``)."""
    est = make_estimator(method, camera)
    tracemalloc.start()
    for fr in frames:
        est.estimate(fr)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak / 1e6


def run_costs(
    method: str, camera: Camera, frames: list[FrameInput], repeats: int
) -> tuple[float, float]:
    """Median over ``repeats`` runs of the estimator over ``frames``: (wall, CPU) seconds."""
    wall, cpu = [], []
    for _ in range(repeats):
        est = make_estimator(method, camera)
        est.reset()
        w0, c0 = time.perf_counter(), time.process_time()
        for fr in frames:
            est.estimate(fr)
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
    return float(np.median(wall)), float(np.median(cpu))


def scaling(repeats: int, n_frames: int, counts: Sequence[int], associations: list[str]) -> None:
    listed = ", ".join(str(n) for n in counts)
    print(f"3. Scaling: ours per frame at {listed} vehicles per frame ({n_frames} frames,")
    print(f"   median of {repeats} runs; ÷ previous: ms/frame over that at the previous N)")
    cam = Camera(721.5, 609.6, 172.9, 1.65, 0.0)
    rows = []
    for with_ids in (True, False):
        if ("ids" if with_ids else "iou") not in associations:
            continue
        previous = (math.nan, math.nan)
        for n in counts:
            frames, n_boxes = traffic_frames(cam, n, n_frames, with_ids)
            wall, cpu = (1e3 * sec / len(frames) for sec in run_costs("ours", cam, frames, repeats))
            rows.append(
                [
                    "track ids" if with_ids else "IoU (no ids)",
                    n,
                    n_boxes / len(frames),
                    overlapping_pairs_per_frame(frames),
                    wall,
                    cpu,
                    1e3 * cpu / (n_boxes / len(frames)),
                    wall / previous[0],
                    cpu / previous[1],
                    peak_memory_mb("ours", cam, frames),
                ]
            )
            previous = (wall, cpu)
    header = [
        "association",
        "N",
        "targets/frame",
        "overlapping pairs/frame",
        "wall ms/frame",
        "CPU ms/frame",
        "CPU us/target",
        "wall ÷ previous",
        "CPU ÷ previous",
        "peak MB",
    ]
    print(format_table(header, rows))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--scaling-frames", type=int, default=40, help="frames per scaling run")
    ap.add_argument(
        "--targets", default="10,100,1000", help="vehicles per frame of the scaling section"
    )
    ap.add_argument(
        "--skip", default="", help="sections to skip, comma-separated: kitti, simulated"
    )
    ap.add_argument(
        "--association",
        default="ids,iou",
        help="scaling runs with track ids (ids) and id-less boxes associated by IoU (iou)",
    )
    args = ap.parse_args(argv)
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    counts = [int(n) for n in args.targets.split(",")]
    if "kitti" in skip:
        pass
    elif (args.data / "label_02").is_dir():
        kitti(args.data, args.repeats)
    else:
        print(f"(KITTI tracking data not found at {args.data}: section 1 skipped)\n")
    if "simulated" not in skip:
        simulated(args.repeats)
        print()
    associations = [a.strip() for a in args.association.split(",")]
    scaling(args.repeats, args.scaling_frames, counts, associations)
    return 0


if __name__ == "__main__":
    sys.exit(main())
