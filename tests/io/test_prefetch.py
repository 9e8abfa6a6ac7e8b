"""Frames decoded ahead in a thread: same frames in the same order, errors raised where they
happen, a bounded queue, and no thread left behind."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from slopedist.core.errors import ConfigurationError, InputFileError
from slopedist.io.frames import Frame, FrameStatus, open_frames
from slopedist.io.overlay import OverlayWriter
from slopedist.io.prefetch import (
    BackgroundOverlay,
    PrefetchedFrames,
    loop_threads,
    opencv_threads,
    usable_cores,
)


class ListSource:
    """``n`` tiny frames; raises ``error`` instead of frame ``fail_at``; counts the frames made."""

    def __init__(self, n: int, fail_at: int | None = None) -> None:
        self.path = Path("list")
        self.n, self.fail_at = n, fail_at
        self.made = 0
        self.closed = False

    def expected_frames(self) -> int | None:
        return self.n

    def frame_size(self) -> tuple[int, int]:
        return (4, 3)

    def __iter__(self) -> Iterator[Frame]:
        try:
            for k in range(self.n):
                if k == self.fail_at:
                    raise InputFileError(self.path, f"frame {k} is broken")
                self.made += 1
                image = np.full((3, 4, 3), k % 256, np.uint8)
                yield Frame(k, 0.1 * k, image, FrameStatus.OK, f"f{k}")
        finally:
            self.closed = True


def _prefetch_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == "slopedist-prefetch"]


def test_same_frames_in_order_and_source_properties() -> None:
    source = ListSource(25)
    wrapped = PrefetchedFrames(source, ahead=3)
    frames = list(wrapped)
    assert [f.index for f in frames] == list(range(25))
    assert all(int(f.image[0, 0, 0]) == f.index for f in frames if f.image is not None)
    assert wrapped.path == source.path and wrapped.expected_frames() == 25
    assert wrapped.frame_size() == (4, 3)
    assert not _prefetch_threads()


def test_error_is_raised_in_the_consumer_after_the_frames_before_it() -> None:
    seen = []
    with pytest.raises(InputFileError, match="frame 7 is broken"):
        for frame in PrefetchedFrames(ListSource(20, fail_at=7)):
            seen.append(frame.index)
    assert seen == list(range(7))
    assert not _prefetch_threads()


def test_queue_is_bounded_and_early_stop_ends_the_thread() -> None:
    source = ListSource(1000)
    frames = iter(PrefetchedFrames(source, ahead=2))
    assert next(frames).index == 0
    time.sleep(0.3)  # the producer fills the queue and waits
    # one handed out, two queued, one waiting to be put
    assert source.made <= 4
    frames.close()  # what a `break` in a for loop does
    assert not _prefetch_threads()
    assert source.closed and source.made <= 5


def test_ahead_must_be_positive() -> None:
    with pytest.raises(ConfigurationError):
        PrefetchedFrames(ListSource(1), ahead=0)


def test_image_folder_through_the_thread_equals_the_folder(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    for k in (0, 1, 3):  # frame 2 missing
        cv2.imwrite(str(tmp_path / f"{k:06d}.png"), rng.integers(0, 255, (8, 10, 3), np.uint8))
    direct = list(open_frames(tmp_path))
    ahead = list(PrefetchedFrames(open_frames(tmp_path)))
    assert [(f.index, f.status, f.source) for f in ahead] == [
        (f.index, f.status, f.source) for f in direct
    ]
    assert ahead[2].status is FrameStatus.MISSING
    for a, b in zip(ahead, direct):
        assert (a.image is None and b.image is None) or np.array_equal(a.image, b.image)


class RecordingSink:
    """Records the calls; fails at frame ``fail_at``; sleeps a little per frame."""

    def __init__(self, fail_at: int | None = None) -> None:
        self.target = Path("recorded.mp4")
        self.calls: list[tuple[str, int]] = []
        self.fail_at = fail_at
        self.closed = False

    def write(self, index: int, image: np.ndarray, timestamp_s: float | None = None) -> None:
        time.sleep(0.002)
        if index == self.fail_at:
            raise OSError(f"disk full at frame {index}")
        self.calls.append(("write", index))

    def write_placeholder(self, index: int, text: str, timestamp_s: float | None = None) -> None:
        self.calls.append(("placeholder", index))

    def close(self) -> None:
        self.closed = True


def test_background_overlay_keeps_the_order_and_closes() -> None:
    sink = RecordingSink()
    writer = BackgroundOverlay(sink, ahead=2)
    for k in range(10):
        if k == 4:
            writer.write_placeholder(k, "missing")
        else:
            writer.write(k, np.zeros((2, 2, 3), np.uint8))
    writer.close()
    assert writer.target == sink.target
    assert sink.calls == [("placeholder" if k == 4 else "write", k) for k in range(10)]
    assert sink.closed
    assert not [t for t in threading.enumerate() if t.name == "slopedist-overlay"]


def test_background_overlay_error_reaches_the_caller() -> None:
    sink = RecordingSink(fail_at=3)
    writer = BackgroundOverlay(sink, ahead=2)
    with pytest.raises(OSError, match="disk full at frame 3"):
        for k in range(50):
            writer.write(k, np.zeros((2, 2, 3), np.uint8))
        writer.close()
    writer.close()  # after the error: closes quietly, nothing more written
    assert sink.calls == [("write", k) for k in range(3)] and sink.closed


def test_background_overlay_draws_in_its_thread_in_order() -> None:
    """``write_drawn``: the images are drawn in the overlay thread, written in call order
    among plain writes; an error of a drawing reaches the caller like a sink error."""
    sink = RecordingSink()
    writer = BackgroundOverlay(sink, ahead=2)
    drawn_in: set[str] = set()

    def draw() -> np.ndarray:
        drawn_in.add(threading.current_thread().name)
        return np.zeros((2, 2, 3), np.uint8)

    for k in range(8):
        if k % 3:
            writer.write_drawn(k, draw)
        else:
            writer.write(k, np.zeros((2, 2, 3), np.uint8))
    writer.close()
    assert sink.calls == [("write", k) for k in range(8)] and sink.closed
    assert drawn_in == {"slopedist-overlay"}

    def broken() -> np.ndarray:
        raise ValueError("no pixels to draw on")

    failing = BackgroundOverlay(RecordingSink(), ahead=1)
    with pytest.raises(ValueError, match="no pixels"):
        failing.write_drawn(0, broken)
        failing.close()


def test_background_overlay_video_equals_the_direct_one(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    images = [rng.integers(0, 255, (48, 64, 3), np.uint8) for _ in range(6)]
    direct = OverlayWriter(tmp_path / "a.mp4", 10.0)
    behind = BackgroundOverlay(OverlayWriter(tmp_path / "b.mp4", 10.0))
    for k, image in enumerate(images):
        direct.write(k, image, 0.1 * k)
        behind.write(k, image, 0.1 * k)
    direct.close()
    behind.close()
    decoded = [list(open_frames(tmp_path / name)) for name in ("a.mp4", "b.mp4")]
    assert len(decoded[0]) == len(images) == len(decoded[1])
    for a, b in zip(*decoded):
        assert a.image is not None and b.image is not None and np.array_equal(a.image, b.image)


def test_opencv_threads_sets_and_gives_back_the_threads() -> None:
    before = cv2.getNumThreads()
    cv2.setNumThreads(3)
    try:
        with opencv_threads(1):
            assert cv2.getNumThreads() == 1
        assert cv2.getNumThreads() == 3
        with pytest.raises(RuntimeError), opencv_threads(2):
            raise RuntimeError
        assert cv2.getNumThreads() == 3
    finally:
        cv2.setNumThreads(before)


def test_the_loop_leaves_a_core_to_the_decoding_thread() -> None:
    """With frames decoded ahead, the loop's OpenCV gets the other cores (at least one);
    without, every core."""
    assert [loop_threads(4, cores) for cores in (1, 2, 8)] == [1, 1, 7]
    assert [loop_threads(0, cores) for cores in (1, 2, 8)] == [1, 2, 8]
    assert loop_threads(0) == usable_cores() >= 1
