"""The depth-source interface: one dense depth map (metres) per frame, timed."""

from __future__ import annotations

import time

import numpy as np
from numpy.typing import NDArray

MIN_PLAUSIBLE_DEPTH_M = 0.1
"""Smaller depths (metres) are not a measurement of anything in front of a car: no value."""
MAX_PLAUSIBLE_DEPTH_M = 1000.0
"""Larger depths (metres) are not a measurement of a road scene: no value."""


def plausible_depth(depth_m: NDArray[np.floating]) -> NDArray[np.bool_]:
    """Mask of depths (metres) that can be a measurement: finite and within
    [:data:`MIN_PLAUSIBLE_DEPTH_M`, :data:`MAX_PLAUSIBLE_DEPTH_M`]."""
    d = np.asarray(depth_m)
    with np.errstate(invalid="ignore"):
        return np.isfinite(d) & (d >= MIN_PLAUSIBLE_DEPTH_M) & (d <= MAX_PLAUSIBLE_DEPTH_M)


class DepthSource:
    """Gives the depth map of a frame; accumulates the wall time spent doing so.

    Subclasses implement :meth:`_depth`. :attr:`seconds` is the total time (seconds) spent in
    :meth:`depth` so far, i.e. file reading for file sources and inference for models (the
    "depth inference" column of the timing table); :attr:`calls` counts the maps produced.
    """

    kind: str = "depth"
    """Short name of what the time measures (``"file read"``, ``"onnx inference"``)."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self.calls = 0

    def depth(
        self, frame_index: int, image: NDArray[np.uint8] | None = None
    ) -> NDArray[np.float32] | None:
        """Depth map of frame ``frame_index`` (float32 ``H×W`` metres, NaN = no value), or None
        when the source has no map for that frame and was told to accept that.

        Args:
            frame_index: 0-based frame number (file sources find the file by it).
            image: the frame's BGR ``H×W×3`` uint8 pixels (models need them; files ignore them).
        """
        t0 = time.perf_counter()
        try:
            return self._depth(frame_index, image)
        finally:
            self.seconds += time.perf_counter() - t0
            self.calls += 1

    def _depth(
        self, frame_index: int, image: NDArray[np.uint8] | None
    ) -> NDArray[np.float32] | None:
        raise NotImplementedError
