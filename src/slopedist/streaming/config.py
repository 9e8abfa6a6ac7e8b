"""What configures a run and what it reports: output names, :class:`RunConfig`,
:class:`RunResult` (``run.json``) and the per-frame log's columns (:data:`FRAME_FIELDS`).

The loop itself is :func:`slopedist.streaming.loop.run_frames`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

from slopedist.core.errors import SlopedistError
from slopedist.estimators.base import ReferencePoint
from slopedist.estimators.references import DEFAULT_REFERENCE
from slopedist.io.depth.base import DepthSource
from slopedist.io.detections.boxes import DEFAULT_VEHICLE_CLASSES
from slopedist.io.outputs import StopFlag, partial_path
from slopedist.io.prefetch import DEFAULT_AHEAD
from slopedist.odometry.base import LOOKBACK_S
from slopedist.streaming.step import RecordColumns
from slopedist.streaming.tracks import TRACKS_NAME

RECORDS_NAME = "records.csv"
FRAMES_NAME = "frames.csv"
SUMMARY_NAME = "run.json"
MCAP_NAME = "run.mcap"
TRAJECTORY_NAME = "trajectory.tum"


def summary_method(summary: Any) -> str:
    """The method a run's summary (``run.json``, parsed) names; empty when it names none (the
    records of the default columns do not name it: their run's summary does)."""
    method = summary.get("method") if isinstance(summary, dict) else None
    return method if isinstance(method, str) else ""


SNAPSHOT_QUALITY = 92
"""JPEG quality of a snapshot image (``run --snapshot``)."""


def snapshot_path(out_dir: Path, frame_index: int) -> Path:
    """``OUT/snapshot_NNNNNN.jpg``: the overlay of one frame as a JPEG (``run --snapshot``)."""
    return out_dir / f"snapshot_{frame_index:06d}.jpg"


class RunExport(str, Enum):
    """Optional outputs for viewers (``slopedist run --export``)."""

    MCAP = "mcap"
    """``run.mcap``: images, boxes, distances and θ with Foxglove schemas."""
    TUM = "tum"
    """``trajectory.tum``: the rotation source's camera-to-world rotations (TUM layout)."""


def export_paths(
    out_dir: Path, exports: Iterable[str | RunExport]
) -> tuple[Path | None, Path | None]:
    """``(OUT/run.mcap, OUT/trajectory.tum)`` for the :class:`RunExport` values in ``exports``
    (None for one not asked for)."""
    wanted = {RunExport(e) for e in exports}
    mcap = out_dir / MCAP_NAME if RunExport.MCAP in wanted else None
    return mcap, out_dir / TRAJECTORY_NAME if RunExport.TUM in wanted else None


class OverlayFormat(str, Enum):
    """How the annotated frames are written (``slopedist run --overlay-format``)."""

    MP4 = "mp4"
    """One video, ``OUT/overlay.mp4``."""
    PNG = "png"
    """One PNG file per frame in ``OUT/overlay/``."""


def overlay_path(out_dir: Path, fmt: str | OverlayFormat) -> Path:
    """Where the overlay of format ``fmt`` goes in ``out_dir`` (:class:`OverlayFormat`)."""
    return out_dir / ("overlay.mp4" if OverlayFormat(fmt) is OverlayFormat.MP4 else "overlay")


def earlier_outputs(out_dir: Path, written: Iterable[str | Path | None]) -> list[Path]:
    """The optional outputs in ``out_dir`` that a run did not write (``written``: its overlay
    and exports, as in :class:`RunResult`): an overlay video or folder, ``run.mcap``,
    ``trajectory.tum`` and snapshot JPEGs left by an earlier run into the same folder, which
    no longer match its records, and the files an earlier run that stopped left under their
    temporary names (:func:`~slopedist.io.outputs.partial_path`)."""
    kept = {Path(p) for p in written if p is not None}
    candidates = [overlay_path(out_dir, f) for f in OverlayFormat]
    candidates += [out_dir / MCAP_NAME, out_dir / TRAJECTORY_NAME]
    candidates += [partial_path(p) for p in candidates]
    tables = (RECORDS_NAME, FRAMES_NAME, TRACKS_NAME, SUMMARY_NAME)
    candidates += [partial_path(out_dir / name) for name in tables]
    candidates += sorted(out_dir.glob("snapshot_[0-9]*.jpg"))
    return [p for p in candidates if p.exists() and p not in kept]


def overlay_fps(fps: float | None, source: object) -> float:
    """Frame rate of an MP4 overlay: ``fps`` (``--fps``), else a video's own rate, else 10."""
    return fps or float(getattr(source, "container_fps", 0.0) or 0.0) or 10.0


