"""From frames to distances: the streaming run behind ``slopedist run``.

For every frame, in order: its boxes come from the box file or from a detector run on its
pixels (:class:`~slopedist.io.detections.onnx_detector.Detector`); the
:class:`~slopedist.streaming.pipeline.Pipeline` turns the frame and its boxes into θ and
per-target estimates (its visual odometry gets the grey image, with the frame's boxes masked out
of its features, and it never looks back across a restart of the odometry); the records are
written and flushed at once. Memory holds one frame, the odometry's own state and the one-second
look-back, whatever the length of the input.

Outputs under the output folder:

- ``records.csv``: one row per target (the columns of ``slopedist estimate``,
  :data:`~slopedist.streaming.step.RECORD_FIELDS`), plus ``gt_distance_m`` (metres) when the boxes
  carry a ground-truth distance (the optional column of the box CSV), so that
  ``slopedist report`` can score the run.
- ``frames.csv``: one row per frame (:data:`FRAME_FIELDS`): frame status, odometry state,
  inliers and segment (restarts of the odometry; θ never looks back across one), ego gradient
  θ (degrees), number of boxes and of estimated distances, odometry, estimation and depth time
  (ms; ``depth_ms`` = reading or inferring the frame's depth map, for depth-map methods, on
  frames with boxes).
- ``tracks.csv``: one row per track (:mod:`slopedist.streaming.tracks`): first and last time,
closest
  distance, smallest TTC, TTC events.
- ``run.json``: a summary (:class:`RunResult`), also written when the run stops on an error;
  its ``"sequence"`` names the sequence, so that the report lines up runs of different methods
  on one sequence.
- optionally an overlay (PNG folder or H.264 MP4,
:func:`slopedist.streaming.drawing.draw_fig3_overlay`),
  an MCAP export for Foxglove (:mod:`slopedist.streaming.mcap_export`) and the rotation source's
  trajectory as a TUM file (camera-to-world, translation 0; for ``evo_traj`` / ``evo_ape``).

Crash safety (:mod:`slopedist.io.outputs`): the output folder is locked for the run (a second
run into it is refused); the tables are written in whole frames (a full disk cuts a file back to
its last whole frame, never leaving a torn row or NUL bytes) under temporary names
(``records.partial.csv``, ``frames.partial.csv``, ``overlay.partial.mp4`` /
``overlay.partial/``, ``snapshot_NNNNNN.partial.jpg``), renamed when the run ends. A complete
run always takes the final names; a run that stops early (an error, a full disk, a stop request:
:func:`stop_on_signals`, SIGTERM/SIGINT stop it after the current frame) takes them only when
the folder holds no complete earlier run, which otherwise stays as it is, the stopped run's
files keeping their temporary names beside it (its summary ``run.partial.json``). After a kill
that leaves no chance to finish (SIGKILL, power loss) the previous run is intact and the
``.partial`` files mark the new one as partial. ``run.json`` is written last, through a
temporary name; the previous one is removed before the new files take their names, so it never
describes other records.

Convention: θ in radians inside, degrees in the CSV files; timestamps in seconds.
"""

from __future__ import annotations

