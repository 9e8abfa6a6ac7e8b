"""Bounded memory of a long ``slopedist run``: the full runner over 10 000 frames.

The runner (:func:`slopedist.streaming.loop.run_frames`: built-in visual odometry on every frame,
the
estimator, ``records.csv`` / ``frames.csv`` written and flushed frame by frame) is fed a short
real frame folder played forward and backward (0…n−1, n−2…1, 0…, so the motion stays
continuous) with increasing timestamps (10 Hz), each output frame with the boxes of the source
frame it shows. Frames are decoded from disk every time, as a real run decodes a video; no
10 000 files are written.

Source: ``../shared/data/kitti_raw_lead`` (78 real 1242×375 frames with the LiDAR vehicle boxes
of :func:`slopedist.io.kitti.raw.lidar_vehicle_boxes`); without it, a built-in synthetic
scenario rendered once to a temporary folder (``--synthetic``).

Prints, at 1 000, 5 000 and 10 000 frames (and at the end): resident set size (RSS, MB), peak
RSS, frames per second so far (wall clock, whole loop: decoding, odometry, estimation, writing),
and the rows written so far. Usage::

    /work/venv/bin/python benchmarks/run_memory.py [--frames 10000] [--method paper]
        [--synthetic SCENARIO] [--out bench_out/run_memory]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
from memory import peak_rss_mb, rss_mb  # benchmarks/memory.py, beside this script

from slopedist.core.camera import Camera
from slopedist.estimators import make_estimator
from slopedist.io.detections.boxes import BoxTable, concat_boxes
from slopedist.io.frames import Frame, FrameStatus
from slopedist.odometry import make_odometry
from slopedist.streaming.config import RECORDS_NAME, RunConfig
from slopedist.streaming.loop import run_frames

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "kitti_raw_lead"
CHECKPOINTS = (1000, 5000, 10000)
FPS = 10.0


def ping_pong(n_frames: int, n: int) -> list[int]:
    """Source frame shown at each of ``n_frames`` output frames: 0…n−1, n−2…1, 0…"""
    cycle = list(range(n)) + list(range(n - 2, 0, -1))
    return [cycle[k % len(cycle)] for k in range(n_frames)]


class LoopedFrames:
    """A frame source (:class:`slopedist.io.frames.FrameSource`) that plays image files in
    ``order``, frame ``k`` at ``k / FPS`` seconds, decoding each file when it is shown.

    ``on_frame(k)`` is called before frame ``k`` is handed out, i.e. once the runner has
    finished the ``k`` frames before it (the checkpoints hook in there).
    """

    def __init__(
        self, files: list[Path], order: list[int], on_frame: Callable[[int], None] | None = None
    ) -> None:
        self.path = files[0].parent
        self.files = files
        self.order = order
        self.on_frame = on_frame

    def expected_frames(self) -> int:
        return len(self.order)

    def frame_size(self) -> tuple[int, int]:
        image = cv2.imread(str(self.files[0]), cv2.IMREAD_COLOR)
        if image is None:
            raise SystemExit(f"cannot read {self.files[0]}")
        return int(image.shape[1]), int(image.shape[0])

    def __iter__(self) -> Iterator[Frame]:
        for k, idx in enumerate(self.order):
            if self.on_frame is not None:
                self.on_frame(k)
            image = cv2.imread(str(self.files[idx]), cv2.IMREAD_COLOR)
            yield Frame(k, k / FPS, np.asarray(image), FrameStatus.OK, self.files[idx].name)


def looped_boxes(source_boxes: BoxTable, order: list[int]) -> BoxTable:
    """The boxes of each output frame: those of the source frame it shows, renumbered; track
    ids are kept (a target seen again after a turn of the loop keeps its id)."""
    by_frame = source_boxes.frame_index()
    empty = source_boxes.select(np.zeros(len(source_boxes), dtype=bool))
    parts = []
    for k, idx in enumerate(order):
        b = by_frame.get(idx, empty)
        parts.append(
            BoxTable(np.full(len(b), k, np.int64), b.boxes, b.track_id, b.score, b.cls, {})
        )
    return concat_boxes(parts)


def kitti_raw_source(data: Path) -> tuple[list[Path], Camera, BoxTable, str]:
    """The lead-car drive: frame files, camera, LiDAR vehicle boxes."""
    from slopedist.io.kitti.raw import KittiRawDrive

    drive = KittiRawDrive.open(data)
    files = sorted(drive.image_dir.glob("*.png"))
    width, height = LoopedFrames(files, [0]).frame_size()
    boxes = drive.lidar_boxes((width, height))
    return files, drive.calib.camera(), boxes, f"kitti_raw_lead ({len(files)} real frames)"


def synthetic_source(
    scenario: str, n: int, folder: Path
) -> tuple[list[Path], Camera, BoxTable, str]:
    """``n`` frames of a built-in synthetic scenario, rendered once into ``folder``."""
    from slopedist.synthetic.scenarios import load_scenario
    from slopedist.synthetic.sequence import SyntheticSequence

    seq = SyntheticSequence(load_scenario(scenario))
    files, parts = [], []
    for k in range(min(n, len(seq))):
        f = seq.frame(k)
        path = folder / f"{k:06d}.png"
        cv2.imwrite(str(path), f.image)
        files.append(path)
        parts.append(f.detections)
    return files, seq.camera, concat_boxes(parts), f"synthetic '{scenario}' ({len(files)} frames)"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10000, help="frames to run")
    parser.add_argument("--method", default="paper", help="estimator")
    parser.add_argument(
        "--data", type=Path, default=DEFAULT_DATA, help="kitti_raw_lead folder (real frames)"
    )
    parser.add_argument(
        "--synthetic",
        metavar="SCENARIO",
        default=None,
        help="use 60 frames of a built-in synthetic scenario instead",
    )
    parser.add_argument("--out", type=Path, default=REPO / "bench_out" / "run_memory")
    args = parser.parse_args(argv)

    with tempfile.TemporaryDirectory() as tmp:
        if args.synthetic is None and not args.data.is_dir():
            print(
                f"kitti_raw_lead not found at {args.data}; using --synthetic same_flat",
                file=sys.stderr,
            )
            args.synthetic = "same_flat"
        if args.synthetic is not None:
            files, camera, source_boxes, what = synthetic_source(args.synthetic, 60, Path(tmp))
        else:
            files, camera, source_boxes, what = kitti_raw_source(args.data)
        order = ping_pong(args.frames, len(files))
        boxes = looped_boxes(source_boxes, order)
        width, height = LoopedFrames(files, [0]).frame_size()
        print(
            f"source: {what}, {width}×{height}, played forward and backward for "
            f"{args.frames} frames at {FPS:g} Hz; {len(boxes)} boxes "
            f"({len(boxes) / args.frames:.2f} per frame); method {args.method}; "
            f"built-in visual odometry; output {args.out}"
        )
        box_mb = (
            sum(
                a.nbytes for a in (boxes.frame, boxes.boxes, boxes.track_id, boxes.score, boxes.cls)
            )
            / 1e6
        )
        print(
            f"RSS before the run: {rss_mb():.1f} MB (the box file of the whole run is read "
            f"up front, as `slopedist run` does: {box_mb:.1f} MB of arrays, plus the runner's "
            "per-frame index of it)"
        )
        print(
            f"{'frames':>7s} {'RSS MB':>8s} {'peak MB':>8s} {'frames/s':>9s} {'rows':>8s}",
            flush=True,
        )
        start = time.perf_counter()
        checkpoints = {c for c in CHECKPOINTS if c < args.frames}
        records_path = args.out / RECORDS_NAME

        def report(k: int) -> None:
            if k in checkpoints:
                rows = sum(1 for _ in records_path.open()) - 1
                print(
                    f"{k:7d} {rss_mb():8.1f} {peak_rss_mb():8.1f} "
                    f"{k / (time.perf_counter() - start):9.1f} {rows:8d}",
                    flush=True,
                )

        frames = LoopedFrames(files, order, report)
        result = run_frames(
            frames,
            boxes,
            make_odometry("builtin", camera),
            make_estimator(args.method, camera),
            RunConfig(args.out, progress=False),
        )
        rows = sum(1 for _ in records_path.open()) - 1
        print(
            f"{result.frames:7d} {rss_mb():8.1f} {peak_rss_mb():8.1f} "
            f"{result.frames_per_s:9.1f} {rows:8d}   (end)"
        )
    print(
        f"odometry {result.odometry_ms_mean:.2f} ms, estimation {result.estimation_ms_mean:.3f}"
        f" ms per frame (means); odometry states: "
        + ", ".join(f"{k} {v}" for k, v in sorted(result.odometry_states.items()))
        + f"; {result.estimated} of {result.records} records with a distance"
    )
    return 0 if result.error is None and rows == len(boxes) else 1


if __name__ == "__main__":
    sys.exit(main())