FRAME_FIELDS = (
    "frame",
    "timestamp_s",
    "source",
    "frame_status",
    "detail",
    "odometry_state",
    "inliers",
    "segment",
    "theta_deg",
    "boxes",
    "estimated",
    "odometry_ms",
    "estimation_ms",
    "depth_ms",
    "detection_ms",
)
"""Columns of ``frames.csv``. ``odometry_state`` is empty for frames without pixels or without
odometry, ``odometry_jump`` for a rotation that is an odometry jump
(:data:`~slopedist.odometry.jumps.JUMP_STATE`); ``theta_deg`` is the ego road gradient (eq. 4)
and empty without a rotation;
``depth_ms`` is empty where no depth map was made; ``detection_ms`` (the detector's pre-processing,
inference and post-processing) is empty without a detector."""

GENERIC_FOLDER_NAMES = frozenset(
    {
        "image_0",
        "image_1",
        "image_2",
        "image_3",
        "image_00",
        "image_01",
        "image_02",
        "image_03",
        "image_l",
        "image_r",
        "images",
        "image",
        "frames",
        "data",
        "rgb",
        "img",
    }
)
"""Frame folder names that say nothing about the sequence (KITTI layouts, ``simulate``
output); :func:`default_sequence_name` takes the parent folder's name instead."""


def default_sequence_name(frames_path: str | Path) -> str:
    """Sequence name of a frame source: a video's file name without its ending, or the image
    folder's name; for generic folder names (:data:`GENERIC_FOLDER_NAMES`, e.g.
    ``drive_0001_sync/image_02/data``) the nearest parent with a specific name."""
    path = Path(frames_path).absolute()
    if path.is_file():
        return path.stem
    for part in (path, *path.parents):
        if part.name and part.name.lower() not in GENERIC_FOLDER_NAMES:
            return part.name
    return path.name or "sequence"


class RunAbortedError(SlopedistError):
    """A run stopped part-way; what was written before the failing frame is kept."""

    def __init__(self, message: str, frame: int | None, records_path: Path) -> None:
        self.frame = frame
        self.records_path = records_path
        super().__init__(message)


@dataclass
class RunResult:
    """Summary of a run (also written to ``run.json``).

    Attributes:
        out_dir: output folder.
        method: estimator name.
        sequence: the sequence the frames belong to (Table 1 row of ``slopedist report``).
        frames: frames seen; ``frame_status``: count per :class:`~slopedist.io.frames.FrameStatus`.
        odometry_states: count per odometry state (frames with pixels only; a jump frame's
            is ``odometry_jump``).
        records: per-target rows written; ``estimated``: rows with status ``ok``;
            ``upper_bounds``: rows with status ``upper_bound`` (e.g. boxes cut by the bottom
            of the image); ``not_vehicles``: rows of classes that are not vehicles;
            ``not_vehicle_classes``: those rows per class name (a detector's class id ``2``
            or a name such as ``vehicle`` that ``--vehicle-classes`` lacks shows here).
        dropped_boxes: rows of the box file its reader left out, ``{reason: rows}``
            (:class:`~slopedist.io.detections.dropped.DroppedBoxes`; e.g. COCO categories that are
            not vehicles); empty when none were.
        boxes_without_frame: boxes whose frame index never came from the frame source, or
            came as an unreadable frame whose time does not follow the frame before it (of a
            run stopped early: of the frames up to the last it completed).
        elapsed_s: wall time of the loop; ``frames_per_s``: frames / elapsed_s.
        odometry_ms_mean / estimation_ms_mean: mean time per frame, milliseconds (of an
            offline method, its pass over the drive at the end included, spread over the
            frames).
        depth_ms_mean: mean time per depth map (read or inference), milliseconds.
        depth_source: what the depth maps came from (e.g. ``"file read: DIR"``), or None.
        detector: the detector's model file when boxes came from a detector, or None.
        detection_ms_mean: mean detection time per frame, milliseconds.
        frames_without_depth: frames with boxes for which the depth source had no map.
        ground_truth: whether ``records.csv`` carries ``gt_distance_m``.
        reference: the point of the vehicle every ``distance_m`` was moved to
            (:class:`~slopedist.estimators.base.ReferencePoint` value; the records'
            ``reference`` column says it row by row), None: each method's own point.
        columns: the columns of ``records.csv`` (``default`` or ``all``).
        overlay: overlay path, or None; ``exports``: the MCAP / TUM files and snapshot images
            written.
        overlay_codec: what the overlay is written as (``h264 (libx264)``, ``mp4v``, ``png``:
            :func:`~slopedist.io.overlay.video_codec`), None without one;
            ``overlay_warning``: why an MP4 overlay is not H.264 (browsers do not play it), or
            None.
        complete: whether every frame was processed.
        last_complete_frame: index of the last frame whose rows are all written (None: none).
        error: why the run stopped early, or None; ``failed_frame``: the frame it stopped at
            (its rows are not written; None for a stop request, which ends between frames).
    """

    out_dir: str
    method: str
    sequence: str = ""
    frames: int = 0
    frame_status: dict[str, int] = field(default_factory=dict)
    odometry_states: dict[str, int] = field(default_factory=dict)
    records: int = 0
    estimated: int = 0
    upper_bounds: int = 0
    not_vehicles: int = 0
    not_vehicle_classes: dict[str, int] = field(default_factory=dict)
    dropped_boxes: dict[str, int] = field(default_factory=dict)
    boxes_without_frame: int = 0
    elapsed_s: float = 0.0
    frames_per_s: float = 0.0
    odometry_ms_mean: float = math.nan
    estimation_ms_mean: float = math.nan
    depth_ms_mean: float = math.nan
    depth_source: str | None = None
    detector: str | None = None
    detection_ms_mean: float = math.nan
    frames_without_depth: int = 0
    ground_truth: bool = False
    reference: str | None = None
    columns: str = RecordColumns.DEFAULT.value
    overlay: str | None = None
    overlay_codec: str | None = None
    overlay_warning: str | None = None
    exports: list[str] = field(default_factory=list)
    complete: bool = False
    last_complete_frame: int | None = None
    error: str | None = None
    failed_frame: int | None = None


