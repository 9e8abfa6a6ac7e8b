"""Inputs and outputs: frames (image folders, videos, drive logs), calibrations, boxes
(:mod:`~slopedist.io.detections`), depth maps (:mod:`~slopedist.io.depth`), the KITTI datasets
(:mod:`~slopedist.io.kitti`), and the crash-safe output files and their formatting.

Internal: the names a user needs are those of :mod:`slopedist` itself (docs/python.md).
"""

from slopedist.io.frames import (
    Frame,
    FrameSource,
    FrameStatus,
    ImageFolderSource,
    VideoSource,
    check_calibration,
    open_frames,
    read_timestamps,
)

__all__ = [
    "Frame",
    "FrameSource",
    "FrameStatus",
    "ImageFolderSource",
    "VideoSource",
    "check_calibration",
    "open_frames",
    "read_timestamps",
]
