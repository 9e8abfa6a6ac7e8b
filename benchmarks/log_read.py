"""Per-frame cost of reading frames from a drive log vs. the same frames from an image folder.

The 78 real 1242×375 frames of ``../shared/data/kitti_raw_lead`` (or, with ``--synthetic`` or
without the shared data, 78 synthetic frames of that size) are written once to a temporary ROS 1
bag, ROS 2 sqlite3 bag and ROS 2 MCAP bag, raw (``bgr8``), JPEG- and PNG-compressed, and then read
back ``--repeat`` times with :class:`slopedist.io.rosbag.LogFrameSource`; the image folder is
read with :class:`slopedist.io.frames.ImageFolderSource` (PNG files). Logs with PNG-compressed
images decode the same PNG data as the folder, so their difference to it is the cost of the log
container itself (reading, deserialising, the stamp bookkeeping). Prints the median wall
time per frame (milliseconds) of one full pass over each source, and the difference to the
folder. The budget: a bag adds no more than 2 ms per frame over the folder.

Usage::

    PYTHONPATH=src python benchmarks/log_read.py [--repeat 5] [--synthetic]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from slopedist.core.camera import Camera
from slopedist.io.frames import FrameSource, ImageFolderSource
from slopedist.io.rosbag import LogFrameSource
from slopedist.io.rosbag_write import ImageEncoding, LogFormat, LogFrame, LogTopics, write_log

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "kitti_raw_lead" / "image_02"
W, H, N = 1242, 375, 78


def synthetic_folder(folder: Path) -> Path:
    """78 frames of textured noise (PNG), so that decoding costs like a real image."""
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    base = cv2.GaussianBlur(rng.integers(0, 255, (H, W, 3), dtype=np.uint8), (0, 0), 3)
    for k in range(N):
        cv2.imwrite(str(folder / f"{k:010d}.png"), np.roll(base, 5 * k, axis=1))
    return folder


def pass_ms(source: FrameSource) -> float:
    """Wall time of one full pass, milliseconds per frame."""
    t0 = time.perf_counter()
    n = sum(1 for f in source if f.ok)
    return (time.perf_counter() - t0) * 1e3 / max(n, 1)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5, help="passes over each source")
    parser.add_argument("--synthetic", action="store_true", help="synthetic frames")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        folder = DEFAULT_DATA
        label = "kitti_raw_lead (78 real PNG frames)"
        if args.synthetic or not folder.is_dir():
            folder, label = synthetic_folder(tmp / "frames"), f"{N} synthetic PNG frames"
        images = [f.image for f in ImageFolderSource(folder) if f.image is not None]
        camera = Camera(721.5377, 609.5593, 172.854).with_image_size(W, H)
        frames = [LogFrame(k * 100_000_000, im) for k, im in enumerate(images)]
        sources: dict[str, FrameSource] = {"image folder (PNG)": ImageFolderSource(folder)}
        for fmt in LogFormat:
            for enc in ImageEncoding:
                name = f"{fmt.value}-{enc.value}"
                path = tmp / (f"{name}.bag" if fmt is LogFormat.ROS1 else name)
                write_log(path, frames, camera, fmt, enc)
                sources[f"{fmt.value}, {enc.value}"] = LogFrameSource(path, LogTopics().image)
        print(f"{label}, {args.repeat} passes each; median ms per frame")
        folder_ms = None
        for name, source in sources.items():
            ms = statistics.median(pass_ms(source) for _ in range(args.repeat))
            folder_ms = ms if folder_ms is None else folder_ms
            print(f"  {name:<22} {ms:7.2f} ms   ({ms - folder_ms:+.2f} ms vs folder)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
