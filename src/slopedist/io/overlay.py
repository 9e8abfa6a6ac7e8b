"""Writing annotated frames: a folder of PNG files or an MP4 video.

MP4 videos are H.264 (``yuv420p``, the profile every browser plays) written with the FFmpeg that
PyAV's wheels bundle (a core dependency; its ``libx264``, else ``libopenh264``) as a *fragmented*
MP4 (``frag_keyframe+empty_moov+default_base_moof``) with a key
frame every second and no encoder look-ahead (``tune=zerolatency``): every finished fragment is
on disk, so a run killed part-way leaves a file that plays up to its last second. Frame times are
the frames' own timestamps (variable frame rate kept), in milliseconds. Without PyAV or an
H.264 encoder in it the video falls back to OpenCV's MPEG-4 Part 2 (``mp4v``; plays in desktop
players, not in browsers), and :func:`video_fallback_note` says so (``run`` and the demo print it
and write it to ``run.json`` / ``results.json``).

Where neither can write MP4, :func:`open_overlay_video` falls back to an animated GIF (needs
Pillow).

Convention: images are BGR ``H×W×3`` uint8; odd widths or heights are padded with one black
column / row (``yuv420p`` needs even sizes).
"""

from __future__ import annotations

import functools
import importlib.util
from fractions import Fraction
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import ConfigurationError, InputFileError
from slopedist.core.paths import utf8_name
from slopedist.io.outputs import write_image

MP4_TIME_BASE = Fraction(1, 1000)
"""Time unit of the presentation timestamps of written videos (milliseconds)."""

H264_OPTIONS = {"preset": "ultrafast", "tune": "zerolatency", "crf": "26"}
"""libx264 settings made for real time: the fastest preset (no B-frames, CAVLC; 3.4 ms per
1242×375 frame and 13 ms per 1920×1080 frame on one core, against 9.5 and 41 ms with
``veryfast``), no look-ahead (frames leave the encoder at once), and CRF 26 (files 20–40 %
larger than ``veryfast`` at CRF 23 gave, labels and boxes as legible; browsers play it like any
other ``yuv420p`` H.264)."""

H264_ENCODERS = ("libx264", "libopenh264")
"""FFmpeg's H.264 encoders, in order of preference (PyAV's wheels carry one of them)."""

ENCODER_OPTIONS = {"libx264": H264_OPTIONS, "libopenh264": {}}
"""Encoder settings of each of :data:`H264_ENCODERS` (OpenH264 has no presets: its defaults)."""

MP4V_CODEC = "mp4v"
"""The FourCC of OpenCV's fallback (MPEG-4 Part 2)."""


@functools.cache
def h264_encoder() -> str | None:
    """The first of :data:`H264_ENCODERS` the installed PyAV can encode with, or None (no
    PyAV, or an FFmpeg built without either)."""
    try:
        import av
    except ImportError:
        return None
    for name in H264_ENCODERS:
        try:
            av.codec.Codec(name, "w")
        except Exception:  # PyAV raises its own error types for an unknown codec
            continue
        return name
    return None


def video_codec() -> str:
    """What an MP4 overlay is encoded with here: ``h264 (libx264)`` or another of
    :data:`H264_ENCODERS`, or :data:`MP4V_CODEC` (OpenCV's fallback)."""
    encoder = h264_encoder()
    return f"h264 ({encoder})" if encoder else MP4V_CODEC


def video_fallback_note() -> str | None:
    """Why an MP4 overlay would not be H.264 here, and what to do (None: it is)."""
    if h264_encoder() is not None:
        return None
    why = (
        "PyAV is not installed"
        if importlib.util.find_spec("av") is None
        else "the installed PyAV's FFmpeg has no H.264 encoder (" + ", ".join(H264_ENCODERS) + ")"
    )
    return (
        f"{why}: the MP4 overlay is MPEG-4 Part 2 (mp4v), which desktop players play and "
        "browsers do not; pip install --upgrade av (its wheels carry H.264) for H.264"
    )


