"""Distances from a live camera or a network stream: frames dropped, never queued.

Usage::

    python examples/live_stream.py SOURCE CALIB BOXES [--method ours]

SOURCE is what ``cv2.VideoCapture`` opens: a camera index (``0``), a stream URL
(``rtsp://...``) or a video file, which is played at its own frame rate as a camera would
deliver it. A reader thread keeps only the newest frame: when the loop falls behind, the frames
it could not take are dropped (and counted) instead of queueing up, so each result is about the
newest frame. Each frame keeps its own time (a file's timestamp, else the time it was read),
so the road gradient looks back one second whatever was dropped.

BOXES stands in for a detector: the boxes of a box file by frame number (the number of the
frame in the stream); put your model's call in ``detect``.
"""

from __future__ import annotations

import argparse
import threading
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

import slopedist


class LatestFrame:
    """The newest frame of a capture, with its number and time; older ones are dropped."""

    def __init__(self, source: int | str) -> None:
        self.capture = cv2.VideoCapture(source)
        if not self.capture.isOpened():
            raise SystemExit(f"cannot open {source!r}")
        self.is_file = isinstance(source, str) and Path(source).is_file()
        self.lock = threading.Lock()
        self.frame: tuple[int, float, np.ndarray] | None = None
        self.read = 0
        self.dropped = 0
        self.ended = threading.Event()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        start = time.monotonic()
        while True:
            ok, image = self.capture.read()
            if not ok:
                break
            if self.is_file:  # a file plays at its own rate, as a camera delivers frames
                t = self.capture.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
                time.sleep(max(0.0, start + t - time.monotonic()))
            else:
                t = time.monotonic() - start
            with self.lock:
                self.dropped += self.frame is not None  # the loop never took the one before
                self.frame = (self.read, t, image)
                self.read += 1
        self.ended.set()

    def take(self) -> tuple[int, float, np.ndarray] | None:
        """The newest frame not yet taken, or None."""
        with self.lock:
            frame, self.frame = self.frame, None
        return frame


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source")
    parser.add_argument("calib", type=Path)
    parser.add_argument("boxes", type=Path)
    parser.add_argument("--method", default="ours")
    args = parser.parse_args()

    by_frame = slopedist.read_boxes(args.boxes).frame_lookup()

    def detect(number: int, image: np.ndarray) -> Any:
        return by_frame.get(number, slopedist.BoxTable.empty())

    source: int | str = int(args.source) if args.source.isdigit() else args.source
    stream = LatestFrame(source)
    stepped = 0
    with slopedist.Pipeline(args.calib, method=args.method) as pipe:
        while not (stream.ended.is_set() and stream.frame is None):
            frame = stream.take()
            if frame is None:
                time.sleep(0.002)
                continue
            number, t, image = frame
            result = pipe.update(image, detect(number, image), t)
            stepped += 1
            shown = [f"{x.cls} {x.distance_m:.1f} m" for x in result.targets if x.ok]
            print(f"frame {number:4d}  t {t:6.2f} s  {', '.join(shown) or 'no distance yet'}")
    print(f"{stepped} frames stepped, {stream.dropped} dropped of {stream.read} read")


if __name__ == "__main__":
    main()
