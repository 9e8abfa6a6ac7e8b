"""The streaming loop (frame → rotation → per-target distance records) and its batch twin.

Convention: rotations camera-to-world ``(3, 3)`` relative to the first frame; timestamps in
seconds; θ in radians inside, degrees only in the CSV written for users.
"""

from __future__ import annotations

import csv
import math
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

from slopedist import geometry as geo
from slopedist.detections.boxes import BoxTable
from slopedist.errors import DataMismatchError
from slopedist.estimators.base import Estimator, FrameEstimates, FrameInput
from slopedist.odometry.base import LOOKBACK_S, TIME_EPS_S, RotationTrack, lookback_indices


class EgoGradientTracker:
    """Ego road gradient θ (eq. 2–4) from a stream of rotations, keeping only the look-back.

    The look-back frame of the current frame is the latest kept frame at least ``lookback_s``
    older; frames with less history use the earliest frame seen. Frames without a rotation are
    not kept. Memory is bounded by the number of frames within one look-back interval.
    """

    def __init__(self, mount_angle_rad: float = 0.0, lookback_s: float = LOOKBACK_S) -> None:
        self.mount_angle_rad = mount_angle_rad
        self.lookback_s = lookback_s
        self._history: deque[tuple[float, NDArray[np.float64]]] = deque()

    def __len__(self) -> int:
        return len(self._history)

    def update(self, timestamp_s: float, R_world_cam: NDArray[np.float64] | None) -> float:
        """Add a frame and return its θ in radians (NaN when ``R_world_cam`` is None)."""
        if R_world_cam is None:
            return math.nan
        R = np.asarray(R_world_cam, dtype=float)
        self._history.append((timestamp_s, R))
        cutoff = timestamp_s - self.lookback_s + TIME_EPS_S
        while len(self._history) > 1 and self._history[1][0] <= cutoff:
            self._history.popleft()
        R_prev = self._history[0][1]
        return float(geo.ego_road_gradient(R_prev, R, self.mount_angle_rad))


class StreamingEstimator:
    """Feed frames one at a time; get one estimate per target back.

    Example::

        stream = StreamingEstimator(make_estimator("paper", camera))
        for k, (t, R, boxes) in enumerate(frames):
            estimates = stream.update(k, t, R, boxes)
    """

    def __init__(self, estimator: Estimator, lookback_s: float = LOOKBACK_S) -> None:
        self.estimator = estimator
        self.gradient = EgoGradientTracker(estimator.camera.mount_angle_rad, lookback_s)
        self._last_timestamp: float | None = None

    def reset(self) -> None:
        """Start a new sequence."""
        self.gradient = EgoGradientTracker(self.gradient.mount_angle_rad, self.gradient.lookback_s)
        self.estimator.reset()
        self._last_timestamp = None

    def update(
        self,
        frame_index: int,
        timestamp_s: float,
        R_world_cam: NDArray[np.float64] | None,
        boxes: BoxTable,
        image: NDArray[np.uint8] | None = None,
        depth_m: NDArray[np.float32] | None = None,
    ) -> FrameEstimates:
        """Estimate the distances of one frame's boxes.

        Raises:
            DataMismatchError: if ``timestamp_s`` does not increase.
        """
        if self._last_timestamp is not None and timestamp_s <= self._last_timestamp:
            raise DataMismatchError(
                f"frame {frame_index}: timestamp {timestamp_s} s does not follow "
                f"{self._last_timestamp} s"
            )
        self._last_timestamp = timestamp_s
        theta = self.gradient.update(timestamp_s, R_world_cam)
        R = None if R_world_cam is None else np.asarray(R_world_cam, dtype=float)
        return self.estimator.estimate(
            FrameInput(frame_index, timestamp_s, theta, boxes, image, depth_m, R)
        )


