"""Overlay label layout on the real ``kitti_raw_lead`` frames: placement rate and draw time.

``slopedist run`` (method ``ours``, built-in odometry, ``--overlay``) on the 78 real 1242×375
frames of ``../shared/data/kitti_raw_lead`` with the vehicle boxes of its LiDAR scans (as
``benchmarks/kitti_raw_lead.py`` makes them, about 13 per frame); every call of
:func:`slopedist.streaming.drawing.draw_fig3_overlay` is recorded. Then each recorded frame is
drawn again
``--repeat`` times and its labels are checked:

- placed: boxes whose label was drawn, of all boxes, and of the boxes whose estimate is ``ok``
  or ``upper_bound`` (the ones with a distance to read); compact: labels drawn in their short
  form; overlaps: pairs of drawn labels sharing a pixel (must be 0);
- how readable the drawn labels are: their distance from their own box (pixels between the two
  rectangles beyond the 3 px gap; over 5 px a leader line joins them), and how many cover more
  than a quarter of their area of other boxes;
- draw time: milliseconds per frame of :func:`draw_fig3_overlay` (the run's overlay stage
  without the encoder), processor time of the drawing thread (steadier than wall time on a
  shared machine), the minimum over the repeats of each frame's time, then the mean and the
  maximum over the frames.

Compare two source trees by running the script with each first on ``PYTHONPATH`` (the
placement statistics work with any version whose ``viz._draw_labels`` returns the label
rectangles).

Usage::

    PYTHONPATH=src python benchmarks/overlay_labels.py [--data ../shared/data/kitti_raw_lead]
        [--repeat 5]
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np

from slopedist.cli import main as slopedist_main
from slopedist.io.detections.writers import write_box_csv
from slopedist.io.kitti.raw import KittiRawDrive
from slopedist.streaming import drawing as viz
from slopedist.streaming.label_placement import LABEL_GAP_PX, Rect, box_rect

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "kitti_raw_lead"
SIZE = (1242, 375)


def record_overlay_calls(data: Path, work: Path) -> list[tuple[Any, ...]]:
    """The arguments of every ``draw_fig3_overlay`` call of a ``slopedist run --overlay`` on
    the drive in ``data`` (boxes from its LiDAR scans, written to ``work``)."""
    drive = KittiRawDrive.open(data)
    boxes = write_box_csv(drive.lidar_boxes(SIZE), work / "boxes.csv", ())
    calls: list[tuple[Any, ...]] = []

    def record(*args: Any) -> Any:
        calls.append(args)
        return viz.draw_fig3_overlay(*args)

    argv = ["run", str(drive.image_dir), "--calib", str(data / "calib.txt")]
    argv += ["--boxes", str(boxes), "--method", "ours", "--overlay", "--overlay-format", "png"]
    argv += ["--out", str(work / "run"), "--quiet"]
    with mock.patch("slopedist.streaming.loop.draw_fig3_overlay", record):
        if slopedist_main(argv) != 0:
            raise SystemExit("slopedist run failed")
    return calls


def frame_labels(args: tuple[Any, ...]) -> tuple[list[Any], float]:
    """The label rectangles of one frame's overlay (None = not drawn) and its draw time, ms."""
    drawn: list[Any] = []
    real = viz._draw_labels

    def keep(*a: Any, **k: Any) -> Any:
        drawn[:] = real(*a, **k)
        return drawn

    with mock.patch.object(viz, "_draw_labels", keep):
        t0 = time.thread_time()
        viz.draw_fig3_overlay(*args)
        ms = (time.thread_time() - t0) * 1e3
    return drawn, ms


def label_quality(rect: Rect, i: int, boxes: Any) -> tuple[float, float]:
    """Distance of label ``rect`` from box ``i`` (pixels beyond the gap) and the fraction of its
    area over the other boxes (summed over them)."""
    own = box_rect(boxes[i])
    dx = max(own.left - rect.right, rect.left - own.right, 0)
    dy = max(own.top - rect.bottom, rect.top - own.bottom, 0)
    area = (rect.right - rect.left) * (rect.bottom - rect.top)
    cover = sum(rect.overlap_area(box_rect(b)) for j, b in enumerate(boxes) if j != i)
    return max(float(np.hypot(dx, dy)) - LABEL_GAP_PX, 0.0), cover / area


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="kitti_raw_lead folder")
    parser.add_argument("--repeat", type=int, default=5, help="draws of each frame (timing)")
    args = parser.parse_args()
    if not (args.data / "image_02").is_dir():
        print(f"kitti_raw_lead not found at {args.data}", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        calls = record_overlay_calls(args.data, Path(tmp))
    times: list[float] = []
    gaps: list[float] = []
    covering = 0
    total = placed = with_distance = placed_with_distance = overlaps = compact = 0
    for call in calls:
        estimates = call[3]
        frame_ms = []
        for _ in range(args.repeat):
            rects, ms = frame_labels(call)
            frame_ms.append(ms)
        times.append(min(frame_ms))
        has_distance = [s in ("ok", "upper_bound") for s in estimates.status]
        total += len(rects)
        placed += sum(r is not None for r in rects)
        with_distance += sum(has_distance)
        placed_with_distance += sum(r is not None for r, d in zip(rects, has_distance) if d)
        compact += sum(getattr(r, "form", 0) > 0 for r in rects if r is not None)
        rects = [getattr(r, "rect", r) for r in rects]  # a Placement or a bare Rect
        shown = [r for r in rects if r is not None]
        for i, r in enumerate(rects):
            if r is not None:
                gap, cover = label_quality(r, i, call[2].boxes)
                gaps.append(gap)
                covering += cover > 0.25
        overlaps += sum(a.intersects(b) for a, b in itertools.combinations(shown, 2))
    print(f"kitti_raw_lead: {len(calls)} frames, {total} boxes ({total / len(calls):.1f} a frame)")
    print(f"labels placed: {placed}/{total} = {100 * placed / max(total, 1):.1f} % of all boxes")
    print(
        f"labels placed, ok/upper_bound boxes: {placed_with_distance}/{with_distance} = "
        f"{100 * placed_with_distance / max(with_distance, 1):.1f} %"
    )
    print(f"compact labels: {compact}; overlapping label pairs: {overlaps}")
    far = sum(g > 5 for g in gaps)
    print(
        f"distance label-box: mean {statistics.fmean(gaps):.1f} px, median "
        f"{statistics.median(gaps):.1f} px, max {max(gaps):.0f} px; {far} with a leader "
        f"line (> 5 px); {covering} cover > 25 % of their area of other boxes"
    )
    print(
        f"draw_fig3_overlay: {statistics.fmean(times):.2f} ms a frame (mean), "
        f"{max(times):.2f} ms max (min of {args.repeat} draws per frame)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
