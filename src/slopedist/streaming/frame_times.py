"""Frame steps longer than the look-back of the ego gradient θ (eq. 2–4).

The look-back frame of a frame is the latest frame at least one look-back (``--lookback``,
1 s by default) older (:class:`~slopedist.streaming.step.EgoGradientTracker`,
:func:`~slopedist.odometry.base.lookback_indices`). Frames further apart than that (a timelapse,
``--timestamps`` or ``--frame-period`` of seconds) look back one frame step instead: θ is the
pitch change over that longer interval, not over the look-back, and its rows keep their states.
:func:`long_step_warning` says so once.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from slopedist.io.frames import Frame, FrameSource


def long_step_warning(steps_s: Iterable[float], lookback_s: float) -> str | None:
    """The warning for frame steps (seconds) whose median exceeds ``lookback_s``, else None."""
    steps = np.fromiter(steps_s, dtype=float)
    if not steps.size:
        return None
    median = float(np.median(steps))
    if median <= lookback_s:
        return None
    return (
        f"warning: the frames are a median {median:.3g} s apart, longer than the {lookback_s:g} s "
        "look-back of the ego gradient (--lookback): each frame's θ looks back one frame step, "
        "so it is the pitch change over that longer interval"
    )


class SteppedFrames:
    """A frame source that keeps the time steps between the frames it yields (seconds)."""

    def __init__(self, frames: FrameSource) -> None:
        self.frames = frames
        self.path: Path = frames.path
        self.steps_s = array("d")
        self._last_s: float | None = None  # the latest frame time seen

    def __iter__(self) -> Iterator[Frame]:
        for frame in self.frames:
            t = float(frame.timestamp_s)
            last = self._last_s
            if math.isfinite(t) and (last is None or t > last):  # else the runner reports it
                if last is not None:
                    self.steps_s.append(t - last)
                self._last_s = t
            yield frame

    def expected_frames(self) -> int | None:
        return self.frames.expected_frames()

    def frame_size(self) -> tuple[int, int]:
        return self.frames.frame_size()
