"""The per-frame step every loop calls (rotation → θ → per-target estimates) and the records.

:class:`FrameStep` is the one step: the streaming :class:`~slopedist.streaming.pipeline.Pipeline`
(``slopedist run``, ``batch``, ``estimate`` and Python users), ``calibrate``
(:func:`stream_track`), the demo and the batch :func:`estimate_sequence` behind the KITTI
evaluation differ only in where the frames come from and where the results go.

Convention: rotations camera-to-world ``(3, 3)`` relative to the first frame; timestamps in
seconds; θ in radians inside, degrees only in the CSV written for users.
"""

from __future__ import annotations

import math
import sys
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.core import geometry as geo
from slopedist.core.errors import ConfigurationError, DataMismatchError
from slopedist.core.suggest import unknown_choice
from slopedist.estimators.base import (
    EstimateStatus,
    Estimator,
    FrameEstimates,
    FrameInput,
    MissingReason,
    ReferencePoint,
    settle_states,
)
from slopedist.estimators.references import at_reference
from slopedist.io.detections.boxes import (
    DEFAULT_VEHICLE_CLASSES,
    NO_TRACK,
    BoxTable,
    concat_boxes,
)
from slopedist.io.detections.readers import CSV_TRUTH_COLUMN
from slopedist.io.formatting import STDOUT_PATH, CsvStreamWriter
from slopedist.odometry.base import (
    LOOKBACK_S,
    TIME_EPS_S,
    RotationTrack,
    check_lookback,
    check_track_times,
    lookback_indices,
)
from slopedist.odometry.jumps import (
    JumpMarks,
    JumpVerdict,
    PitchJumpGuard,
    track_jumps,
    trusted_rotations,
)

MAX_EGO_GRADIENT_RAD = math.radians(30.0)
"""The largest ego gradient θ a road can give, radians, beyond the θ of the camera at rest (its
mount angle's): the steepest public roads climb about 20° (35 %), and eq. 4 measures the change
of the camera's pitch over one second. A larger θ is an odometry glitch (a rotation that
jumps), not a road: its vanishing line would put every target a few metres ahead.
:class:`FrameStep` treats such a frame as one without a rotation (``no_rotation`` for the
methods that need one)."""


def usable_gradient(theta_rad: float, theta_rest_rad: float = 0.0) -> float:
    """``theta_rad`` when it is a road's gradient (finite, within :data:`MAX_EGO_GRADIENT_RAD`
    of ``theta_rest_rad``, the θ of the camera at rest), else NaN: no rotation to go by."""
    return theta_rad if abs(theta_rad - theta_rest_rad) <= MAX_EGO_GRADIENT_RAD else math.nan


