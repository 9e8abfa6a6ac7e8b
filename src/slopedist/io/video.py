"""Video files decoded with PyAV, frame times from the presentation timestamps.

Dashcams record at a variable frame rate: the container's nominal rate then puts frame ``k`` at
the wrong time, and the one-second look-back of the ego gradient looks back to the wrong frame.
:class:`PyAVVideoSource` gives every frame its presentation time (``pts × time_base``, seconds
after the first frame's). :func:`open_video` uses it when PyAV (optional extra ``video``) is
installed and falls back to OpenCV's :class:`~slopedist.io.frames.VideoSource` (nominal rate)
otherwise.

Convention: images BGR ``H×W×3`` uint8; frames numbered 0, 1, ... in presentation order;
timestamps float64 seconds. A frame is turned as its display matrix says (a phone's or an
upside-down dashcam's rotation metadata), as players and OpenCV show it and as a detector run
on it saw it. A frame without a pts takes the previous one's plus one nominal period; a pts
that does not increase gives a frame of status ``unreadable`` (as in a log, see
:mod:`slopedist.io.rosbag`).

Damage: a frame the decoder reports damaged (libav logs an error while decoding it, such as
"Error at MB" or "ac-tex damaged", or flags it corrupt) is ``unreadable``, and so is every frame
after it up to the next key frame: they are predicted from the damaged one and show its smear.
The decoder's messages can arrive a few frames ahead of their frame (B-frame reordering), so
the frames from the first message on are marked, and a key frame ends the damage only once
:func:`damage_slack` frames have gone by without a message. A B-frame is shown before the
frame it is predicted from, so B-frames are held until their next reference frame is decoded,
and are ``unreadable`` with it when it is damaged. Frames are decoded on one
thread: PyAV deadlocks when a decoding thread of libav logs (which is why it logs nothing by
default). OpenCV's decoding (:class:`~slopedist.io.frames.VideoSource`: without PyAV, or with
a forced frame rate) reports no damage.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import InputFileError, MissingInputError
from slopedist.io.frames import DEFAULT_FPS, Frame, FrameStatus, VideoSource


def pyav_available() -> bool:
    """True when PyAV can be imported."""
    try:
        import av  # noqa: F401
    except ImportError:
        return False
    return True


class PyAVVideoSource:
    """Frames of the first video stream of a file, timed by their presentation timestamps.

    Args:
        path: the video file.
        timestamps_s: one timestamp per frame, seconds; overrides the presentation times.

    Raises:
        MissingInputError: no such file.
        InputFileError: not a video PyAV can open, or no video stream.
    """

    def __init__(self, path: str | Path, timestamps_s: NDArray[np.float64] | None = None) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise MissingInputError(f"video file not found: {self.path}")
        self.timestamps_s = timestamps_s
        with self._open() as container:
            stream = container.streams.video[0]
            rate = stream.average_rate or stream.guessed_rate
            self.container_fps = float(rate) if rate else DEFAULT_FPS
            self.frame_count = int(stream.frames) or None

    def _open(self) -> Any:
        import av

        try:
            container = av.open(str(self.path))
        except (av.FFmpegError, OSError) as exc:
            raise InputFileError(self.path, f"cannot be opened as a video: {exc}") from None
        if not container.streams.video:
            container.close()
            raise InputFileError(self.path, "has no video stream")
        return container

    def expected_frames(self) -> int | None:
        return self.frame_count

    def frame_size(self) -> tuple[int, int]:
        import av

        with self._open() as container:
            stream = container.streams.video[0]
            _one_thread(stream)
            size = int(stream.codec_context.width), int(stream.codec_context.height)
            try:
                first = next(container.decode(stream))
            except (StopIteration, av.FFmpegError):
                return size
            return _displayed_size(first)

    def __iter__(self) -> Iterator[Frame]:
        return _with_b_frames_held(self._judged())

    def _judged(self) -> Iterator[tuple[Frame, bool, bool]]:
        """Each frame, whether it is a B-frame and whether the decoder reports it damaged."""
        import av

        period = 1.0 / self.container_fps
        t0: Fraction | None = None
        last: float | None = None
        size: tuple[int, int] | None = None
        k = 0
        with self._open() as container, decoder_errors() as errors:
            stream = container.streams.video[0]
            _one_thread(stream)
            frames = container.decode(stream)
            damage = _Damage(stream.codec_context, errors)
            while True:
                name = f"{self.path.name}#{k}"
                try:
                    vf = next(frames)
                except StopIteration:
                    return
                except av.FFmpegError as exc:
                    t = (last or 0.0) + period
                    why = f"decoding stopped: {exc}"
                    yield Frame(k, t, None, FrameStatus.UNREADABLE, name, why), False, False
                    return
                if vf.pts is not None and vf.time_base is not None:
                    pts = vf.pts * vf.time_base
                    t0 = pts if t0 is None else t0
                    t = float(pts - t0)
                else:
                    t = 0.0 if last is None else last + period
                if self.timestamps_s is not None:
                    t = self._given(k)
                damaged = damage.judge(k, vf)
                status, detail, image = self._check(vf, t, last, size, damaged)
                size = size or _displayed_size(vf)
                if status is FrameStatus.OK:
                    last = t
                reported = damaged.startswith(REPORTED_DAMAGE)
                yield Frame(k, t, image, status, name, detail), _is_b_frame(vf), reported
                k += 1

    def _given(self, k: int) -> float:
        assert self.timestamps_s is not None
        if k >= len(self.timestamps_s):
            raise InputFileError(
                self.path, f"{len(self.timestamps_s)} timestamps given, but there is a frame {k}"
            )
        return float(self.timestamps_s[k])

    @staticmethod
    def _check(
        vf: Any, t: float, last: float | None, size: tuple[int, int] | None, damaged: str
    ) -> tuple[FrameStatus, str, NDArray[np.uint8] | None]:
        this = _displayed_size(vf)
        if damaged:
            return FrameStatus.UNREADABLE, damaged, None
        if last is not None and not t > last:
            why = f"presentation time {t:.6f} s does not increase (the frame before: {last:.6f} s)"
            return FrameStatus.UNREADABLE, why, None
        if size is not None and this != size:
            why = f"image is {this[0]}×{this[1]} px, the first frame was {size[0]}×{size[1]} px"
            return FrameStatus.SIZE_CHANGED, why, None
        image = np.asarray(vf.to_ndarray(format="bgr24"), dtype=np.uint8)
        turns = _quarter_turns(vf)
        if turns:
            image = np.ascontiguousarray(np.rot90(image, turns))
        return FrameStatus.OK, "", image


DAMAGE_SLACK_FRAMES = 1
"""Frames beyond the decoder's threads and reordering delay that must go by without a damage
message before a key frame ends the damage (see :func:`damage_slack`)."""

REORDER_FRAMES = 4
"""Frames a decoder with B-frames holds back before showing one, at most, in the streams of
common encoders (x264's B-pyramid: 2; H.264 allows up to 16, which no dashcam writes)."""


AV_PICTURE_TYPE_B = 3
"""libav's picture type of a B-frame (``AV_PICTURE_TYPE_B``)."""

REPORTED_DAMAGE = "the decoder reports damage"
"""How the detail of a frame the decoder itself reports damaged begins."""


def _is_b_frame(vf: Any) -> bool:
    """True when the decoded frame ``vf`` is a B-frame (predicted from a later frame too)."""
    kind = getattr(vf, "pict_type", None)  # PyAV ≥ 18: an int; before: an enum item
    return kind == AV_PICTURE_TYPE_B or str(getattr(kind, "name", "")) == "B"


def _with_b_frames_held(
    judged: Iterator[tuple[Frame, bool, bool]],
) -> Iterator[Frame]:
    """The frames of ``judged`` in order, each B-frame held until the next other frame, its
    later reference: when the decoder reports that one damaged, the held B-frames, predicted
    from it, are ``unreadable`` too."""
    held: list[Frame] = []
    for frame, is_b, reported in judged:
        if is_b:
            held.append(frame)
            continue
        for b in held:
            yield _predicted_from(b, frame) if reported and b.status is FrameStatus.OK else b
        held = []
        yield frame
    yield from held


def _predicted_from(b: Frame, reference: Frame) -> Frame:
    """The B-frame ``b`` marked ``unreadable``: it is predicted from the damaged ``reference``."""
    why = f"predicted from damaged frame {reference.index} ({reference.detail})"
    return dataclasses.replace(b, image=None, status=FrameStatus.UNREADABLE, detail=why)


def _one_thread(stream: Any) -> None:
    """Decode ``stream`` on the calling thread: a decoding thread of libav that logs while
    Python waits for it deadlocks PyAV (hence PyAV logs nothing by default), and the damage
    check needs the decoder's messages (:func:`decoder_errors`)."""
    stream.thread_type = "NONE"
    stream.codec_context.thread_count = 1


def damage_slack(codec_context: Any) -> int:
    """How many frames the decoder's messages may arrive ahead of their frame: one per
    decoding thread beyond the first (none: :func:`_one_thread`), the reordering delay of a
    stream with B-frames, and :data:`DAMAGE_SLACK_FRAMES`."""
    threads = int(getattr(codec_context, "thread_count", 1) or 1)
    reorder = REORDER_FRAMES if getattr(codec_context, "has_b_frames", False) else 0
    return threads - 1 + reorder + DAMAGE_SLACK_FRAMES


class _Damage:
    """Which frames of a stream the decoder's error messages (``errors``, shared with
    :func:`decoder_errors`) mark damaged (see the module docstring)."""

    def __init__(self, codec_context: Any, errors: list[tuple[int, str, str]]) -> None:
        self.codec = str(getattr(codec_context, "name", ""))
        self.slack = damage_slack(codec_context)
        self.errors = errors
        self.seen = len(errors)
        self.why = ""
        self.since = -1
        self.quiet = 0

    def judge(self, k: int, vf: Any) -> str:
        """Why frame ``k`` (decoded as ``vf``) is damaged, or "" when it is not."""
        new = [m for _, name, m in self.errors[self.seen :] if name == self.codec]
        self.seen = len(self.errors)
        if new or getattr(vf, "is_corrupt", False):
            said = new[0].strip() if new else "the frame is flagged corrupt"
            if not self.why:
                self.why, self.since = said, k
            self.quiet = 0
            return f"{REPORTED_DAMAGE}: {said}"
        if not self.why:
            return ""
        self.quiet += 1
        if vf.key_frame and self.quiet > self.slack:
            self.why, self.since, self.quiet = "", -1, 0
            return ""
        return f"predicted from damaged frames (from frame {self.since} on: {self.why})"


class _SharedCapture:
    """One capture of libav's messages for every decoding that overlaps in time (PyAV routes
    them to a single capture at a time)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.users = 0
        self.capture: Any = None
        self.level: Any = None

    def enter(self) -> list[tuple[int, str, str]]:
        import av.logging

        with self.lock:
            if self.users == 0:
                self.level = av.logging.get_level()
                av.logging.set_level(av.logging.ERROR)
                self.capture = av.logging.Capture(local=False)
                self.capture.__enter__()
            self.users += 1
            logs: list[tuple[int, str, str]] = self.capture.logs
            return logs

    def exit(self) -> None:
        import av.logging

        with self.lock:
            self.users -= 1
            if self.users == 0:
                self.capture.__exit__(None, None, None)
                av.logging.set_level(self.level)
                self.capture = None


_SHARED = _SharedCapture()


@contextmanager
def decoder_errors() -> Iterator[list[tuple[int, str, str]]]:
    """The messages ``(level, source, text)`` of level error and worse that libav logs while
    the block runs, from any thread (PyAV logs nothing by default); blocks that overlap (a
    decoding thread and the main one) share the list, each reading on from where it began."""
    errors = _SHARED.enter()
    try:
        yield errors
    finally:
        _SHARED.exit()


def _quarter_turns(vf: Any) -> int:
    """Counter-clockwise quarter turns (0..3) that show frame ``vf`` upright: its display
    matrix's rotation (PyAV's ``VideoFrame.rotation``, degrees; 0 where PyAV lacks it)."""
    return round(float(getattr(vf, "rotation", 0) or 0) / 90.0) % 4


def _displayed_size(vf: Any) -> tuple[int, int]:
    """``(width, height)`` of frame ``vf`` as shown, after its rotation."""
    w, h = int(vf.width), int(vf.height)
    return (h, w) if _quarter_turns(vf) % 2 else (w, h)


def open_video(
    path: str | Path,
    fps: float | None = None,
    timestamps_s: NDArray[np.float64] | None = None,
    timestamps_name: str = "timestamps",
) -> PyAVVideoSource | VideoSource:
    """A video file as frames: presentation times with PyAV; without PyAV, or when a frame
    rate is forced with ``fps``, OpenCV with ``index / fps`` (see
    :class:`~slopedist.io.frames.VideoSource`)."""
    if fps is None and pyav_available():
        return PyAVVideoSource(path, timestamps_s)
    return VideoSource(path, fps, timestamps_s, timestamps_name)
