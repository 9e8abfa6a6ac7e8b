"""Reading user media: frames from image folders and video files."""

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
