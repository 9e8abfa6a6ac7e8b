"""Frames decoded ahead, and overlays drawn and encoded behind, in background threads.

Decoding a frame (PNG inflate, H.264) runs in OpenCV without Python's global lock, so a thread
that decodes the next frames while the odometry works on the current one lets a stream use a
second core when one is free; with one core, the work per frame is the same as without it (the
frames are handed over through a bounded queue, a few microseconds each).

The frames come out in order and unchanged; an error of the source is raised in the consumer at
the frame where it happened; a consumer that stops early (``break``, an exception) stops the
thread and waits for it.
"""

from __future__ import annotations

import contextlib
import os
import queue
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import ConfigurationError
from slopedist.io.frames import Frame, FrameSource

DEFAULT_AHEAD = 4
"""Frames decoded ahead by default (a 1920×1080 BGR frame is 6 MB)."""
_POLL_S = 0.05
"""How often a blocked producer checks whether the consumer has gone, seconds."""


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one)."""
    if hasattr(os, "sched_getaffinity"):
        return max(len(os.sched_getaffinity(0)), 1)
    return max(os.cpu_count() or 1, 1)


def loop_threads(decode_ahead: int, cores: int | None = None) -> int:
    """OpenCV threads for a frame loop: with frames decoded ahead (and an overlay encoded
    behind) in a thread that keeps one core busy, the loop's OpenCV calls get the other
    cores (``cores − 1``, at least 1; on two cores, one thread: OpenCV's own parallel loops
    would only take turns with the decoding thread, at a higher processor cost per frame);
    without, every core (``cores``). ``cores``: default :func:`usable_cores`."""
    cores = usable_cores() if cores is None else cores
    return max(cores - 1, 1) if decode_ahead else max(cores, 1)


@contextlib.contextmanager
def opencv_threads(n: int) -> Iterator[None]:
    """OpenCV on ``n`` threads inside the block, its earlier setting restored after (the
    setting is the process's: blocks must not overlap in different threads)."""
    before = cv2.getNumThreads()
    cv2.setNumThreads(n)
    try:
        yield
    finally:
        cv2.setNumThreads(before)


@dataclass(frozen=True)
class _Failure:
    """An exception of the source, handed to the consumer."""

    error: BaseException


_END = object()
"""Queue item after the last frame."""


class PrefetchedFrames:
    """``source`` with up to ``ahead`` frames decoded ahead in a background thread.

    Has the source's ``path``, ``expected_frames()`` and ``frame_size()``, so it is a
    :class:`~slopedist.io.frames.FrameSource` itself. Each iteration starts its own thread.
    """

    def __init__(self, source: FrameSource, ahead: int = DEFAULT_AHEAD) -> None:
        if ahead < 1:
            raise ConfigurationError(f"frames decoded ahead must be ≥ 1, got {ahead}")
        self.source = source
        self.ahead = ahead
        self.path: Path = source.path

    def expected_frames(self) -> int | None:
        return self.source.expected_frames()

    def frame_size(self) -> tuple[int, int]:
        return self.source.frame_size()

    def __iter__(self) -> Iterator[Frame]:
        items: queue.Queue[object] = queue.Queue(maxsize=self.ahead)
        stop = threading.Event()
        worker = threading.Thread(
            target=_produce, args=(self.source, items, stop), name="slopedist-prefetch", daemon=True
        )
        worker.start()
        try:
            while True:
                item = items.get()
                if item is _END:
                    return
                if isinstance(item, _Failure):
                    raise item.error
                assert isinstance(item, Frame)
                yield item
        finally:
            stop.set()
            while worker.is_alive():  # unblock a producer waiting on a full queue
                try:
                    items.get_nowait()
                except queue.Empty:
                    worker.join(_POLL_S)


def _produce(source: FrameSource, items: queue.Queue[object], stop: threading.Event) -> None:
    """Decode the frames of ``source`` into ``items`` until the end, an error, or ``stop``."""
    try:
        for frame in source:
            if not _put(items, frame, stop):
                return
    except BaseException as exc:  # handed to the consumer, raised there
        _put(items, _Failure(exc), stop)
        return
    _put(items, _END, stop)


def _put(items: queue.Queue[object], item: object, stop: threading.Event) -> bool:
    """Put ``item`` once there is room; False when the consumer has stopped first."""
    while not stop.is_set():
        try:
            items.put(item, timeout=_POLL_S)
            return True
        except queue.Full:
            continue
    return False


class OverlaySink(Protocol):
    """What :class:`BackgroundOverlay` forwards to (e.g. :class:`~slopedist.io.overlay.
    OverlayWriter`; ``timestamp_s``: the frame's time, seconds)."""

    @property
    def target(self) -> Path: ...

    def write(
        self, index: int, image: NDArray[np.uint8], timestamp_s: float | None = None
    ) -> None: ...

    def write_placeholder(
        self, index: int, text: str, timestamp_s: float | None = None
    ) -> None: ...

    def close(self) -> None: ...


class BackgroundOverlay:
    """An overlay writer whose encoding (and, with :meth:`write_drawn`, drawing) runs in a
    background thread, up to ``ahead`` frames behind the caller (the images and data handed
    over must not be changed afterwards).

    Calls reach ``sink`` in order; an error of the sink or of a drawing is raised by the next
    call (or by :meth:`close`), after which nothing more is written.
    """

    def __init__(self, sink: OverlaySink, ahead: int = DEFAULT_AHEAD) -> None:
        if ahead < 1:
            raise ConfigurationError(f"overlay frames queued must be ≥ 1, got {ahead}")
        self.sink = sink
        self._calls: queue.Queue[tuple[Callable[..., None], tuple[object, ...]] | None] = (
            queue.Queue(ahead)
        )
        self._error: BaseException | None = None
        self._worker = threading.Thread(target=self._drain, name="slopedist-overlay", daemon=True)
        self._worker.start()

    @property
    def target(self) -> Path:
        """The sink's output path."""
        return self.sink.target

    def write(self, index: int, image: NDArray[np.uint8], timestamp_s: float | None = None) -> None:
        self._submit(self.sink.write, (index, image, timestamp_s))

    def write_drawn(
        self,
        index: int,
        draw: Callable[[], NDArray[np.uint8]],
        timestamp_s: float | None = None,
    ) -> None:
        """Write the image ``draw()`` returns, drawn in the background thread (``draw`` must
        only read data that the caller no longer changes): the drawing leaves the caller's
        thread, as the encoding does."""
        self._submit(self._draw_and_write, (index, draw, timestamp_s))

    def write_placeholder(self, index: int, text: str, timestamp_s: float | None = None) -> None:
        self._submit(self.sink.write_placeholder, (index, text, timestamp_s))

    def close(self) -> None:
        """Write everything queued, close the sink, and raise the sink's error if any."""
        if self._worker.is_alive():
            self._calls.put(None)
            self._worker.join()
        self._raise()

    def _submit(self, call: Callable[..., None], args: tuple[object, ...]) -> None:
        self._raise()
        self._calls.put((call, args))

    def _draw_and_write(
        self, index: int, draw: Callable[[], NDArray[np.uint8]], timestamp_s: float | None
    ) -> None:
        self.sink.write(index, draw(), timestamp_s)

    def _raise(self) -> None:
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def _drain(self) -> None:
        failed = False
        while True:
            call = self._calls.get()
            if call is None:
                break
            if failed:
                continue  # keep taking calls so that the caller never blocks
            try:
                call[0](*call[1])
            except BaseException as exc:  # raised in the caller's thread
                self._error, failed = exc, True
        try:
            self.sink.close()
        except BaseException as exc:
            self._error = self._error or exc
