"""Time-stamped camera rotations and the one-second look-back.

Convention: rotations are 3×3 camera-to-world matrices relative to the first frame
(camera frame x right, y down, z forward); timestamps are float64 seconds, increasing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.core.errors import ConfigurationError, DataMismatchError
from slopedist.core.geometry import not_rotations

LOOKBACK_S = 1.0
"""Default look-back of the ego gradient, seconds (the paper's one second)."""

TIME_EPS_S = 1e-6
"""Tolerance when comparing timestamps (k × 0.1 s is not exact in binary floating point)."""


def check_lookback(lookback_s: float) -> float:
    """``lookback_s`` as a float, the look-back of the ego gradient (eq. 4), seconds.

    Raises:
        ConfigurationError: it is not a finite number > 0 (a NaN, 0 or negative look-back
            gave θ = 0 or NaN for every frame without a word).
    """
    if not (
        isinstance(lookback_s, (int, float, np.integer, np.floating))
        and not isinstance(lookback_s, bool)
        and math.isfinite(lookback_s)
        and lookback_s > 0
    ):
        raise ConfigurationError(
            f"lookback_s must be a finite number of seconds > 0, got {lookback_s!r}"
        )
    return float(lookback_s)


def lookback_indices(timestamps_s: ArrayLike, lookback_s: float = LOOKBACK_S) -> NDArray[np.intp]:
    """Index of the look-back frame for every frame.

    The look-back frame of frame i is the latest frame j with ``t_j ≤ t_i − lookback``; frames with
    less history than that look back to the earliest frame (index 0).

    Args:
        timestamps_s: increasing timestamps, seconds, shape ``(N,)``.
        lookback_s: look-back interval, seconds.
    """
    t = np.asarray(timestamps_s, dtype=float)
    j = np.searchsorted(t, t - lookback_s + TIME_EPS_S, side="right") - 1
    return np.maximum(j, 0).astype(np.intp)


@dataclass(frozen=True)
class RotationTrack:
    """Camera-to-world rotations of a sequence.

    Attributes:
        timestamps_s: ``(N,)`` seconds, strictly increasing.
        R_world_cam: ``(N, 3, 3)`` camera-to-world rotations relative to the first frame.
        valid: ``(N,)`` bool; False where the source has no rotation for that frame (e.g. visual
            odometry not initialised or lost).
    """

    timestamps_s: NDArray[np.float64]
    R_world_cam: NDArray[np.float64]
    valid: NDArray[np.bool_]

    @classmethod
    def from_arrays(
        cls, timestamps_s: ArrayLike, R_world_cam: ArrayLike, valid: ArrayLike | None = None
    ) -> RotationTrack:
        """Validate and build a track.

        Raises:
            DataMismatchError: timestamps that are not ``(N,)`` finite, increasing numbers;
                rotations that are not ``(N, 3, 3)`` numbers, or a finite one of a valid frame
                that is not a rotation (:func:`~slopedist.core.geometry.not_rotations`, as
                :class:`~slopedist.streaming.step.FrameStep` refuses it); ``valid`` that is not
                ``(N,)``.
        """
        try:
            t = np.asarray(timestamps_s, dtype=float)
            R = np.asarray(R_world_cam, dtype=float)
        except (TypeError, ValueError) as exc:
            raise DataMismatchError(f"rotation track: {exc}") from None
        if t.ndim != 1:
            raise DataMismatchError(f"timestamps must be one per frame (N,), got shape {t.shape}")
        if R.ndim != 3 or R.shape[1:] != (3, 3) or R.shape[0] != t.shape[0]:
            raise DataMismatchError(
                f"rotations must be (N, 3, 3) with N = {t.shape[0]} timestamps, got {R.shape}"
            )
        if not np.isfinite(t).all():
            k = int(np.argmin(np.isfinite(t)))
            raise DataMismatchError(f"timestamps must be finite: frame {k} at {t[k]} s")
        if t.size > 1 and np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0)) + 1
            raise DataMismatchError(
                f"timestamps must increase: frame {k} at {t[k]} s follows {t[k - 1]} s"
            )
        v = np.ones(t.shape, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
        if v.shape != t.shape:
            raise DataMismatchError(
                f"valid must be one flag per frame ({t.shape[0]}), got shape {v.shape}"
            )
        bad = np.flatnonzero(v & np.isfinite(R).all(axis=(1, 2)))  # the finite rotations
        if bad.size:
            bad = bad[not_rotations(R[bad])]
        if bad.size:
            k = int(bad[0])
            raise DataMismatchError(
                f"frame {k}: the rotation is not a rotation matrix: {R[k].tolist()}"
            )
        return cls(t, R, v)

    def __len__(self) -> int:
        return int(self.timestamps_s.shape[0])


class OdometryState(str, Enum):
    """Per-frame state of a visual-odometry backend."""

    OK = "ok"
    NOT_INITIALISED = "not_initialised"
    LOST = "lost"


@dataclass(frozen=True)
class OdometryResult:
    """What a visual-odometry backend reports for one frame.

    Attributes:
        R_world_cam: camera-to-world rotation ``(3, 3)`` relative to the first frame, or None
            when the state is not ``OK``.
        state: :class:`OdometryState`.
        inliers: number of inlier correspondences behind the estimate (0 if none).
        segment: counts the restarts of the backend after it was lost for good (0 until the
            first). Rotations of different segments are not related: a consumer should not
            look back across a change of segment (the new segment starts from the last known
            rotation, i.e. assumes no rotation during the gap).
    """

    R_world_cam: NDArray[np.float64] | None
    state: OdometryState
    inliers: int = 0
    segment: int = 0


class RotationOdometry(Protocol):
    """Interface of rotation sources that work from pixels (built-in VO, ORB-SLAM3).

    ``process`` is fed frames in time order (grey ``H×W`` uint8 images, timestamps in seconds,
    optional ``(N, 4)`` boxes (left, top, right, bottom) of moving vehicles to mask out of the
    features) and returns the frame's :class:`OdometryResult`. Memory must not grow with the
    number of frames.
    """

    def process(
        self,
        image_gray: NDArray[np.uint8],
        timestamp_s: float,
        mask_boxes: NDArray[np.float64] | None = None,
    ) -> OdometryResult: ...

    def reset(self) -> None: ...


def check_track_times(track: RotationTrack, timestamps_s: NDArray[np.float64]) -> None:
    """Refuse rotations that are not of the frames they are paired with: rotation k's own
    time more than half a frame period (the median step of ``timestamps_s``, seconds; the
    track's when there is one frame) from frame k's (a pose file at another rate or offset).

    Frame times that are not finite and increasing are left to :class:`FrameStep`, which
    names the frame.

    Raises:
        DataMismatchError: fewer rotations than frames; naming the first frame whose rotation
            is of another time, and both times.
    """
    n = len(timestamps_s)
    if len(track) < n:
        raise DataMismatchError(f"rotations cover {len(track)} frames but the sequence has {n}")
    t, t_rot = timestamps_s, track.timestamps_s[:n]
    if n == 0 or not np.isfinite(t).all() or np.any(np.diff(t) <= 0):
        return
    steps = np.diff(t) if n > 1 else np.diff(track.timestamps_s)
    if not steps.size:
        return
    half_period_s = 0.5 * float(np.median(steps))
    off = np.abs(t_rot - t) > half_period_s + TIME_EPS_S
    if off.any():
        k = int(np.argmax(off))
        raise DataMismatchError(
            f"frame {k}: its rotation is of time {t_rot[k]:.6g} s but the frame is at "
            f"{t[k]:.6g} s ({abs(t_rot[k] - t[k]):.3g} s apart, more than half the frame period "
            f"of {2 * half_period_s:.3g} s): the rotations are not of these frames (poses at "
            "another rate, or with an offset?)"
        )
