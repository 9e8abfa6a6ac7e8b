"""Accuracy and speed of a rotation source from pixels against ground-truth rotations.

Two figures matter for the ego gradient (DESIGN.md eq. 2–4), both over the look-back pairs
``(j, i)`` (``j`` = look-back frame of ``i`` among the frames the backend gave a rotation for,
within one segment):

- θ error: ``θ(R̂_j, R̂_i) − θ(R_j, R_i)``, the paper's ego gradient from the estimated and from
  the true rotations of the *same* pair of frames;
- relative-rotation error: the angle of ``(R̂_jᵀ R̂_i)ᵀ (R_jᵀ R_i)``, over full look-back windows
  only (``t_i − t_j ≥ look-back``; 10 frames at KITTI's 10 Hz).

Radians inside; :meth:`OdometryEvaluation.as_dict` reports degrees and milliseconds.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.core import geometry as geo
from slopedist.core.errors import DataMismatchError
from slopedist.odometry.base import (
    LOOKBACK_S,
    TIME_EPS_S,
    OdometryResult,
    OdometryState,
    RotationOdometry,
    RotationTrack,
    lookback_indices,
)

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class OdometryRun:
    """What a backend produced for a sequence.

    Attributes:
        timestamps_s: ``(N,)`` seconds.
        R_world_cam: ``(N, 3, 3)`` rotations; identity where there is none.
        valid: ``(N,)`` True where the state was ``OK``.
        segment: ``(N,)`` segment number of every frame (see ``OdometryResult.segment``).
        seconds: time spent inside ``process`` (wall clock, image decoding excluded).
        cpu_seconds: processor time of this process inside ``process`` (all its threads; less
            sensitive than the wall clock to other programs competing for the cores).
    """

    timestamps_s: FloatArray
    R_world_cam: FloatArray
    valid: NDArray[np.bool_]
    segment: NDArray[np.int64]
    seconds: float
    cpu_seconds: float

    def __len__(self) -> int:
        return int(self.timestamps_s.shape[0])

    @property
    def track(self) -> RotationTrack:
        """The rotations as a :class:`RotationTrack` (invalid frames flagged)."""
        return RotationTrack.from_arrays(self.timestamps_s, self.R_world_cam, self.valid)


def run_odometry(
    odometry: RotationOdometry,
    frames: Iterable[tuple[float, NDArray[np.uint8]]],
    on_result: Callable[[int, OdometryResult], None] | None = None,
) -> OdometryRun:
    """Feed ``(timestamp_s, grey image)`` frames to ``odometry`` and collect its rotations.

    Only the time inside ``process`` is counted (frames may be decoded lazily by the iterable).
    ``on_result(k, result)`` is called after every frame (e.g. a progress bar).
    """
    times: list[float] = []
    rotations: list[FloatArray] = []
    valid: list[bool] = []
    segments: list[int] = []
    seconds = cpu_seconds = 0.0
    for k, (t, image) in enumerate(frames):
        start, cpu_start = time.perf_counter(), time.process_time()
        result = odometry.process(image, t)
        seconds += time.perf_counter() - start
        cpu_seconds += time.process_time() - cpu_start
        ok = result.state is OdometryState.OK and result.R_world_cam is not None
        times.append(float(t))
        rotations.append(np.asarray(result.R_world_cam) if ok else np.eye(3))
        valid.append(ok)
        segments.append(int(getattr(result, "segment", 0)))
        if on_result is not None:
            on_result(k, result)
    return OdometryRun(
        np.asarray(times, dtype=np.float64),
        np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3),
        np.asarray(valid, dtype=bool),
        np.asarray(segments, dtype=np.int64),
        seconds,
        cpu_seconds,
    )


def lookback_pairs(
    run: OdometryRun, lookback_s: float = LOOKBACK_S
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
    """Look-back pairs ``(j, i)`` over the valid frames of each segment.

    Returns:
        ``(j, i, full)``: frame indices and whether the pair spans a full look-back.
    """
    js: list[NDArray[np.intp]] = []
    is_: list[NDArray[np.intp]] = []
    for seg in np.unique(run.segment[run.valid]):
        idx = np.flatnonzero(run.valid & (run.segment == seg))
        j = idx[lookback_indices(run.timestamps_s[idx], lookback_s)]
        js.append(j)
        is_.append(idx)
    if not js:
        empty = np.empty(0, dtype=np.intp)
        return empty, empty, np.empty(0, dtype=bool)
    j_all = np.concatenate(js)
    i_all = np.concatenate(is_)
    full = run.timestamps_s[i_all] - run.timestamps_s[j_all] >= lookback_s - TIME_EPS_S
    return j_all, i_all, full


@dataclass(frozen=True)
class RotationErrors:
    """Per-frame errors of a run against ground truth (NaN where not defined).

    Attributes:
        theta_err_rad: ``(N,)`` θ error, radians; NaN for frames without a rotation.
        rel_err_rad: ``(N,)`` relative-rotation error over a full look-back window, radians;
            NaN where the frame has no rotation or less than a full look-back of history.
    """

    theta_err_rad: FloatArray
    rel_err_rad: FloatArray


def rotation_errors(
    run: OdometryRun,
    truth: RotationTrack,
    lookback_s: float = LOOKBACK_S,
    mount_angle_rad: float = 0.0,
) -> RotationErrors:
    """θ and relative-rotation errors of ``run`` against ``truth`` (same frames)."""
    if len(truth) != len(run):
        raise DataMismatchError(
            f"{len(truth)} ground-truth rotations for {len(run)} frames of visual odometry"
        )
    j, i, full = lookback_pairs(run, lookback_s)
    R, G = run.R_world_cam, truth.R_world_cam
    theta_err = np.full(len(run), np.nan)
    theta_err[i] = geo.ego_road_gradient(R[j], R[i], mount_angle_rad) - geo.ego_road_gradient(
        G[j], G[i], mount_angle_rad
    )
    rel_err = np.full(len(run), np.nan)
    rel_est = geo.relative_rotation(R[j], R[i])
    rel_true = geo.relative_rotation(G[j], G[i])
    angles = geo.rotation_angle_rad(np.swapaxes(rel_est, -1, -2) @ rel_true)
    rel_err[i[full]] = angles[full]
    return RotationErrors(theta_err, rel_err)


@dataclass(frozen=True)
class OdometryEvaluation:
    """Summary figures of a backend on one sequence.

    Attributes:
        frames: frames in the sequence.
        frames_ok: frames the backend gave a rotation for.
        theta_rms_rad: RMS of the θ error over the frames with a rotation, radians.
        rel_rot_median_rad: median relative-rotation error over full look-back windows, radians.
        seconds_per_frame: mean time per frame inside the backend, seconds (wall clock).
        cpu_seconds_per_frame: the same in processor time.
    """

    frames: int
    frames_ok: int
    theta_rms_rad: float
    rel_rot_median_rad: float
    seconds_per_frame: float
    cpu_seconds_per_frame: float

    @classmethod
    def from_run(
        cls,
        run: OdometryRun,
        truth: RotationTrack,
        lookback_s: float = LOOKBACK_S,
        mount_angle_rad: float = 0.0,
    ) -> OdometryEvaluation:
        """Compare ``run`` with ``truth``."""
        errors = rotation_errors(run, truth, lookback_s, mount_angle_rad)
        theta = errors.theta_err_rad[np.isfinite(errors.theta_err_rad)]
        rel = errors.rel_err_rad[np.isfinite(errors.rel_err_rad)]
        return cls(
            frames=len(run),
            frames_ok=int(np.count_nonzero(run.valid)),
            theta_rms_rad=float(np.sqrt(np.mean(theta**2))) if theta.size else math.nan,
            rel_rot_median_rad=float(np.median(rel)) if rel.size else math.nan,
            seconds_per_frame=run.seconds / max(len(run), 1),
            cpu_seconds_per_frame=run.cpu_seconds / max(len(run), 1),
        )

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready figures in degrees and milliseconds (NaN → None)."""

        def num(value: float, digits: int) -> float | None:
            return round(value, digits) if math.isfinite(value) else None

        return {
            "frames": self.frames,
            "frames_ok": self.frames_ok,
            "theta_rms_deg": num(math.degrees(self.theta_rms_rad), 4),
            "rel_rot_median_deg": num(math.degrees(self.rel_rot_median_rad), 4),
            "ms_per_frame": num(1000.0 * self.seconds_per_frame, 2),
            "cpu_ms_per_frame": num(1000.0 * self.cpu_seconds_per_frame, 2),
        }