def ego_gradients(
    track: RotationTrack, mount_angle_rad: float = 0.0, lookback_s: float = LOOKBACK_S
) -> NDArray[np.float64]:
    """θ (radians) of every frame of ``track`` at once; NaN where the track has no rotation."""
    theta = np.full(len(track), np.nan)
    valid = np.flatnonzero(track.valid)
    if valid.size:
        ref = valid[lookback_indices(track.timestamps_s[valid], lookback_s)]
        theta[valid] = geo.ego_road_gradient(
            track.R_world_cam[ref], track.R_world_cam[valid], mount_angle_rad
        )
    return theta


@dataclass
class SequenceEstimates:
    """Estimates of a whole sequence: the boxes (sorted by frame) and per-box results."""

    boxes: BoxTable
    timestamps_s: NDArray[np.float64]
    estimates: FrameEstimates
    method: str


def concat_estimates(parts: list[FrameEstimates]) -> FrameEstimates:
    """Concatenate per-frame estimates into one."""
    if not parts:
        e = np.zeros(0)
        o = np.zeros(0, dtype=object)
        return FrameEstimates(e, e, e, e, e, o, o)
    keys: set[str] = set().union(*(p.extra for p in parts))

    def cat(name: str) -> NDArray:
        return np.concatenate([getattr(p, name) for p in parts])

    return FrameEstimates(
        theta_rad=cat("theta_rad"),
        theta_adj_rad=cat("theta_adj_rad"),
        delta_y_px=cat("delta_y_px"),
        v_px=cat("v_px"),
        distance_m=cat("distance_m"),
        reason=cat("reason"),
        reference=cat("reference"),
        extra={
            k: np.concatenate([p.extra.get(k, np.full(len(p), np.nan)) for p in parts])
            for k in sorted(keys)
        },
    )


def concat_boxes(parts: list[BoxTable]) -> BoxTable:
    """Concatenate box tables (columns present in every part are kept)."""
    if not parts:
        return BoxTable.empty()
    keys = set.intersection(*(set(p.extra) for p in parts))
    return BoxTable(
        np.concatenate([p.frame for p in parts]),
        np.concatenate([p.boxes for p in parts]),
        np.concatenate([p.track_id for p in parts]),
        np.concatenate([p.score for p in parts]),
        np.concatenate([p.cls for p in parts]),
        {k: np.concatenate([p.extra[k] for p in parts]) for k in keys},
    )


def estimate_sequence(
    estimator: Estimator,
    boxes: BoxTable,
    timestamps_s: NDArray[np.float64],
    track: RotationTrack | None,
    lookback_s: float = LOOKBACK_S,
    depth: Callable[[int], NDArray[np.float32] | None] | None = None,
) -> SequenceEstimates:
    """Batch use: all frames' θ at once (vectorised), then the estimator frame by frame.

    Args:
        estimator: the method (reset before use).
        boxes: boxes of the sequence; frame indices index ``timestamps_s`` and ``track``.
        timestamps_s: timestamp of every frame, seconds.
        track: rotations of every frame (``len(track) == len(timestamps_s)``), or None.
        depth: depth map (metres) of a frame index, called for the frames with boxes when the
            estimator ``needs_depth`` (e.g. :meth:`slopedist.depth.DepthSource.depth`).
    """
    if track is not None and len(track) < len(timestamps_s):
        raise DataMismatchError(
            f"rotations cover {len(track)} frames but the sequence has {len(timestamps_s)}"
        )
    theta = (
        ego_gradients(track, estimator.camera.mount_angle_rad, lookback_s)
        if track is not None
        else np.full(len(timestamps_s), np.nan)
    )
    estimator.reset()
    box_parts, est_parts = [], []
    for k, frame_boxes in boxes.by_frame():
        if not 0 <= k < len(timestamps_s):
            raise DataMismatchError(
                f"boxes refer to frame {k}, but the sequence has frames 0..{len(timestamps_s) - 1}"
            )
        depth_m = depth(k) if depth is not None and estimator.needs_depth else None
        R = track.R_world_cam[k] if track is not None and track.valid[k] else None
        est_parts.append(
            estimator.estimate(
                FrameInput(
                    k,
                    float(timestamps_s[k]),
                    float(theta[k]),
                    frame_boxes,
                    depth_m=depth_m,
                    R_world_cam=R,
                )
            )
        )
        box_parts.append(frame_boxes)
    return SequenceEstimates(
        concat_boxes(box_parts),
        np.asarray(timestamps_s),
        concat_estimates(est_parts),
        estimator.name,
    )