import functools
import logging
import math
import time
from collections import Counter
from collections.abc import Mapping
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from slopedist.core.errors import ConfigurationError, SlopedistError
from slopedist.estimators.base import EstimateStatus, Estimator, FrameEstimates, MissingReason
from slopedist.io.depth.base import DepthSource
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.onnx_detector import Detector
from slopedist.io.detections.readers import CSV_TRUTH_COLUMN
from slopedist.io.formatting import CsvStreamWriter
from slopedist.io.frames import Frame, FrameSource, check_box_frames, check_calibration
from slopedist.io.intrinsics import in_frame_pixels
from slopedist.io.outputs import (
    OutputFiles,
    OutputFolder,
    OutputWriteError,
    RunStoppedError,
    partial_path,
    write_image,
)
from slopedist.io.overlay import OverlayWriter, video_fallback_note
from slopedist.io.prefetch import (
    BackgroundOverlay,
    OverlaySink,
    PrefetchedFrames,
    loop_threads,
    opencv_threads,
)
from slopedist.odometry.base import RotationOdometry
from slopedist.odometry.jumps import shown_state
from slopedist.odometry.posefiles import TumPoseWriter
from slopedist.streaming.config import (
    FRAME_FIELDS,
    FRAMES_NAME,
    RECORDS_NAME,
    SNAPSHOT_QUALITY,
    SUMMARY_NAME,
    RunAbortedError,
    RunConfig,
    RunningMean,
    RunResult,
    default_sequence_name,
    describe_depth,
    snapshot_path,
)
from slopedist.streaming.drawing import draw_fig3_overlay, lead_index
from slopedist.streaming.mcap_export import McapExportWriter
from slopedist.streaming.pipeline import FinishResult, FrameResult, OdometryOutput, Pipeline
from slopedist.streaming.step import close_records, frame_records, with_user_track_ids
from slopedist.streaming.tracks import TRACK_FIELDS, TRACKS_NAME, TrackSummaries

_log = logging.getLogger(__name__)


def run_frames(
    frames: FrameSource,
    boxes: BoxTable,
    odometry: RotationOdometry | None,
    estimator: Estimator,
    config: RunConfig,
    depth: DepthSource | None = None,
    detector: Detector | None = None,
    dropped_boxes: Mapping[str, int] | None = None,
) -> RunResult:
    """Run the whole pipeline on ``frames``, writing as it goes (see the module docstring).

    Args:
        frames: image folder or video (:func:`slopedist.io.frames.open_frames`).
        boxes: boxes of every frame, by frame index; a ``gt_distance_m`` column (metres) is
            copied into ``records.csv``.
        odometry: rotation source fed every readable frame, or None (no rotations: for methods
            that do not use them, e.g. ``flat`` and ``depthmap``).
        estimator: distance method; its camera is the frames' calibration (checked against the
            frame size first); a camera that knows the image size
            (:meth:`~slopedist.core.camera.Camera.with_image_size`, as ``slopedist run`` sets it)
            flags boxes cut by the image border and boxes outside it.
        config: output folder and options.
        depth: depth maps for a method that ``needs_depth`` (asked for every readable frame
            with boxes; a frame without a map gives its targets the reason ``no_depth``).
        detector: finds the boxes of every readable frame instead of ``boxes`` (which must then
            be empty); its boxes have no track ids (the estimator associates them).
        dropped_boxes: rows the box file's reader left out, ``{reason: rows}``, for
            ``run.json`` (:class:`~slopedist.io.detections.dropped.DroppedBoxes`).

    Raises:
        ConfigurationError: a depth-map method without ``depth``, or ``depth`` for a method
            that does not use it (before anything is written).
        DataMismatchError: calibration that does not fit the frames (before anything is written).
        RunAbortedError: an error part-way; ``records.csv`` / ``frames.csv`` keep every frame before
            the failing one and ``run.json`` says where it stopped.
    """
    check_depth_matches(estimator, depth)
    if detector is not None and len(boxes):
        raise ConfigurationError("give boxes or a detector, not both")
    width, height = frames.frame_size()
    check_calibration(estimator.camera, width, height, str(frames.path))
    check_box_frames(boxes.frame, frames)
    out = Path(config.out_dir)
    result = RunResult(
        str(out),
        estimator.name,
        sequence=config.sequence if config.sequence else default_sequence_name(frames.path),
        overlay=str(config.overlay) if config.overlay else None,
        ground_truth=CSV_TRUTH_COLUMN in boxes.extra,
        reference=config.reference.value if config.reference is not None else None,
        columns=config.columns.value,
        dropped_boxes=dict(dropped_boxes or {}),
        depth_source=describe_depth(depth) if depth is not None else None,
        exports=[str(p) for p in (config.mcap, config.trajectory) if p is not None],
        detector=str(getattr(detector, "model_path", type(detector).__name__))
        if detector
        else None,
    )
    if config.decode_ahead:
        frames = PrefetchedFrames(frames, config.decode_ahead)
    # with frames decoded ahead, the loop's OpenCV calls leave a core to the decoding thread
    # (never more threads than the caller allowed)
    threads = min(cv2.getNumThreads(), loop_threads(config.decode_ahead))
    with OutputFolder(out).lock(), opencv_threads(threads):
        loop = _RunLoop(boxes, odometry, estimator, depth, config, result, detector)
        result = loop.run(frames)
    for warning in loop.end.warnings if loop.end is not None else ():
        _log.warning("%s", warning)
    return result