class EgoGradientTracker:
    """Ego road gradient θ (eq. 2–4) from a stream of rotations, keeping only the look-back.

    The look-back frame of the current frame is the latest kept frame at least ``lookback_s``
    older; frames with less history use the earliest frame seen. Frames without a rotation are
    not kept. A change of odometry segment (:attr:`~slopedist.odometry.base.OdometryResult.
    segment`) forgets the history: θ never looks back across a restart of the odometry. Memory
    is bounded by the number of frames within one look-back interval.

    A rotation whose pitch jumps faster than a car can pitch (:mod:`slopedist.odometry.jumps`)
    is a glitch: θ NaN, not kept, :attr:`jump` True (:attr:`trusted_rotation`: the last kept);
    a jump that persists is accepted as a new level after a settling time: history restarts.
    """

    def __init__(self, mount_angle_rad: float = 0.0, lookback_s: float = LOOKBACK_S) -> None:
        self.mount_angle_rad = mount_angle_rad
        self.lookback_s = check_lookback(lookback_s)
        self.segment = 0
        self.jump = False
        self.trusted_rotation: NDArray[np.float64] | None = None
        self._guard = PitchJumpGuard(mount_angle_rad)
        self._history: deque[tuple[float, NDArray[np.float64]]] = deque()

    def __len__(self) -> int:
        return len(self._history)

    def update(
        self, timestamp_s: float, R_world_cam: NDArray[np.float64] | None, segment: int = 0
    ) -> float:
        """Add a frame of odometry ``segment`` and return its θ in radians (NaN when
        ``R_world_cam`` is None or not finite, not kept, or an odometry jump: :attr:`jump`)."""
        if segment != self.segment:
            self._history.clear()
            self._guard.reset()
            self.segment = segment
        if R_world_cam is None or not np.isfinite(R_world_cam).all():
            self.jump = False
            return math.nan
        R = np.asarray(R_world_cam, dtype=float)
        verdict = self._guard.update(timestamp_s, R)
        self.jump = verdict is JumpVerdict.JUMP
        if self.jump:
            return math.nan
        if verdict is JumpVerdict.NEW_LEVEL:
            self._history.clear()
        self.trusted_rotation = R
        self._history.append((timestamp_s, R))
        cutoff = timestamp_s - self.lookback_s + TIME_EPS_S
        while len(self._history) > 1 and self._history[1][0] <= cutoff:
            self._history.popleft()
        R_prev = self._history[0][1]
        return float(geo.ego_road_gradient(R_prev, R, self.mount_angle_rad))

    def given_rotation(self, R: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
        """The rotation the last frame's estimators get: ``R``, or on a jump the last trusted."""
        return self.trusted_rotation if self.jump else R


@dataclass(frozen=True)
class StepResult:
    """What one frame step gives: the ego gradient θ (radians, NaN without a rotation), the
    per-box estimates and whether the frame's rotation was an odometry jump (not trusted)."""

    theta_rad: float
    estimates: FrameEstimates
    odometry_jump: bool = False


class FrameStep:
    """The per-frame step every loop calls: look-back → θ → estimator, one frame at a time.

    It owns the segment-aware look-back (:class:`EgoGradientTracker`), checks that timestamps
    increase, handles frames without boxes in one place (the estimator is not called for
    them, exactly as in batch use, so that streaming equals batch) and settles the per-box
    states no method may overrule (:func:`~slopedist.estimators.base.settle_states`: the
    ``cut`` flag from the camera's image size, boxes outside the image or degenerate, classes
    not in ``vehicle_classes``, and for a method that does not handle border cuts itself
    (:attr:`~slopedist.estimators.base.Estimator.handles_border_cuts`) a bottom cut makes an
    ``ok`` row an ``upper_bound``). With a ``reference`` every method's distances are moved to
    that point of the vehicle (:func:`~slopedist.estimators.references.at_reference`: what a
    user sees, :data:`~slopedist.estimators.references.DEFAULT_REFERENCE` by default in
    ``run``); None leaves each at the point its method reports (evaluations, which compare at
    their truth's point). Loops differ only in where frames come from and where the results
    go.

    Example::

        step = FrameStep(make_estimator("paper", camera))
        for k, (t, R, boxes) in enumerate(frames):
            result = step.step(k, t, R, boxes)  # result.theta_rad, result.estimates
    """

    def __init__(
        self,
        estimator: Estimator,
        lookback_s: float = LOOKBACK_S,
        vehicle_classes: Iterable[str] = DEFAULT_VEHICLE_CLASSES,
        reference: ReferencePoint | None = None,
    ) -> None:
        self.estimator = estimator
        self.reference = ReferencePoint(reference) if reference is not None else None
        if isinstance(vehicle_classes, str):  # tuple("Car") is ("C", "a", "r"): no vehicle at all
            raise ConfigurationError(
                f"vehicle_classes must be a collection of class names, got the text "
                f"{vehicle_classes!r} (write ({vehicle_classes!r},))"
            )
        self.vehicle_classes = tuple(vehicle_classes)
        self.gradient = EgoGradientTracker(estimator.camera.mount_angle_rad, lookback_s)
        self._theta_rest = float(geo.rest_gradient(estimator.camera.mount_angle_rad))
        self._last_timestamp: float | None = None
        self._offline_boxes: list[tuple[BoxTable, bool]] = []

    def reset(self) -> None:
        """Start a new sequence."""
        self.gradient = EgoGradientTracker(self.gradient.mount_angle_rad, self.gradient.lookback_s)
        self.estimator.reset()
        self._last_timestamp = None
        self._offline_boxes = []

    def finish(self) -> list[FrameEstimates]:
        """An offline estimator's final estimates (:meth:`Estimator.finish`) of every frame
        with boxes since :meth:`reset`, in order, settled as :meth:`estimate` settles them.

        Raises:
            NotImplementedError: the estimator is causal (its per-frame estimates are final).
        """
        est = self.estimator.finish()
        return [
            self._settle(e, boxes, jump)
            for e, (boxes, jump) in zip(est, self._offline_boxes, strict=True)
        ]

    def step(
        self,
        frame_index: int,
        timestamp_s: float,
        R_world_cam: NDArray[np.float64] | None,
        boxes: BoxTable | None,
        image: NDArray[np.uint8] | None = None,
        depth_m: NDArray[np.float32] | None = None,
        segment: int = 0,
    ) -> StepResult:
        """θ of the frame (look-back within odometry ``segment``; NaN beyond
        :data:`MAX_EGO_GRADIENT_RAD` or on an odometry jump, :class:`EgoGradientTracker`) and
        its boxes' estimates.

        Raises:
            DataMismatchError: if ``timestamp_s`` is not finite or does not increase, or
                ``R_world_cam`` is not a ``(3, 3)`` matrix.
        """
        self._check_time(frame_index, timestamp_s)  # before the look-back takes the frame
        R = _rotation(frame_index, R_world_cam)
        theta = usable_gradient(self.gradient.update(timestamp_s, R, segment), self._theta_rest)
        R, jump = self.gradient.given_rotation(R), self.gradient.jump  # on a jump: none since
        est = self._estimate(frame_index, timestamp_s, theta, R, boxes, image, depth_m, jump)
        return StepResult(theta, est, jump)

    def estimate(
        self,
        frame_index: int,
        timestamp_s: float,
        theta_rad: float,
        R_world_cam: NDArray[np.float64] | None,
        boxes: BoxTable | None,
        image: NDArray[np.uint8] | None = None,
        depth_m: NDArray[np.float32] | None = None,
        odometry_jump: bool = False,
    ) -> FrameEstimates:
        """The estimates of a frame whose θ (radians; taken as NaN beyond
        :data:`MAX_EGO_GRADIENT_RAD`) was computed elsewhere: vectorised over a
        whole track (:func:`estimate_sequence`) or shared by several methods fed the same
        rotations (the demo). ``odometry_jump``: the frame's rotation is a glitch
        (:func:`ego_gradients`' marks): θ is NaN, and ``R_world_cam`` should be the last trusted
        one (:func:`~slopedist.odometry.jumps.trusted_rotations`).

        Raises:
            DataMismatchError: if ``timestamp_s`` is not finite or does not increase, or
                ``R_world_cam`` is not a ``(3, 3)`` matrix.
        """
        self._check_time(frame_index, timestamp_s)
        R = _rotation(frame_index, R_world_cam)
        theta = math.nan if odometry_jump else usable_gradient(theta_rad, self._theta_rest)
        return self._estimate(
            frame_index, timestamp_s, theta, R, boxes, image, depth_m, odometry_jump
        )

    def _estimate(
        self,
        frame_index: int,
        timestamp_s: float,
        theta_rad: float,
        R: NDArray[np.float64] | None,
        boxes: BoxTable | None,
        image: NDArray[np.uint8] | None,
        depth_m: NDArray[np.float32] | None,
        jump: bool = False,
    ) -> FrameEstimates:
        """:meth:`estimate` of a frame whose time and rotation ``R`` were checked."""
        self._last_timestamp = timestamp_s
        if boxes is None or not len(boxes):
            return FrameEstimates.empty()
        est = self.estimator.estimate(
            FrameInput(frame_index, timestamp_s, theta_rad, boxes, image, depth_m, R)
        )
        if self.estimator.offline:
            self._offline_boxes.append((boxes, jump))
        return self._settle(est, boxes, jump)

    def _settle(self, est: FrameEstimates, boxes: BoxTable, jump: bool) -> FrameEstimates:
        """:func:`~slopedist.estimators.base.settle_states`; on an odometry ``jump`` the rows
        a method left without a rotation say why (``odometry_jump``)."""
        est = settle_states(
            est,
            boxes,
            self.estimator.camera,
            self.vehicle_classes,
            not self.estimator.handles_border_cuts,
        )
        if jump:
            est.reason[est.reason == MissingReason.NO_ROTATION.value] = (
                MissingReason.ODOMETRY_JUMP.value
            )
        if self.reference is not None:
            est = at_reference(est, boxes.cls, self.reference)
        return est

    def skip(self, frame_index: int, timestamp_s: float) -> None:
        """Take a frame that :meth:`estimate` is not called for (no boxes, θ computed
        elsewhere): its timestamp is checked and kept, as :meth:`step` checks and keeps every
        frame's, so that a batch loop refuses the same timestamps as a streaming one.

        Raises:
            DataMismatchError: if ``timestamp_s`` is not finite or does not increase.
        """
        self._check_time(frame_index, timestamp_s)
        self._last_timestamp = timestamp_s

    def _check_time(self, frame_index: int, timestamp_s: float) -> None:
        if not isinstance(timestamp_s, (int, float, np.integer, np.floating)):
            raise DataMismatchError(
                f"frame {frame_index}: timestamp must be a number of seconds, got {timestamp_s!r}"
            )
        if not math.isfinite(timestamp_s):
            raise DataMismatchError(f"frame {frame_index}: timestamp {timestamp_s} s is not finite")
        if self._last_timestamp is not None and timestamp_s <= self._last_timestamp:
            raise DataMismatchError(
                f"frame {frame_index}: timestamp {timestamp_s} s does not follow "
                f"{self._last_timestamp} s"
            )


def _rotation(
    frame_index: int, R_world_cam: NDArray[np.float64] | None
) -> NDArray[np.float64] | None:
    """``R_world_cam`` as a float ``(3, 3)`` array (None stays None: no rotation).

    Raises:
        DataMismatchError: it is not a ``(3, 3)`` matrix of numbers, or a finite one that is
            not a rotation (:func:`~slopedist.core.geometry.not_rotations`, as pose files are
            checked).
    """
    if R_world_cam is None:
        return None
    try:
        R = np.asarray(R_world_cam, dtype=float)
    except (TypeError, ValueError):
        R = np.empty(0)
    if R.shape != (3, 3):
        raise DataMismatchError(
            f"frame {frame_index}: the camera rotation must be a 3×3 matrix (or None), got "
            f"shape {np.shape(R_world_cam)}"
        )
    if np.isfinite(R).all() and geo.not_rotations(R):
        raise DataMismatchError(
            f"frame {frame_index}: the camera rotation is not a rotation matrix: {R.tolist()}"
        )
    return R


def stream_track(
    step: FrameStep, track: RotationTrack, boxes: BoxTable
) -> Iterator[tuple[BoxTable, float, StepResult]]:
    """Feed every frame of ``track`` with its boxes to ``step``, in order; yields each frame's
    ``(boxes, timestamp_s, result)`` (box frame indices index the track)."""
    by_frame = boxes.frame_index()
    step.reset()
    for k in range(len(track)):
        t = float(track.timestamps_s[k])
        R = track.R_world_cam[k] if track.valid[k] else None
        frame_boxes = by_frame.get(k, _NO_BOXES)
        yield frame_boxes, t, step.step(k, t, R, frame_boxes)


_NO_BOXES = BoxTable.empty()


def ego_gradients(
    track: RotationTrack,
    mount_angle_rad: float = 0.0,
    lookback_s: float = LOOKBACK_S,
    jumps: JumpMarks | None = None,
) -> NDArray[np.float64]:
    """θ (radians) of every frame of ``track`` at once, as :class:`EgoGradientTracker` gives
    it frame by frame: NaN where the track has no rotation or an odometry jump (``jumps``,
    :func:`~slopedist.odometry.jumps.track_jumps` when not given), whose frames are no
    look-back reference; the look-back never crosses an accepted new level.

    Raises:
        ConfigurationError: ``lookback_s`` is not a finite number > 0.
    """
    lookback_s = check_lookback(lookback_s)
    if jumps is None:
        jumps = track_jumps(track, mount_angle_rad)
    theta = np.full(len(track), np.nan)
    valid = np.flatnonzero(track.valid & ~jumps.jump)
    if valid.size:
        level = jumps.level[valid]  # non-decreasing: the first frame of each level
        first = np.searchsorted(level, level, side="left")
        back = lookback_indices(track.timestamps_s[valid], lookback_s)
        ref = valid[np.maximum(back, first)]
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
        return FrameEstimates.empty()
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
        status=cat("status"),
        cut=cat("cut"),
        extra={
            k: np.concatenate([p.extra.get(k, np.full(len(p), np.nan)) for p in parts])
            for k in sorted(keys)
        },
    )