RECORD_FIELDS = (
    "frame",
    "timestamp_s",
    "track_id",
    "class",
    "score",
    "left",
    "top",
    "right",
    "bottom",
    "method",
    "theta_deg",
    "theta_adj_deg",
    "delta_y_px",
    "v_px",
    "distance_m",
    "reference",
    "status",
    "reason",
)
"""Columns of the per-target records CSV, in order; method-specific extras follow."""


def iter_records(
    boxes: BoxTable,
    timestamps_s: Iterable[float] | NDArray[np.float64],
    est: FrameEstimates,
    method: str,
) -> Iterator[dict[str, Any]]:
    """One dict per target (``RECORD_FIELDS`` plus extras), angles in degrees.

    ``timestamps_s`` is indexed by each box's frame number.
    """
    ts = np.asarray(
        list(timestamps_s) if not isinstance(timestamps_s, np.ndarray) else timestamps_s
    )
    for i in range(len(boxes)):
        ok = est.reason[i] == ""
        row: dict[str, Any] = {
            "frame": int(boxes.frame[i]),
            "timestamp_s": float(ts[boxes.frame[i]]) if ts.size > boxes.frame[i] else math.nan,
            "track_id": int(boxes.track_id[i]),
            "class": boxes.cls[i],
            "score": float(boxes.score[i]),
            "left": float(boxes.boxes[i, 0]),
            "top": float(boxes.boxes[i, 1]),
            "right": float(boxes.boxes[i, 2]),
            "bottom": float(boxes.boxes[i, 3]),
            "method": method,
            "theta_deg": math.degrees(est.theta_rad[i]),
            "theta_adj_deg": math.degrees(est.theta_adj_rad[i]),
            "delta_y_px": float(est.delta_y_px[i]),
            "v_px": float(est.v_px[i]),
            "distance_m": float(est.distance_m[i]) if ok else math.nan,
            "reference": est.reference[i],
            "status": "ok" if ok else "missing",
            "reason": est.reason[i],
        }
        for key, values in est.extra.items():
            row[key] = float(values[i])
        yield row


class RecordWriter:
    """Writes per-target records to CSV as they come (flushes after every frame).

    Missing values are written as empty fields; the header is written with the first frame so
    that method-specific extra columns are included.
    """

    def __init__(self, stream: IO[str]) -> None:
        self._stream = stream
        self._writer: csv.DictWriter | None = None

    @classmethod
    def open(cls, path: str | Path) -> RecordWriter:
        """Open ``path`` for writing (parents created)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        return cls(path.open("w", newline=""))

    def write(self, rows: Iterable[dict[str, Any]]) -> None:
        """Write rows and flush."""
        for row in rows:
            if self._writer is None:
                fields = list(RECORD_FIELDS) + [k for k in row if k not in RECORD_FIELDS]
                self._writer = csv.DictWriter(
                    self._stream, fieldnames=fields, extrasaction="ignore"
                )
                self._writer.writeheader()
            self._writer.writerow({k: _fmt(v) for k, v in row.items()})
        self._stream.flush()

    def close(self) -> None:
        """Close the file (writes a header-only file if nothing was written)."""
        if self._writer is None:
            csv.writer(self._stream).writerow(RECORD_FIELDS)
        self._stream.close()

    def __enter__(self) -> RecordWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _fmt(value: Any) -> Any:
    if isinstance(value, float):
        return "" if not math.isfinite(value) else f"{value:.6g}"
    return value
