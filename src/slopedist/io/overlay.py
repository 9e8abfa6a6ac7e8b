"""Writing annotated frames: a folder of PNG files or an MP4 video (``cv2.VideoWriter``, mp4v),
or an animated GIF where OpenCV cannot write MP4 (needs Pillow).

Convention: images are BGR ``H×W×3`` uint8.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.errors import ConfigurationError, InputFileError


class OverlayWriter:
    """Writes one annotated image per frame, to PNG files or to an MP4 file.

    ``target`` ending in ``.mp4`` writes a video at ``fps`` frames per second (size of the first
    frame; frames of another size are resized to it); anything else is a folder that receives
    ``<frame index, 6 digits>.png``. Frames without pixels are written to the video as a grey
    placeholder (so its timeline stays right) and skipped in a PNG folder.
    """

    def __init__(self, target: str | Path, fps: float = 10.0) -> None:
        self.target = Path(target)
        self.fps = fps
        self.is_video = self.target.suffix.lower() == ".mp4"
        self._video: cv2.VideoWriter | None = None
        self._size: tuple[int, int] | None = None
        self.written = 0
        if self.is_video:
            if not fps > 0:
                raise ConfigurationError(f"overlay video needs a frame rate > 0, got {fps}")
            self.target.parent.mkdir(parents=True, exist_ok=True)
        else:
            self.target.mkdir(parents=True, exist_ok=True)

    def write(self, index: int, image: NDArray[np.uint8]) -> None:
        """Write the annotated image of frame ``index``."""
        if not self.is_video:
            path = self.target / f"{index:06d}.png"
            if not cv2.imwrite(str(path), image):
                raise InputFileError(path, "could not write the overlay image")
            self.written += 1
            return
        if self._video is None:
            self._size = (int(image.shape[1]), int(image.shape[0]))
            self._video = cv2.VideoWriter(
                str(self.target), cv2.VideoWriter.fourcc(*"mp4v"), self.fps, self._size
            )
            if not self._video.isOpened():
                raise InputFileError(self.target, "OpenCV cannot write an MP4 (mp4v) video here")
        assert self._size is not None
        if (image.shape[1], image.shape[0]) != self._size:
            image = np.asarray(cv2.resize(image, self._size))
        self._video.write(image)
        self.written += 1

    def write_placeholder(self, index: int, text: str) -> None:
        """Mark a frame without pixels (video only: a grey frame with ``text``)."""
        if not self.is_video or self._size is None:
            return
        image = np.full((self._size[1], self._size[0], 3), 64, np.uint8)
        cv2.putText(
            image, text, (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 1, cv2.LINE_AA
        )
        self.write(index, image)

    def close(self) -> None:
        """Finish the video file (no-op for PNG folders)."""
        if self._video is not None:
            self._video.release()
            self._video = None


class GifWriter:
    """Animated GIF fallback for the overlay (half resolution)."""

    def __init__(self, path: Path, fps: float) -> None:
        self.path = path
        self.fps = fps
        self.frames: list[Any] = []

    def write(self, index: int, image: NDArray[np.uint8]) -> None:
        from PIL import Image

        small = cv2.resize(image, (image.shape[1] // 2, image.shape[0] // 2))
        self.frames.append(Image.fromarray(cv2.cvtColor(small, cv2.COLOR_BGR2RGB)))

    def close(self) -> None:
        if self.frames:
            self.frames[0].save(
                self.path,
                save_all=True,
                append_images=self.frames[1:],
                duration=int(1000 / self.fps),
                loop=0,
            )


def open_overlay_video(folder: Path, fps: float) -> OverlayWriter | GifWriter:
    """``folder/overlay.mp4``, or an animated ``folder/overlay.gif`` where OpenCV cannot write
    MP4."""
    try:
        writer = OverlayWriter(folder / "overlay.mp4", fps)
        probe = cv2.VideoWriter(
            str(folder / "overlay.mp4"), cv2.VideoWriter.fourcc(*"mp4v"), fps, (16, 16)
        )
        ok = probe.isOpened()
        probe.release()
        if ok:
            return writer
    except InputFileError:
        pass
    return GifWriter(folder / "overlay.gif", fps)
