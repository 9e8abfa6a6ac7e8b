"""From frames to distances: the streaming run behind ``slopedist run``.

For every frame, in order: the visual odometry gets the grey image (with the frame's boxes
masked out of its features) and returns a camera rotation; :class:`~slopedist.pipeline.
StreamingEstimator` turns rotation and boxes into per-target estimates; the records are written
and flushed at once. Memory holds one frame, the odometry's own state and the one-second
look-back, whatever the length of the input.

Outputs under the output folder:

- ``records.csv``: one row per target (the columns of ``slopedist estimate``,
  :data:`~slopedist.pipeline.RECORD_FIELDS`), plus ``gt_distance_m`` (metres) when the boxes
  carry a ground-truth distance (the optional column of the box CSV), so that
  ``slopedist report`` can score the run.
- ``frames.csv``: one row per frame (:data:`FRAME_FIELDS`): frame status, odometry state,
  inliers and segment (restarts of the odometry; θ never looks back across one), ego gradient
  θ (degrees), number of boxes and of estimated distances, odometry, estimation and depth time
  (ms; ``depth_ms`` = reading or inferring the frame's depth map, for depth-map methods, on
  frames with boxes).
- ``run.json``: a summary (:class:`RunResult`), also written when the run stops on an error;
  its ``"sequence"`` names the sequence, so that the report lines up runs of different methods
  on one sequence.
- optionally an overlay (PNG folder or MP4, :func:`slopedist.viz.draw_fig3_overlay`).

Convention: θ in radians inside, degrees in the CSV files; timestamps in seconds.
"""

from __future__ import annotations

import csv
import json
import math
import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import IO, Any

import cv2
import numpy as np
from tqdm import tqdm

from slopedist.camera import Camera
from slopedist.depth.base import DepthSource
from slopedist.detections.boxes import BoxTable
from slopedist.detections.readers import CSV_TRUTH_COLUMN
from slopedist.errors import ConfigurationError, SlopedistError
from slopedist.estimators.base import Estimator
from slopedist.io.frames import Frame, FrameSource, check_calibration
from slopedist.io.overlay import OverlayWriter
from slopedist.odometry.base import LOOKBACK_S, RotationOdometry
from slopedist.pipeline import EgoGradientTracker, RecordWriter, StreamingEstimator, iter_records
from slopedist.viz import draw_fig3_overlay

