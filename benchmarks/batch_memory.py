"""Memory per Ray worker over a long drive, run as a batch (``benchmarks/run_memory.py`` as a
``slopedist batch``).

The drives: the 78 real ``kitti_raw_lead`` frames played forward and backward (as in
``run_memory.py``) and encoded as MP4 videos at 10 fps — a short one (``--short`` frames), a long
one (``--frames``) and the short one again — with the LiDAR vehicle boxes of the frames they
show. They run as one batch on an embedded Ray instance with one CPU, so one worker process runs
them one after another; ``status.csv`` gives the worker's peak resident memory after each drive.
Memory is flat when the peak after the long drive is that after the short one.

While the batch runs, the worker's resident memory is sampled every ``--every`` seconds (the
process titled ``ray::process_drive``, from ``/proc``) with the frames its drive has written so
far (lines of the frame log being written in its temporary folder), and printed per 1,000 frames
of the long drive: flat memory over the drive is the same RSS at frame 1,000 and at the end.

Usage::

    PYTHONPATH=src python benchmarks/batch_memory.py [--frames 10000] [--short 200]
        [--out bench_out/batch_memory]
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import shutil
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
from run_memory import DEFAULT_DATA, kitti_raw_source, looped_boxes, ping_pong

from slopedist.batch import BatchOptions, load_drives, run_batch
from slopedist.batch.drive import TMP_PREFIX
from slopedist.io.detections.writers import write_box_csv
from slopedist.io.outputs import partial_path
from slopedist.streaming.config import FRAMES_NAME

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


TASK_TITLE = b"ray::process_drive"
"""Process title Ray gives a worker while it runs a drive."""


def _status(pid: int | str) -> dict[str, str]:
    lines = Path(f"/proc/{pid}/status").read_text().splitlines()
    return dict(line.split(":", 1) for line in lines if ":" in line)


def _descends_from_us(pid: str) -> bool:
    """Whether process ``pid`` is a descendant of this one (Ray's workers of this driver)."""
    me, current = str(os.getpid()), pid
    for _ in range(8):
        current = _status(current)["PPid"].strip()
        if current == me:
            return True
        if current in ("0", "1"):
            return False
    return False


def task_rss_mb() -> float:
    """Resident memory (MB) of this driver's worker running a drive now (NaN when none is)."""
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            if (proc / "cmdline").read_bytes().startswith(TASK_TITLE) and _descends_from_us(
                proc.name
            ):
                return int(_status(proc.name)["VmRSS"].split()[0]) / 1024
        except (OSError, KeyError):
            continue
    return math.nan


def frames_written(out: Path) -> tuple[str, int]:
    """The drive running now (its temporary folder) and the frames its ``frames.csv`` has."""
    for folder in out.glob(f"{TMP_PREFIX}*"):
        log = partial_path(folder / FRAMES_NAME)
        if log.is_file():
            drive = folder.name[len(TMP_PREFIX) :].rsplit("-", 1)[0]
            return drive, max(log.read_bytes().count(b"\n") - 1, 0)
    return "", 0


@dataclass
class RssSampler:
    """Samples ``(seconds, drive, frames written, worker RSS MB)`` every ``every`` seconds."""

    out: Path
    every: float
    samples: list[tuple[float, str, int, float]] = field(default_factory=list)
    stop: threading.Event = field(default_factory=threading.Event)

    def run(self) -> None:
        start = time.perf_counter()
        while not self.stop.wait(self.every):
            rss = task_rss_mb()
            drive, frames = frames_written(self.out)
            if drive and math.isfinite(rss):
                self.samples.append((time.perf_counter() - start, drive, frames, rss))

    def over_drive(self, drive: str, step: int) -> list[tuple[float, str, int, float]]:
        """The first sample at or after each ``step`` frames of ``drive``, and its last."""
        mine = [s for s in self.samples if s[1] == drive]
        picked, mark = [], step
        for s in mine:
            if s[2] >= mark:
                picked.append(s)
                mark = (s[2] // step + 1) * step
        if mine and (not picked or picked[-1] is not mine[-1]):
            picked.append(mine[-1])
        return picked


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10000, help="frames of the long drive")
    parser.add_argument("--short", type=int, default=200, help="frames of the short drives")
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--out", type=Path, default=REPO / "bench_out" / "batch_memory")
    parser.add_argument("--every", type=float, default=1.0, help="RSS sampling period, s")
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
    sampler = RssSampler(args.out / "out", args.every)
    thread = threading.Thread(target=sampler.run, daemon=True)
    try:
        options = BatchOptions(progress=False, parquet=False)
        (args.out / "out").mkdir(parents=True)
        thread.start()
        run_batch(load_drives(drives), args.out / "out", options)
    finally:
        sampler.stop.set()
        ray.shutdown()
    print(f"worker RSS over the long drive (sampled every {args.every:g} s):")
    print(f"{'frames':>7s} {'seconds':>8s} {'worker RSS MB':>14s}")
    for t, _drive, frames, rss in sampler.over_drive("b_long", 1000):
        print(f"{frames:7d} {t:8.1f} {rss:14.1f}")
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
