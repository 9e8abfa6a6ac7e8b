"""Memory per Ray worker over a long drive, run as a batch (``benchmarks/run_memory.py`` as a
``slopedist batch``).

The drives: the 78 real ``kitti_raw_lead`` frames played forward and backward (as in
``run_memory.py``) and encoded as MP4 videos at 10 fps — a short one (``--short`` frames), a long
one (``--frames``) and the short one again — with the LiDAR vehicle boxes of the frames they
show. They run as one batch on an embedded Ray instance with one CPU, so one worker process runs
them one after another; ``status.csv`` gives the worker's peak resident memory after each drive.
Memory is flat when the peak after the long drive is that after the short one.

Usage::

    PYTHONPATH=src python benchmarks/batch_memory.py [--frames 10000] [--short 200]
        [--out bench_out/batch_memory]
"""

from __future__ import annotations

import argparse
import csv
import shutil
import sys
import time
from pathlib import Path

import cv2
from run_memory import DEFAULT_DATA, kitti_raw_source, looped_boxes, ping_pong

from slopedist.batch import BatchOptions, load_drives, run_batch
from slopedist.detections.writers import write_box_csv

REPO = Path(__file__).resolve().parents[1]


def write_drive(
    folder: Path, files: list[Path], order: list[int], calib: Path, boxes: object
) -> None:
    """``folder``/{video.mp4, calib.txt, boxes.csv}: the frames ``order`` of ``files``."""
    folder.mkdir(parents=True, exist_ok=True)
    first = cv2.imread(str(files[0]))
    height, width = first.shape[:2]
    video = cv2.VideoWriter(
        str(folder / "video.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (width, height)
    )
    images = [cv2.imread(str(f)) for f in files]
    for idx in order:
        video.write(images[idx])
    video.release()
    shutil.copy(calib, folder / "calib.txt")
    write_box_csv(looped_boxes(boxes, order), folder / "boxes.csv")  # type: ignore[arg-type]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10000, help="frames of the long drive")
    parser.add_argument("--short", type=int, default=200, help="frames of the short drives")
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--out", type=Path, default=REPO / "bench_out" / "batch_memory")
    args = parser.parse_args(argv)
    if not args.data.is_dir():
        print(f"kitti_raw_lead not found at {args.data}", file=sys.stderr)
        return 2
    files, _camera, boxes, what = kitti_raw_source(args.data)
    drives = args.out / "drives"
    shutil.rmtree(args.out, ignore_errors=True)
    start = time.perf_counter()
    for name, n in (("a_short", args.short), ("b_long", args.frames)):
        write_drive(drives / name, files, ping_pong(n, len(files)), args.data / "calib.txt", boxes)
    shutil.copytree(drives / "a_short", drives / "c_short_again")
    print(
        f"{what}: drives of {args.short}, {args.frames}, {args.short} frames written as MP4 "
        f"in {time.perf_counter() - start:.0f} s"
    )
    import ray

    ray.init(address="local", num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        options = BatchOptions(progress=False, parquet=False)
        run_batch(load_drives(drives), args.out / "out", options)
    finally:
        ray.shutdown()
    with (args.out / "out" / "status.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    print(
        f"{'drive':14s} {'status':>7s} {'frames':>7s} {'seconds':>8s} {'frames/s':>9s} "
        f"{'worker peak RSS MB':>19s}"
    )
    for r in rows:
        seconds = float(r["seconds"] or "nan")
        print(
            f"{r['drive']:14s} {r['status']:>7s} {r['frames']:>7s} {seconds:8.1f} "
            f"{int(r['frames']) / seconds:9.1f} {r['worker_peak_rss_mb']:>19s}"
        )
    return 0 if all(r["status"] == "done" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