RECORDS_NAME = "records.csv"
FRAMES_NAME = "frames.csv"
SUMMARY_NAME = "run.json"

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
)
"""Columns of ``frames.csv``. ``odometry_state`` is empty for frames without pixels or without
odometry; ``theta_deg`` is the ego road gradient (eq. 4) and empty without a rotation;
``depth_ms`` is empty where no depth map was made."""

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
        odometry_states: count per odometry state (frames with pixels only).
        records: per-target rows written; ``estimated``: rows with a distance.
        boxes_without_frame: boxes whose frame index never came from the frame source.
        elapsed_s: wall time of the loop; ``frames_per_s``: frames / elapsed_s.
        odometry_ms_mean / estimation_ms_mean: mean time per frame, milliseconds.
        depth_ms_mean: mean time per depth map (read or inference), milliseconds.
        depth_source: what the depth maps came from (e.g. ``"file read: DIR"``), or None.
        frames_without_depth: frames with boxes for which the depth source had no map.
        ground_truth: whether ``records.csv`` carries ``gt_distance_m``.
        overlay: overlay path, or None.
        error: why the run stopped early, or None; ``failed_frame``: its frame index.
    """

    out_dir: str
    method: str
    sequence: str = ""
    frames: int = 0
    frame_status: dict[str, int] = field(default_factory=dict)
    odometry_states: dict[str, int] = field(default_factory=dict)
    records: int = 0
    estimated: int = 0
    boxes_without_frame: int = 0
    elapsed_s: float = 0.0
    frames_per_s: float = 0.0
    odometry_ms_mean: float = math.nan
    estimation_ms_mean: float = math.nan
    depth_ms_mean: float = math.nan
    depth_source: str | None = None
    frames_without_depth: int = 0
    ground_truth: bool = False
    overlay: str | None = None
    error: str | None = None
    failed_frame: int | None = None

    def as_dict(self) -> dict[str, Any]:
        return {
            k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in asdict(self).items()
        }


class _FrameLog:
    """``frames.csv`` writer (flushes every row)."""

    def __init__(self, path: Path) -> None:
        self._fh: IO[str] = path.open("w", newline="")
        self._writer = csv.DictWriter(self._fh, fieldnames=FRAME_FIELDS)
        self._writer.writeheader()
        self._fh.flush()

    def write(self, row: dict[str, Any]) -> None:
        self._writer.writerow({k: _fmt(v) for k, v in row.items()})
        self._fh.flush()

    def close(self) -> None:
        self._fh.close()


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


def _fmt(value: Any) -> Any:
    if isinstance(value, float):
        return "" if not math.isfinite(value) else f"{value:.6g}"
    return value


def describe_depth(depth: DepthSource) -> str:
    """``"<kind>: <folder or model file>"`` of a depth source, for ``run.json``."""
    where = getattr(depth, "folder", None)
    model = getattr(depth, "model", None)
    if where is None and model is not None:
        where = getattr(getattr(model, "config", None), "model_path", None)
    return f"{depth.kind}: {where}" if where is not None else depth.kind


def run_frames(
    frames: FrameSource,
    camera: Camera,
    boxes: BoxTable,
    odometry: RotationOdometry | None,
    estimator: Estimator,
    out_dir: str | Path,
    *,
    lookback_s: float = LOOKBACK_S,
    overlay: str | Path | None = None,
    overlay_fps: float = 10.0,
    progress: bool = True,
    sequence: str | None = None,
    depth: DepthSource | None = None,
) -> RunResult:
    """Run the whole pipeline on ``frames``, writing as it goes (see the module docstring).

    Args:
        frames: image folder or video (:func:`slopedist.io.frames.open_frames`).
        camera: calibration of the frames (checked against the frame size first).
        boxes: boxes of every frame, by frame index; a ``gt_distance_m`` column (metres) is
            copied into ``records.csv``.
        odometry: rotation source fed every readable frame, or None (no rotations: for methods
            that do not use them, e.g. ``flat`` and ``depthmap``).
        estimator: distance method.
        out_dir: output folder (created).
        lookback_s: look-back of the ego gradient, seconds.
        overlay: None, a folder for annotated PNG frames, or a ``.mp4`` path.
        overlay_fps: frame rate of an MP4 overlay.
        progress: show a progress bar on stderr.
        sequence: sequence name written to ``run.json`` (None:
            :func:`default_sequence_name` of the frames).
        depth: depth maps for a method that ``needs_depth`` (asked for every readable frame
            with boxes; a frame without a map gives its targets the reason ``no_depth``).

    Raises:
        ConfigurationError: a depth-map method without ``depth``, or ``depth`` for a method
            that does not use it (before anything is written).
        DataMismatchError: calibration that does not fit the frames (before anything is written).
        RunAbortedError: an error part-way; ``records.csv`` / ``frames.csv`` keep every frame before
            the failing one and ``run.json`` says where it stopped.
    """
    if estimator.needs_depth and depth is None:
        raise ConfigurationError(
            f"method '{estimator.name}' needs depth maps (a depth folder or an ONNX depth model)"
        )
    if depth is not None and not estimator.needs_depth:
        raise ConfigurationError(
            f"depth maps were given, but method '{estimator.name}' does "
            "not use them (use the depthmap method)"
        )
    out = Path(out_dir)
    width, height = frames.frame_size()
    check_calibration(camera, width, height, str(frames.path))
    out.mkdir(parents=True, exist_ok=True)
    records_path = out / RECORDS_NAME
    has_truth = CSV_TRUTH_COLUMN in boxes.extra
    result = RunResult(
        str(out),
        estimator.name,
        sequence=sequence if sequence else default_sequence_name(frames.path),
        overlay=str(overlay) if overlay else None,
        ground_truth=has_truth,
        depth_source=describe_depth(depth) if depth is not None else None,
    )
    by_frame = boxes.frame_index()
    seen_box_frames: set[int] = set()
    empty = boxes.select(np.zeros(len(boxes), dtype=bool))
    stream = StreamingEstimator(estimator, lookback_s)
    gradient = EgoGradientTracker(camera.mount_angle_rad, lookback_s)
    status_count: Counter[str] = Counter()
    odo_count: Counter[str] = Counter()
    times = {"odometry": RunningMean(), "estimation": RunningMean(), "depth": RunningMean()}
    writer = RecordWriter.open(records_path)
    log = _FrameLog(out / FRAMES_NAME)
    painter = OverlayWriter(overlay, overlay_fps) if overlay else None
    bar = tqdm(
        total=frames.expected_frames(),
        unit="frame",
        disable=not progress,
        dynamic_ncols=True,
        desc="slopedist run",
    )
    start = time.perf_counter()
    frame: Frame | None = None
    last_segment = 0
    try:
        for frame in frames:
            k = frame.index
            frame_boxes = by_frame.get(k, empty)
            if k in by_frame:
                seen_box_frames.add(k)
            status_count[frame.status.value] += 1
            R = None
            odo_state, inliers, t_odo = "", 0, math.nan
            if frame.image is not None and odometry is not None:
                gray = np.asarray(cv2.cvtColor(frame.image, cv2.COLOR_BGR2GRAY), dtype=np.uint8)
                t0 = time.perf_counter()
                res = odometry.process(gray, frame.timestamp_s, frame_boxes.boxes)
                # a backend that waits on purpose (ORB-SLAM3's real-time pacing) reports its
                # own working time
                t_odo = getattr(odometry, "last_track_ms", (time.perf_counter() - t0) * 1e3)
                times["odometry"].add(t_odo)
                R = res.R_world_cam
                odo_state, inliers = res.state.value, int(res.inliers)
                odo_count[odo_state] += 1
                segment = getattr(res, "segment", 0)
                if segment != last_segment:  # the backend restarted: no look-back across
                    gradient = EgoGradientTracker(camera.mount_angle_rad, lookback_s)
                    stream.gradient = EgoGradientTracker(camera.mount_angle_rad, lookback_s)
                    last_segment = segment
            theta = gradient.update(frame.timestamp_s, R)
            depth_m, t_depth = None, math.nan
            if depth is not None and frame.image is not None and len(frame_boxes):
                t0 = time.perf_counter()
                depth_m = depth.depth(k, frame.image)
                t_depth = (time.perf_counter() - t0) * 1e3
                times["depth"].add(t_depth)
                result.frames_without_depth += int(depth_m is None)
            t0 = time.perf_counter()
            est = stream.update(k, frame.timestamp_s, R, frame_boxes, frame.image, depth_m)
            t_est = (time.perf_counter() - t0) * 1e3
            times["estimation"].add(t_est)
            rows = list(
                iter_records(
                    frame_boxes, np.broadcast_to(frame.timestamp_s, (k + 1,)), est, estimator.name
                )
            )
            if has_truth:
                for row, g in zip(rows, frame_boxes.extra[CSV_TRUTH_COLUMN]):
                    row[CSV_TRUTH_COLUMN] = float(g)
            writer.write(rows)
            n_est = int(np.sum(est.reason == ""))
            result.records += len(rows)
            result.estimated += n_est
            log.write(
                {
                    "frame": k,
                    "timestamp_s": frame.timestamp_s,
                    "source": frame.source,
                    "frame_status": frame.status.value,
                    "detail": frame.detail,
                    "odometry_state": odo_state,
                    "inliers": inliers,
                    "segment": last_segment,
                    "theta_deg": math.degrees(theta),
                    "boxes": len(frame_boxes),
                    "estimated": n_est,
                    "odometry_ms": t_odo,
                    "estimation_ms": t_est,
                    "depth_ms": t_depth,
                }
            )
            if painter is not None:
                if frame.image is not None:
                    head = (
                        f"frame {k}  theta {math.degrees(theta):+.2f} deg"
                        if math.isfinite(theta)
                        else f"frame {k}  no rotation ({odo_state or 'no odometry'})"
                    )
                    painter.write(
                        k, draw_fig3_overlay(frame.image, camera, frame_boxes, est, theta, head)
                    )
                else:
                    painter.write_placeholder(k, f"frame {k}: {frame.status.value}")
            result.frames += 1
            bar.update(1)
    except (Exception, KeyboardInterrupt) as exc:
        where = f"frame {frame.index} ({frame.source})" if frame is not None else "the first frame"
        result.error = f"{type(exc).__name__}: {exc}"
        result.failed_frame = frame.index if frame is not None else None
        _finish(result, start, status_count, odo_count, times, by_frame, seen_box_frames)
        _close(writer, log, painter, bar, out, result)
        if isinstance(exc, (SlopedistError, OSError)):
            raise RunAbortedError(
                f"run stopped at {where}: {exc}. The records of the {result.frames} frames "
                f"before it are in {records_path} (per-frame log {out / FRAMES_NAME})",
                result.failed_frame,
                records_path,
            ) from exc
        raise
    _finish(result, start, status_count, odo_count, times, by_frame, seen_box_frames)
    _close(writer, log, painter, bar, out, result)
    return result


def _finish(
    result: RunResult,
    start: float,
    status_count: Counter[str],
    odo_count: Counter[str],
    times: dict[str, RunningMean],
    by_frame: dict[int, BoxTable],
    seen: set[int],
) -> None:
    result.elapsed_s = time.perf_counter() - start
    result.frames_per_s = result.frames / result.elapsed_s if result.elapsed_s > 0 else math.nan
    result.frame_status = dict(status_count)
    result.odometry_states = dict(odo_count)
    result.odometry_ms_mean = times["odometry"].mean()
    result.estimation_ms_mean = times["estimation"].mean()
    result.depth_ms_mean = times["depth"].mean()
    result.boxes_without_frame = sum(len(b) for k, b in by_frame.items() if k not in seen)


def _close(
    writer: RecordWriter,
    log: _FrameLog,
    painter: OverlayWriter | None,
    bar: tqdm,
    out: Path,
    result: RunResult,
) -> None:
    bar.close()
    writer.close()
    log.close()
    if painter is not None:
        painter.close()
    (out / SUMMARY_NAME).write_text(json.dumps(result.as_dict(), indent=2) + "\n")