def check_depth_matches(estimator: Estimator, depth: DepthSource | None) -> None:
    """Fail unless depth maps come exactly with a method that needs them."""
    if estimator.needs_depth and depth is None:
        raise ConfigurationError(
            f"method '{estimator.name}' needs depth maps (a depth folder or an ONNX depth model)"
        )
    if depth is not None and not estimator.needs_depth:
        raise ConfigurationError(
            f"depth maps were given, but method '{estimator.name}' does "
            "not use them (use the depthmap method)"
        )


class _RunLoop:
    """The state of one run: the frame step, the open outputs and the running counts."""

    def __init__(
        self,
        boxes: BoxTable,
        odometry: RotationOdometry | None,
        estimator: Estimator,
        depth: DepthSource | None,
        config: RunConfig,
        result: RunResult,
        detector: Detector | None = None,
    ) -> None:
        self.depth, self.config, self.result = depth, config, result
        self.detector = detector
        self.camera = estimator.camera
        self.method = estimator.name
        self.pipeline = Pipeline.from_parts(
            estimator,
            odometry,
            lookback_s=config.lookback_s,
            vehicle_classes=config.vehicle_classes,
            reference=config.reference,
        )
        self.held: list[int] | None = [] if estimator.offline else None
        """An offline method's frames with boxes (their indices), whose records wait for the
        end of the drive (:meth:`Pipeline.finish`)."""
        self.end: FinishResult | None = None
        """What the pipeline gave at the end (:meth:`finish`), once it ended."""
        self.by_frame = boxes.frame_lookup()
        self.no_boxes = boxes.select(np.zeros(len(boxes), dtype=bool))
        self.seen_box_frames: set[int] = set()
        self.last_time_s: float | None = None
        """Time (s) of the last frame given to the frame step; a frame source's unreadable
        frame of a stamp that does not increase comes at or before it."""
        self.status_count: Counter[str] = Counter()
        self.odometry_count: Counter[str] = Counter()
        self.times = {
            "odometry": RunningMean(),
            "estimation": RunningMean(),
            "depth": RunningMean(),
            "detection": RunningMean(),
        }
        out = Path(config.out_dir)
        extra_outputs = [p for p in (config.overlay, config.mcap, config.trajectory) if p]
        self.files = OutputFiles(
            out, (RECORDS_NAME, FRAMES_NAME, TRACKS_NAME), extra_outputs, whole_only=(TRACKS_NAME,)
        )
        self.files.reserve(SUMMARY_NAME)
        self.records = CsvStreamWriter(self.files.open_whole_rows(RECORDS_NAME))
        self.frame_log = CsvStreamWriter(self.files.open_whole_rows(FRAMES_NAME), FRAME_FIELDS)
        self.painter: OverlaySink | None = None
        if config.overlay:
            writer = OverlayWriter(partial_path(config.overlay), config.overlay_fps)
            result.overlay_codec = writer.codec
            result.overlay_warning = video_fallback_note() if writer.is_video else None
            self.painter = writer
            if config.decode_ahead:  # encoded behind the loop, in a thread
                self.painter = BackgroundOverlay(self.painter, config.decode_ahead)
        # an offline method's overlay and export show its causal pass, as the frames come: say so
        self.shown = f"{self.method} (causal pass)" if self.held is not None else self.method
        self.export = (
            McapExportWriter(partial_path(config.mcap), self.shown, config.time_origin_ns)
            if config.mcap
            else None
        )
        self.trajectory = (
            TumPoseWriter(partial_path(config.trajectory)) if config.trajectory else None
        )
        self.tracks = TrackSummaries()
        self.bar: tqdm | None = None
        self.summary_failed = ""
        self.offline_failed: SlopedistError | OSError | None = None
        """Why an offline method's records could not all be written at the end, or None."""
        self.offline_written = 0
        """How many of :attr:`held`'s frames have their offline records written."""
        self.offline_failed_frame = 0
        """The first frame whose offline records could not be written (with
        :attr:`offline_failed`)."""
        self.start = time.perf_counter()

    def run(self, frames: FrameSource) -> RunResult:
        """Every frame of ``frames``, then the summary (also after an error)."""
        self.bar = tqdm(
            total=frames.expected_frames(),
            unit="frame",
            disable=not self.config.progress,
            dynamic_ncols=True,
            desc="slopedist run",
        )
        frame: Frame | None = None
        try:
            for frame in frames:
                self.process(frame)
                self.result.last_complete_frame = frame.index
                self.bar.update(1)
                signum = self.config.stop.signum
                if signum is not None:
                    frame = None  # it is complete: the run ends between frames
                    raise RunStoppedError(signum)
        except (Exception, KeyboardInterrupt) as exc:
            self.result.error = f"{type(exc).__name__}: {exc}"
            self.result.failed_frame = frame.index if frame is not None else None
            self.finish()
            if isinstance(exc, (SlopedistError, OSError)):
                raise self._aborted(exc, frame) from exc
            raise
        self.result.complete = True
        self.finish()
        if self.offline_failed is not None:  # the frames all ran; their records did not
            raise RunAbortedError(
                f"run went through its {self.result.frames} frames (per-frame log "
                f"{self.files.where(FRAMES_NAME)}), but{self._offline_note()[1:]}"
                f"{self.summary_failed}{self.files.kept_note()}",
                self.result.failed_frame,
                self.files.where(RECORDS_NAME),
            ) from self.offline_failed
        if self.files.failed:  # the frames all ran; an output could not be written whole
            raise RunAbortedError(
                f"run went through its {self.result.frames} frames, but {self.files.failed}"
                f"{self.summary_failed}{self.files.kept_note()}",
                None,
                self.files.where(RECORDS_NAME),
            )
        return self.result

    def process(self, frame: Frame) -> None:
        """One frame: depth, the pipeline (odometry and frame step), then every output."""
        k = frame.index
        late = self._out_of_time(frame)  # logged; its boxes are not used (boxes_without_frame)
        frame_boxes, detection_ms = (self.no_boxes, math.nan) if late else self._boxes(frame)
        depth_m, depth_ms = self._depth(frame, frame_boxes)
        if late:
            res = self._skipped(frame)
        else:
            res = self.pipeline.process(
                k, frame.timestamp_s, frame.image, frame_boxes, depth_m=depth_m
            )
            self.last_time_s = frame.timestamp_s
        self.times["estimation"].add(res.estimation_ms)
        odo = res.odometry
        state = shown_state(odo.state, res.odometry_jump)
        if odo.state:  # the odometry ran on the frame
            self.odometry_count[state] += 1
            self.times["odometry"].add(odo.ms)
        frame_boxes = with_user_track_ids(frame_boxes, res.estimates)  # as the records name them
        if self.held is None:
            n_est = self._write_records(frame_boxes, frame.timestamp_s, res.estimates)
            speed = self._speed_at(frame.timestamp_s)
            self.tracks.add(frame.timestamp_s, frame_boxes, res.estimates, speed)
        else:  # offline: the records and tracks come from the pass over the drive (finish)
            if len(frame_boxes):
                self.held.append(k)
            n_est = int(np.sum(res.estimates.status == EstimateStatus.OK.value))
        with self.files.writing(FRAMES_NAME):
            self.frame_log.write_row(
                {
                    "frame": k,
                    "timestamp_s": frame.timestamp_s,
                    "source": frame.source,
                    "frame_status": frame.status.value,
                    "detail": frame.detail,
                    "odometry_state": state,
                    "inliers": odo.inliers,
                    "segment": odo.segment,
                    "theta_deg": math.degrees(res.theta_rad),
                    "boxes": len(frame_boxes),
                    "estimated": n_est,
                    "odometry_ms": odo.ms,
                    "estimation_ms": res.estimation_ms,
                    "depth_ms": depth_ms,
                    "detection_ms": detection_ms,
                }
            )
        self._paint(frame, frame_boxes, res, state)
        self._export(frame, frame_boxes, res)
        self.result.frames += 1  # a frame that fails part-way is in neither count
        self.status_count[frame.status.value] += 1

    def _skipped(self, frame: Frame) -> FrameResult:
        """The result of a frame the pipeline cannot take (:meth:`_out_of_time`): no θ, no
        estimates, the odometry's segment kept."""
        segment = self.pipeline.segment
        return FrameResult(
            frame.index,
            frame.timestamp_s,
            math.nan,
            self.method,
            self.no_boxes,
            FrameEstimates.empty(),
            OdometryOutput(None, segment),
            estimation_ms=0.0,
        )

    def _out_of_time(self, frame: Frame) -> bool:
        """Whether ``frame`` is an unreadable frame whose time (a repeated or out-of-order log
        stamp or video timestamp) does not follow the last frame's: the frame step cannot take
        it, and the run goes on with the next frame."""
        last = self.last_time_s
        return frame.image is None and last is not None and not frame.timestamp_s > last

    def _boxes(self, frame: Frame) -> tuple[BoxTable, float]:
        """The frame's boxes (from the box file, or the detector on its pixels) and the
        detection time (ms; NaN without a detector)."""
        k = frame.index
        if self.detector is None:
            if k in self.by_frame:
                self.seen_box_frames.add(k)
            return self.by_frame.get(k, self.no_boxes), math.nan
        if frame.image is None:
            return self.no_boxes, math.nan
        boxes = self.detector.detect(frame.image, k)
        ms = self.detector.last_timing.total_s * 1e3
        self.times["detection"].add(ms)
        return boxes, ms

    def _depth(
        self, frame: Frame, frame_boxes: BoxTable
    ) -> tuple[NDArray[np.float32] | None, float]:
        """The depth map (metres) of a readable frame with boxes, and the time it took (ms)."""
        if self.depth is None or frame.image is None or not len(frame_boxes):
            return None, math.nan
        t0 = time.perf_counter()
        depth_m = self.depth.depth(frame.index, frame.image)
        ms = (time.perf_counter() - t0) * 1e3
        self.times["depth"].add(ms)
        self.result.frames_without_depth += int(depth_m is None)
        return depth_m, ms

    def _write_records(self, frame_boxes: BoxTable, timestamp_s: float, est: FrameEstimates) -> int:
        """Write a frame's records (with the ground truth when the boxes carry it); returns
        how many have a distance."""
        rows = frame_records(frame_boxes, timestamp_s, est, self.method, self.config.columns)
        with self.files.writing(RECORDS_NAME):
            self.records.write_rows(rows)
        n_est = int(np.sum(est.status == EstimateStatus.OK.value))
        self.result.records += len(rows)
        self.result.estimated += n_est
        self.result.upper_bounds += int(np.sum(est.status == EstimateStatus.UPPER_BOUND.value))
        not_vehicle = est.reason == MissingReason.NOT_A_VEHICLE.value
        self.result.not_vehicles += int(np.sum(not_vehicle))
        counts = self.result.not_vehicle_classes
        for name in frame_boxes.cls[not_vehicle]:
            counts[name] = counts.get(name, 0) + 1
        return n_est

    def _end_pipeline(self) -> None:
        """The pipeline's end (:meth:`Pipeline.finish`): an offline method's records of every
        frame seen, from its pass over the drive, and its track summaries from the same
        estimates."""
        t0 = time.perf_counter()
        self.end = self.pipeline.finish()
        self.times["estimation"].total += (time.perf_counter() - t0) * 1e3  # over the frames
        for res in self.end.frames:
            boxes = with_user_track_ids(res.boxes, res.estimates)
            self._write_records(boxes, res.t, res.estimates)
            self.tracks.add(res.t, boxes, res.estimates, self._speed_at(res.t))
            self.offline_written += 1

    def _offline_records_failed(self, exc: SlopedistError | OSError) -> None:
        """An offline method's records stopped part-way (a full disk): ``records.csv`` keeps
        the whole frames before the failing one, and the summary says which those are."""
        result, held = self.result, self.held or []
        self.offline_failed = exc
        result.complete = False
        failed = self.offline_failed_frame = held[self.offline_written]
        result.failed_frame = failed if result.failed_frame is None else result.failed_frame
        reached = failed - 1 if failed > 0 else None  # the frames before it have all their rows
        if result.last_complete_frame is None or reached is None:
            result.last_complete_frame = None
        else:
            result.last_complete_frame = min(result.last_complete_frame, reached)
        if result.error is None:
            result.error = f"{type(exc).__name__}: {exc}"

    def _offline_note(self) -> str:
        """What the messages add when an offline method's records stopped part-way (else "")."""
        if self.offline_failed is None:
            return ""
        return (
            f"; the {self.method} records stop before frame {self.offline_failed_frame} "
            f"({self.offline_failed}): {self.files.where(RECORDS_NAME)} holds those of the "
            "frames before it"
        )

    def _speed_at(self, timestamp_s: float) -> float:
        """The ego speed (m/s) at a frame time (s), NaN when unknown."""
        return self.config.ego_speed(timestamp_s) if self.config.ego_speed else math.nan

    def _paint(self, frame: Frame, frame_boxes: BoxTable, res: FrameResult, state: str) -> None:
        """The frame's overlay: to the overlay video or folder, and as a snapshot JPEG when
        asked for."""
        k, t = frame.index, frame.timestamp_s
        snapshot = k in self.config.snapshots
        if self.painter is None and not snapshot:
            return
        if frame.image is None:
            if self.painter is not None:
                with self.files.writing(self.painter.target.name):
                    self.painter.write_placeholder(k, f"frame {k}: {frame.status.value}", t)
            return
        theta = res.theta_rad
        head = f"frame {k}  t {t:.2f} s"
        if not math.isfinite(theta):
            head += f"  no rotation ({state or 'no odometry'})"
        drawn = in_frame_pixels(frame_boxes)  # the frame's own pixels, distorted or not
        draw = functools.partial(
            draw_fig3_overlay,
            frame.image,
            self.camera,
            drawn,
            res.estimates,
            theta,
            head,
            self.shown,
        )
        if isinstance(self.painter, BackgroundOverlay) and not snapshot:
            with self.files.writing(self.painter.target.name):
                self.painter.write_drawn(k, draw, t)  # drawn in the overlay's thread
            return
        image = draw()
        if self.painter is not None:
            with self.files.writing(self.painter.target.name):
                self.painter.write(k, image, t)
        if snapshot:
            path = snapshot_path(Path(self.config.out_dir), k)
            self.files.add(path)
            write_image(partial_path(path), image, [cv2.IMWRITE_JPEG_QUALITY, SNAPSHOT_QUALITY])
            self.result.exports.append(str(path))

    def _export(self, frame: Frame, frame_boxes: BoxTable, res: FrameResult) -> None:
        """The frame in the MCAP export and its rotation in the TUM trajectory."""
        R = res.odometry.R_world_cam
        if self.trajectory is not None and R is not None:
            with self.files.writing(self.trajectory.path.name):
                self.trajectory.write(frame.timestamp_s, R)
        if self.export is None:
            return
        with self.files.writing(self.export.path.name):
            self.export.write_frame(
                frame.index,
                frame.timestamp_s,
                frame.source,
                frame.status.value,
                frame.image,
                in_frame_pixels(frame_boxes),  # annotations of the source image
                res.estimates,
                res.theta_rad,
                lead_index(self.camera, frame_boxes, res.estimates),
            )

    def finish(self) -> None:
        """Fill in the summary, close every output and write ``run.json``."""
        result = self.result
        result.boxes_without_frame = sum(  # of a run stopped early: of the frames it reached
            self.by_frame.count(k)
            for k in self.by_frame
            if k not in self.seen_box_frames and self._reached(k)
        )
        if self.bar is not None:
            self.bar.close()
        files = self.files
        try:
            self._end_pipeline()
        except (SlopedistError, OSError) as exc:  # the other outputs are closed all the same
            if not self.held:
                raise
            self._offline_records_failed(exc)
        # (after the offline pass: its time is the method's, spread over the frames)
        result.elapsed_s = time.perf_counter() - self.start
        result.frames_per_s = result.frames / result.elapsed_s if result.elapsed_s > 0 else math.nan
        result.frame_status = dict(self.status_count)
        result.odometry_states = dict(self.odometry_count)
        result.odometry_ms_mean = self.times["odometry"].mean()
        result.estimation_ms_mean = self.times["estimation"].mean()
        result.depth_ms_mean = self.times["depth"].mean()
        result.detection_ms_mean = self.times["detection"].mean()
        files.close(
            RECORDS_NAME,
            lambda: close_records(self.records, self.config.columns, self.result.ground_truth),
        )
        files.close(FRAMES_NAME, self.frame_log.close)
        files.close(TRACKS_NAME, self._write_tracks)
        if self.painter is not None:
            files.close(self.painter.target.name, self.painter.close)
        for writer in (self.export, self.trajectory):
            if writer is not None:
                files.close(writer.path.name, writer.close)
        if files.failed:  # an output is cut or missing: the run is not whole
            result.complete = False
            result.error = result.error or files.failed
        files.commit(SUMMARY_NAME, result.complete)
        try:
            files.write_summary(SUMMARY_NAME, result)
        except OSError as exc:
            if result.error is None:
                raise OutputWriteError(Path(self.config.out_dir) / SUMMARY_NAME, exc) from exc
            self.summary_failed = f"; {SUMMARY_NAME} could not be written: {exc.strerror or exc}"

    def _reached(self, k: int) -> bool:
        """Whether frame index ``k`` is within the run: any frame of a complete run; of a run
        stopped early, one up to the last it completed (none when it completed none)."""
        if self.result.complete:
            return True
        last = self.result.last_complete_frame
        return last is not None and k <= last

    def _write_tracks(self) -> None:
        tracks = CsvStreamWriter(self.files.open_whole_rows(TRACKS_NAME), TRACK_FIELDS)
        tracks.write_rows(self.tracks.rows())

    def _aborted(self, exc: BaseException, frame: Frame | None) -> RunAbortedError:
        last = self.result.last_complete_frame
        if frame is not None:
            where = f"frame {frame.index} ({frame.source})"
        else:
            where = "the first frame" if last is None else f"the end of frame {last}"
        whose = (  # an offline method's pass went over the frames it reached, not the drive
            f"{self.method} records, from its pass over those frames only,"
            if self.held is not None
            else "records"
        )
        return RunAbortedError(
            f"run stopped at {where}: {exc}. The {whose} of the {self.result.frames} frames "
            f"before it are in {self.files.where(RECORDS_NAME)} (per-frame log "
            f"{self.files.where(FRAMES_NAME)}){self._offline_note()}{self.summary_failed}"
            f"{self.files.kept_note()}",
            self.result.failed_frame,
            self.files.where(RECORDS_NAME),
        )