def estimate_sequence(
    estimator: Estimator,
    boxes: BoxTable,
    timestamps_s: NDArray[np.float64],
    track: RotationTrack | None,
    lookback_s: float = LOOKBACK_S,
    depth: Callable[[int], NDArray[np.float32] | None] | None = None,
    vehicle_classes: Iterable[str] = DEFAULT_VEHICLE_CLASSES,
) -> SequenceEstimates:
    """Batch use: all frames' θ at once (vectorised), then the estimator frame by frame (and,
    for an offline estimator such as ``ours-offline``, its pass over the whole drive).

    Args:
        estimator: the method (reset before use).
        boxes: boxes of the sequence; frame indices index ``timestamps_s`` and ``track``.
        timestamps_s: timestamp of every frame, seconds.
        track: rotations of every frame (``len(track) == len(timestamps_s)``), or None.
        depth: depth map (metres) of a frame index, called for the frames with boxes when the
            estimator ``needs_depth`` (e.g. :meth:`slopedist.io.depth.DepthSource.depth`).
        vehicle_classes: class names scored as vehicles (others: ``not_a_vehicle``).

    Raises:
        DataMismatchError: a timestamp (of any frame, with boxes or not) that is not finite
            or does not increase, as :meth:`FrameStep.step` refuses it; boxes of a frame
            beyond ``timestamps_s``; fewer rotations than frames; ``timestamps_s`` that are
            not ``(N,)``; a rotation whose own time is more than half a frame period from its
            frame's (:func:`~slopedist.odometry.base.check_track_times`).
        ConfigurationError: a ``lookback_s`` or ``vehicle_classes`` :class:`FrameStep`
            refuses.
    """
    step = FrameStep(estimator, lookback_s, vehicle_classes)  # its options checked first
    try:
        timestamps_s = np.asarray(timestamps_s, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DataMismatchError(f"timestamps_s: {exc}") from None
    if timestamps_s.ndim != 1:
        raise DataMismatchError(
            f"timestamps_s must be one per frame (N,), got shape {timestamps_s.shape}"
        )
    n = len(timestamps_s)
    theta, valid, jump, rotations = np.full(n, np.nan), np.zeros(n, bool), np.zeros(n, bool), None
    if track is not None:  # a jump frame's estimator gets the last trusted rotation, as a stream's
        check_track_times(track, timestamps_s)
        jumps = track_jumps(track, estimator.camera.mount_angle_rad)
        theta = ego_gradients(track, estimator.camera.mount_angle_rad, lookback_s, jumps)
        valid, jump, rotations = track.valid, jumps.jump, trusted_rotations(track, jumps)
    step.reset()
    box_parts, est_parts = [], []
    done = 0  # frames taken so far: those without boxes are checked as a stream checks them
    for k, frame_boxes in boxes.by_frame():
        if not 0 <= k < len(timestamps_s):
            raise DataMismatchError(
                f"boxes refer to frame {k}, but the sequence has frames 0..{len(timestamps_s) - 1}"
            )
        for j in range(done, k):
            step.skip(j, float(timestamps_s[j]))
        done = k + 1
        depth_m = depth(k) if depth is not None and estimator.needs_depth else None
        R = rotations[k] if rotations is not None and valid[k] else None
        t_k, theta_k, jump_k = float(timestamps_s[k]), float(theta[k]), bool(jump[k])
        est_parts.append(step.estimate(k, t_k, theta_k, R, frame_boxes, None, depth_m, jump_k))
        box_parts.append(frame_boxes)
    for j in range(done, len(timestamps_s)):
        step.skip(j, float(timestamps_s[j]))
    if estimator.offline:  # the whole drive seen: the offline pass revises every frame
        est_parts = step.finish()
    return SequenceEstimates(
        concat_boxes(box_parts, like=boxes),
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
    "cut",
)
"""Columns of the full per-target records (:attr:`RecordColumns.ALL`), in order; the method's
extra columns follow.

``status`` is ``ok``, ``upper_bound`` (``distance_m`` is a bound the true distance does not
exceed; ``reason`` says why) or ``missing`` (no distance; ``reason`` says why); ``cut`` names
the image edges that cut the box (``bottom``, ``left+bottom``, ...; empty when none or when
the image size is unknown)."""

DEFAULT_RECORD_FIELDS = (
    "frame",
    "timestamp_s",
    "track_id",
    "class",
    "left",
    "top",
    "right",
    "bottom",
    "distance_m",
    "sigma_m",
    "reference",
    "status",
    "reason",
    "speed_mps",
    "ttc_s",
)
"""Columns of ``records.csv`` by default (:attr:`RecordColumns.DEFAULT`), in order: what a
user acts on; ``gt_distance_m`` follows when the boxes carry a truth. ``sigma_m``,
``speed_mps`` and ``ttc_s`` are empty for a method that states none. The schema table of
``docs/usage.md`` ("Columns of ``records.csv``") lists them."""

OWN_TRACK_KEY = "track_uid"
"""The estimates' column of a method's own track number (``ours``'s tracker)."""
METHOD_TRACK_COLUMN = "method_track_uid"
"""What the full records call :data:`OWN_TRACK_KEY`: the method's internal track number, which
starts anew when its tracker loses a vehicle (``track_id`` is the one to follow)."""


class RecordColumns(str, Enum):
    """Which columns the per-target records have (``--columns``)."""

    DEFAULT = "default"
    """:data:`DEFAULT_RECORD_FIELDS`: what a user acts on."""
    ALL = "all"
    """:data:`RECORD_FIELDS` and every extra column of the method (its diagnostics)."""


def parse_columns(value: str | RecordColumns) -> RecordColumns:
    """``value`` as :class:`RecordColumns`.

    Raises:
        ConfigurationError: neither ``default`` nor ``all``.
    """
    try:
        return RecordColumns(getattr(value, "value", value))
    except ValueError:
        names = [c.value for c in RecordColumns]
        raise ConfigurationError(unknown_choice("record columns", str(value), names)) from None


def user_track_ids(boxes: BoxTable, est: FrameEstimates) -> NDArray[np.int64]:
    """The track a user follows for each box: the box's own track id when it carries one
    (from the box file or the user's tracker), else the method's own track (``ours``), else
    :data:`~slopedist.io.detections.boxes.NO_TRACK`."""
    ids = np.array(boxes.track_id, dtype=np.int64)
    own = np.asarray(est.extra.get(OWN_TRACK_KEY, np.full(len(ids), np.nan)), dtype=float)
    unknown = (ids == NO_TRACK) & np.isfinite(own)
    ids[unknown] = own[unknown].astype(np.int64)
    return ids


def with_user_track_ids(boxes: BoxTable, est: FrameEstimates) -> BoxTable:
    """``boxes`` with the track ids of :func:`user_track_ids` (what ``tracks.csv`` and the
    overlay name the vehicles by)."""
    return replace(boxes, track_id=user_track_ids(boxes, est))


def record_fields(columns: RecordColumns, truth: bool) -> tuple[str, ...]:
    """The header of records of ``columns`` (the full set: before the method's extras), with
    ``gt_distance_m`` when the boxes carry a truth."""
    base = DEFAULT_RECORD_FIELDS if columns is RecordColumns.DEFAULT else RECORD_FIELDS
    return (*base, CSV_TRUTH_COLUMN) if truth else base


def iter_records(
    boxes: BoxTable,
    timestamps_s: float | Iterable[float] | NDArray[np.float64],
    est: FrameEstimates,
    method: str,
    columns: RecordColumns = RecordColumns.ALL,
) -> Iterator[dict[str, Any]]:
    """One dict per target, angles in degrees: :data:`RECORD_FIELDS` plus the method's extras
    (:attr:`RecordColumns.ALL`; its own track as :data:`METHOD_TRACK_COLUMN`) or
    :data:`DEFAULT_RECORD_FIELDS`. ``track_id`` is :func:`user_track_ids`'s.

    ``timestamps_s`` is the timestamp of the boxes' frame (seconds), or an array indexed by
    each box's frame number.
    """
    row_t = _row_timestamps(boxes, timestamps_s)
    track = user_track_ids(boxes, est)
    for i in range(len(boxes)):
        row = _full_record(boxes, est, i, float(row_t[i]), method)
        row["track_id"] = int(track[i])
        if columns is RecordColumns.DEFAULT:
            yield {k: row.get(k, math.nan) for k in DEFAULT_RECORD_FIELDS}
        else:
            yield row


def _full_record(
    boxes: BoxTable, est: FrameEstimates, i: int, t_s: float, method: str
) -> dict[str, Any]:
    """Record ``i`` of a frame with every column (:attr:`RecordColumns.ALL`)."""
    has_distance = est.status[i] != EstimateStatus.MISSING.value
    row: dict[str, Any] = {
        "frame": int(boxes.frame[i]),
        "timestamp_s": t_s,
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
        "distance_m": float(est.distance_m[i]) if has_distance else math.nan,
        "reference": est.reference[i],
        "status": est.status[i],
        "reason": est.reason[i],
        "cut": est.cut[i],
    }
    for key, values in est.extra.items():
        row[METHOD_TRACK_COLUMN if key == OWN_TRACK_KEY else key] = float(values[i])
    return row


def frame_records(
    boxes: BoxTable,
    timestamp_s: float,
    est: FrameEstimates,
    method: str,
    columns: RecordColumns = RecordColumns.ALL,
) -> list[dict[str, Any]]:
    """The records of one frame as ``records.csv`` has them (:func:`iter_records`, of
    ``columns``), with the ground-truth distance
    (:data:`~slopedist.io.detections.readers.CSV_TRUTH_COLUMN`, metres) when the boxes carry
    it: what ``slopedist run`` writes and :meth:`slopedist.FrameResult.to_records` gives."""
    rows = list(iter_records(boxes, timestamp_s, est, method, columns))
    truth = boxes.extra.get(CSV_TRUTH_COLUMN)
    if truth is not None:
        for row, g in zip(rows, truth, strict=True):
            row[CSV_TRUTH_COLUMN] = float(g)
    return rows


def _row_timestamps(
    boxes: BoxTable, timestamps_s: float | Iterable[float] | NDArray[np.float64]
) -> NDArray[np.float64]:
    """Timestamp of every box's frame (NaN for a frame beyond ``timestamps_s``)."""
    if isinstance(timestamps_s, (float, int)):
        return np.full(len(boxes), float(timestamps_s))
    ts = np.asarray(
        list(timestamps_s) if not isinstance(timestamps_s, np.ndarray) else timestamps_s,
        dtype=float,
    )
    inside = boxes.frame < ts.size
    out = np.full(len(boxes), np.nan)
    out[inside] = ts[boxes.frame[inside]]
    return out


def open_records(path: str | Path | None, fields: Sequence[str] | None = None) -> CsvStreamWriter:
    """The per-target records CSV (:data:`RECORD_FIELDS`, then the method's extra columns) at
    ``path`` (parents created; None or ``-``: standard output), written frame by frame.

    The header is ``fields`` when given, otherwise the keys of the first record; close with
    :func:`close_records` so that a run without any target still writes its header.
    """
    if path is None or str(path) == STDOUT_PATH:
        return CsvStreamWriter(sys.stdout, fields)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return CsvStreamWriter.open(path, fields)


def close_records(
    writer: CsvStreamWriter, columns: RecordColumns = RecordColumns.ALL, truth: bool = False
) -> None:
    """Close a records CSV, writing the header alone (:func:`record_fields` of ``columns``) if
    no record was written."""
    if writer.fields is None:
        writer.write_header(record_fields(columns, truth))
    writer.close()