FRAGMENTED_MP4 = {"movflags": "frag_keyframe+empty_moov+default_base_moof", "flush_packets": "1"}
"""MP4 muxer flags: a fragment per key frame, the header first (playable while written), each
packet flushed to the file at once."""


def even_size(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """``image`` padded with a black row / column where its height / width is odd."""
    h, w = image.shape[:2]
    if h % 2 == 0 and w % 2 == 0:
        return image
    return np.asarray(cv2.copyMakeBorder(image, 0, h % 2, 0, w % 2, cv2.BORDER_CONSTANT, value=0))


class H264Writer:
    """H.264 fragmented MP4 via PyAV (see the module docstring).

    Args:
        path: the ``.mp4`` file (overwritten).
        size: ``(width, height)`` of the frames, pixels (padded to even).
        fps: nominal frame rate (key-frame interval, and the times of frames written without
            one).

    Raises:
        ImportError: PyAV is missing or has no H.264 encoder (:func:`h264_encoder`; callers
            choose the fallback).
    """

    def __init__(self, path: str | Path, size: tuple[int, int], fps: float) -> None:
        import av

        encoder = h264_encoder()
        if encoder is None:
            raise ImportError("no H.264 encoder in PyAV")
        self.path = Path(path)
        self.fps = fps
        width, height = size[0] + size[0] % 2, size[1] + size[1] % 2
        self.size = (width, height)
        self._container: Any = av.open(
            str(self.path), "w", format="mp4", container_options=FRAGMENTED_MP4
        )
        rate = Fraction(fps).limit_denominator(1001)
        options = dict(ENCODER_OPTIONS[encoder])
        stream: Any = self._container.add_stream(encoder, rate=rate, options=options)
        stream.width, stream.height = width, height
        stream.pix_fmt = "yuv420p"
        stream.time_base = MP4_TIME_BASE
        stream.codec_context.time_base = MP4_TIME_BASE
        stream.codec_context.gop_size = max(round(fps), 1)
        self._stream = stream
        self._last_pts = -1
        self._offset_s = 0.0

    def write(self, image: NDArray[np.uint8], timestamp_s: float) -> None:
        """Encode one BGR frame shown at ``timestamp_s`` seconds (times must increase; a time
        that does not is moved to one millisecond after the previous frame). The first frame
        is shown at 0 and the others keep their spacing: a video's times cannot be negative (a
        timestamps file from -1 s), and one of Unix times would open on decades of nothing."""
        import av

        if self._last_pts < 0:  # the first frame
            self._offset_s = -timestamp_s
        timestamp_s += self._offset_s

        # OpenCV's BT.601 conversion: decoders give back the colours within 2 levels (swscale's
        # default conversion is 3-4 levels off)
        i420 = cv2.cvtColor(np.ascontiguousarray(even_size(image)), cv2.COLOR_BGR2YUV_I420)
        frame = av.VideoFrame.from_ndarray(np.asarray(i420, dtype=np.uint8), format="yuv420p")
        pts = max(round(timestamp_s / float(MP4_TIME_BASE)), self._last_pts + 1)
        frame.pts, frame.time_base = pts, MP4_TIME_BASE
        self._last_pts = pts
        for packet in self._stream.encode(frame):
            self._container.mux(packet)

    def close(self) -> None:
        """Flush the encoder and finish the file."""
        if self._container is None:
            return
        for packet in self._stream.encode(None):
            self._container.mux(packet)
        self._container.close()
        self._container = None


class _OpenCVWriter:
    """MPEG-4 Part 2 via ``cv2.VideoWriter`` (fallback without PyAV; frame times are lost)."""

    def __init__(self, path: Path, size: tuple[int, int], fps: float) -> None:
        self.path = path
        self.size = size
        with utf8_name(path) as name:  # (OpenCV keeps the file it opened)
            self._video = cv2.VideoWriter(name, cv2.VideoWriter.fourcc(*"mp4v"), fps, size)
        if not self._video.isOpened():
            raise InputFileError(path, "OpenCV cannot write an MP4 (mp4v) video here")

    def write(self, image: NDArray[np.uint8], timestamp_s: float) -> None:
        self._video.write(image)

    def close(self) -> None:
        self._video.release()


def open_video_writer(
    path: str | Path, size: tuple[int, int], fps: float
) -> H264Writer | _OpenCVWriter:
    """H.264 with PyAV when it has an H.264 encoder, else OpenCV's mp4v (see the module
    docstring and :func:`video_fallback_note`)."""
    path = Path(path)
    try:
        return H264Writer(path, size, fps)
    except ImportError:
        return _OpenCVWriter(path, size, fps)


class OverlayWriter:
    """Writes one annotated image per frame, to PNG files or to an MP4 file.

    ``target`` ending in ``.mp4`` writes a video (:func:`open_video_writer`; size of the first
    frame, frames of another size are resized to it); anything else is a folder that receives
    ``<frame index, 6 digits>.png``. Frames without pixels are written to the video as a grey
    placeholder (so its timeline stays right) and skipped in a PNG folder.

    Args:
        target: folder or ``.mp4`` path.
        fps: nominal frame rate; frames written without a timestamp are shown at
            ``index / fps`` seconds.
    """

    def __init__(self, target: str | Path, fps: float = 10.0) -> None:
        self.target = Path(target)
        self.fps = fps
        self.is_video = self.target.suffix.lower() == ".mp4"
        self.codec = video_codec() if self.is_video else "png"
        """What the frames are written as: :func:`video_codec` for a video, ``png``."""
        self._video: H264Writer | _OpenCVWriter | None = None
        self._size: tuple[int, int] | None = None
        self.written = 0
        if self.is_video:
            if not fps > 0:
                raise ConfigurationError(f"overlay video needs a frame rate > 0, got {fps}")
            self.target.parent.mkdir(parents=True, exist_ok=True)
        else:
            self.target.mkdir(parents=True, exist_ok=True)

    def write(self, index: int, image: NDArray[np.uint8], timestamp_s: float | None = None) -> None:
        """Write the annotated image of frame ``index`` (shown at ``timestamp_s`` seconds, or
        ``index / fps`` when None)."""
        if not self.is_video:
            write_image(self.target / f"{index:06d}.png", image)  # whole, or not at all
            self.written += 1
            return
        if self._video is None:
            self._size = (int(image.shape[1]), int(image.shape[0]))
            self._video = open_video_writer(self.target, self._size, self.fps)
        assert self._size is not None
        if (image.shape[1], image.shape[0]) != self._size:
            image = np.asarray(cv2.resize(image, self._size))
        self._video.write(image, index / self.fps if timestamp_s is None else timestamp_s)
        self.written += 1

    def write_placeholder(self, index: int, text: str, timestamp_s: float | None = None) -> None:
        """Mark a frame without pixels (video only: a grey frame with ``text``)."""
        if not self.is_video or self._size is None:
            return
        image = np.full((self._size[1], self._size[0], 3), 64, np.uint8)
        cv2.putText(
            image, text, (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 1, cv2.LINE_AA
        )
        self.write(index, image, timestamp_s)

    def close(self) -> None:
        """Finish the video file (no-op for PNG folders)."""
        if self._video is not None:
            self._video.close()
            self._video = None


class GifWriter:
    """Animated GIF fallback for the overlay (half resolution, nominal frame rate)."""

    def __init__(self, path: Path, fps: float) -> None:
        self.path = path
        self.fps = fps
        self.frames: list[Any] = []

    def write(self, index: int, image: NDArray[np.uint8], timestamp_s: float | None = None) -> None:
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
    """``folder/overlay.mp4`` (H.264 with PyAV, else OpenCV's mp4v: :func:`video_fallback_note`),
    or an animated ``folder/overlay.gif`` where neither can write MP4."""
    try:
        writer = OverlayWriter(folder / "overlay.mp4", fps)
        if h264_encoder() is not None:
            return writer
        with utf8_name(folder / "overlay.mp4") as name:
            probe = cv2.VideoWriter(name, cv2.VideoWriter.fourcc(*"mp4v"), fps, (16, 16))
        ok = probe.isOpened()
        probe.release()
        if ok:
            return writer
    except InputFileError:
        pass
    return GifWriter(folder / "overlay.gif", fps)
