"""Distances from a video or an image folder with your own detector in the loop.

Usage::

    python examples/detector_loop.py FRAMES CALIB BOXES [--method ours] [--fps 10]

FRAMES is a video file or an image folder, CALIB its calibration (KITTI calib, 3×3 K, OpenCV
or ROS YAML). ``RecordedDetector`` stands in for your detector: it replays the boxes of a box
file (BOXES, e.g. written by ``slopedist detect``) frame by frame, with the call of a model
(an image in, an ``(N, 6)`` array of left, top, right, bottom, score, class index out). Put
your model's call in its place.

For each frame, the nearest vehicle with a distance is printed.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

import slopedist

VEHICLE_CLASS = 2
"""COCO's index of ``car`` (the class map of ultralytics' models and of most exported ones)."""


class RecordedDetector:
    """A detector's boxes replayed from a box file: call ``k`` gives frame ``k``'s boxes."""

    def __init__(self, path: Path) -> None:
        self.by_frame = slopedist.read_boxes(path).frame_lookup()
        self.calls = 0

    def __call__(self, image: np.ndarray) -> np.ndarray:
        """``(N, 6)``: left, top, right, bottom (pixels), score, class index."""
        table = self.by_frame.get(self.calls)
        self.calls += 1
        if table is None:
            return np.zeros((0, 6))
        score = np.nan_to_num(table.score, nan=1.0)
        return np.c_[table.boxes, score, np.full(len(table), VEHICLE_CLASS)]


def nearest(result: slopedist.FrameResult) -> slopedist.Target | None:
    """The target with the shortest distance to act on, if any."""
    ok = [t for t in result.targets if t.ok]
    return min(ok, key=lambda t: t.distance_m) if ok else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frames", type=Path)
    parser.add_argument("calib", type=Path)
    parser.add_argument("boxes", type=Path)
    parser.add_argument("--method", default="ours")
    parser.add_argument("--fps", type=float, default=None)
    args = parser.parse_args()

    detector = RecordedDetector(args.boxes)
    with slopedist.Pipeline(args.calib, method=args.method) as pipe:
        for frame in slopedist.open_frames(args.frames, fps=args.fps):
            if frame.image is None:
                continue  # an unreadable frame: nothing to detect in
            result = pipe.update(frame.image, detector(frame.image), frame.timestamp_s)
            lead = nearest(result)
            if lead is None:
                print(f"frame {result.frame:4d}  t {result.t:6.2f} s  no distance yet")
                continue
            sigma = f" ± {lead.sigma_m:.1f}" if math.isfinite(lead.sigma_m) else ""
            print(
                f"frame {result.frame:4d}  t {result.t:6.2f} s  nearest: {lead.cls} "
                f"(track {lead.track_id}) at {lead.distance_m:.1f}{sigma} m"
            )
        for warning in pipe.finish().warnings:
            print(warning)


if __name__ == "__main__":
    main()