class RunningMean:
    """Running mean in constant memory."""

    def __init__(self) -> None:
        self.total = 0.0
        self.count = 0

    def add(self, value: float) -> None:
        self.total += value
        self.count += 1

    def mean(self) -> float:
        return self.total / self.count if self.count else math.nan


def describe_depth(depth: DepthSource) -> str:
    """``"<kind>: <folder or model file>"`` of a depth source, for ``run.json``."""
    where = getattr(depth, "folder", None)
    model = getattr(depth, "model", None)
    if where is None and model is not None:
        where = getattr(getattr(model, "config", None), "model_path", None)
    return f"{depth.kind}: {where}" if where is not None else depth.kind


@dataclass(frozen=True)
class RunConfig:
    """Where and how a run writes (the inputs are the arguments of :func:`run_frames`).

    Attributes:
        out_dir: output folder (created).
        lookback_s: look-back of the ego gradient, seconds.
        overlay: None, a folder for annotated PNG frames, or a ``.mp4`` path.
        overlay_fps: frame rate of an MP4 overlay.
        progress: show a progress bar on stderr.
        sequence: sequence name written to ``run.json`` (None:
            :func:`default_sequence_name` of the frames).
        mcap: path of an MCAP export (:class:`~slopedist.streaming.mcap_export.McapExportWriter`),
        or None.
        trajectory: path of a TUM trajectory of the rotation source's rotations, or None.
        time_origin_ns: log time of frame time 0 in the MCAP export, nanoseconds (a drive log's
            first image stamp, so the export plays in sync with the log).
        ego_speed: the ego speed (m/s) at a frame time (s), for the headway time of
            ``tracks.csv``; None when unknown.
        vehicle_classes: class names scored as vehicles (other boxes: ``missing``,
            ``not_a_vehicle``).
        reference: the point of the vehicle every method's distances are moved to
            (:data:`~slopedist.estimators.references.DEFAULT_REFERENCE`, the nearest face,
            unless told otherwise); None: each method's own point.
        stop: checked after every frame; once its ``signum`` is set the run ends there
            (:func:`~slopedist.io.outputs.stop_on_signals`), raising :class:`RunAbortedError` from
            :class:`RunStoppedError`.
        snapshots: frame indices whose overlay is also written as a JPEG
            (:func:`snapshot_path`), with or without ``overlay``.
        decode_ahead: frames decoded ahead in a background thread
            (:class:`~slopedist.io.prefetch.PrefetchedFrames`; a second core decodes while the
            odometry works), and overlay frames queued for drawing and encoding in another
            (:class:`~slopedist.io.prefetch.BackgroundOverlay`); 0: all in the loop's thread.
        columns: the columns of ``records.csv`` (``--columns``: what a user acts on, or all
            with the method's diagnostics).
    """

    out_dir: Path
    lookback_s: float = LOOKBACK_S
    overlay: Path | None = None
    overlay_fps: float = 10.0
    progress: bool = True
    sequence: str | None = None
    mcap: Path | None = None
    trajectory: Path | None = None
    time_origin_ns: int = 0
    ego_speed: Callable[[float], float] | None = None
    vehicle_classes: tuple[str, ...] = DEFAULT_VEHICLE_CLASSES
    reference: ReferencePoint | None = DEFAULT_REFERENCE
    stop: StopFlag = field(default_factory=StopFlag)
    decode_ahead: int = DEFAULT_AHEAD
    snapshots: tuple[int, ...] = ()
    columns: RecordColumns = RecordColumns.DEFAULT
