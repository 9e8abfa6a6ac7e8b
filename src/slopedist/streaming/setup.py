"""A run into a folder, built one way for ``slopedist run`` and ``slopedist batch``.

:func:`run_to_folder` takes :class:`RunOptions` (the options of ``slopedist run``: what it
reads, how, and what it writes) and opens the frame source (image folder, video or drive
log), the calibration (a file, values, or a log's ``camera_info``), the boxes or the detector
mapped into the ideal camera, the estimator, the depth source, the rotation source (a log's IMU
/ odometry topic or visual odometry on the frames) and a log's ego speed; then it runs them
through the loop (:func:`slopedist.streaming.loop.run_frames`, over a
:class:`~slopedist.streaming.pipeline.Pipeline`) into the output folder and removes what an
earlier run there wrote and this one did not. The ``run`` command and each batch drive call this
and nothing else, so a drive of a batch gives the records of ``slopedist run`` with its options.
"""

from __future__ import annotations

import logging
import math
import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from slopedist.core.camera import KITTI_CAMERA_HEIGHT_M, Camera
from slopedist.core.errors import ConfigurationError
from slopedist.estimators import Estimator, EstimatorConfig, build_estimator
from slopedist.estimators.base import ReferencePoint
from slopedist.estimators.depthmap import DepthScaling
from slopedist.estimators.references import DEFAULT_REFERENCE
from slopedist.io.calibration import CameraCalibration, read_calibration
from slopedist.io.depth import DepthSource, FileDepthSource
from slopedist.io.detections.boxes import DEFAULT_VEHICLE_CLASSES, BoxTable
from slopedist.io.detections.dropped import DroppedBoxes
from slopedist.io.detections.onnx_detector import Detector
from slopedist.io.detections.readers import CSV_TRUTH_COLUMN, read_box_file
from slopedist.io.frames import FrameSource, with_frame_size
from slopedist.io.intrinsics import Intrinsics, RectifiedDetector
from slopedist.io.outputs import OutputFolder, StopFlag, check_outputs_spare_inputs, partial_path
from slopedist.io.prefetch import DEFAULT_AHEAD
from slopedist.io.sources import log_calibration, log_rotation_source, log_speed, open_source
from slopedist.odometry.base import LOOKBACK_S, RotationOdometry
from slopedist.odometry.imu import SpeedTrack
from slopedist.odometry.point_map import PointMap
from slopedist.streaming.config import (
    FRAMES_NAME,
    RECORDS_NAME,
    SUMMARY_NAME,
    OverlayFormat,
    RunConfig,
    RunResult,
    earlier_outputs,
    export_paths,
    overlay_fps,
    overlay_path,
    snapshot_path,
)
from slopedist.streaming.loop import run_frames
from slopedist.streaming.pipeline import build_odometry
from slopedist.streaming.step import RecordColumns
from slopedist.streaming.tracks import TRACKS_NAME

_log = logging.getLogger(__name__)

DepthFactory = Callable[[FrameSource], DepthSource]
"""Builds a run's depth source once its frame source is open (the maps' expected size)."""


def folder_depth_source(folder: Path, frames: FrameSource) -> FileDepthSource:
    """Per-frame depth maps from ``folder`` (frames without a map: no depth), of the frames'
    size."""
    width, height = frames.frame_size()
    return FileDepthSource(folder, missing_ok=True, expected_shape=(height, width))


def check_runnable(
    estimator: Estimator,
    has_depth: bool = False,
    boxes: BoxTable | None = None,
    logged_rotations: bool = False,
) -> None:
    """Fail for methods ``run`` cannot feed: those defined on another rotation source (IMU)
    unless the rotations come from a log topic (``logged_rotations``), depth-map methods without
    a depth source (or depth without a depth-map method), and the ``truth`` depth scaling
    without a ground-truth column in the boxes."""
    source = getattr(estimator, "rotation_source", None)
    if source is not None and not logged_rotations:
        raise ConfigurationError(
            f"method '{estimator.name}' is defined on '{source}' rotations; slopedist run feeds "
            "visual-odometry rotations from the frames, or a drive log's IMU / odometry topic "
            "with --rotation-topic (or use slopedist estimate with pose files)"
        )
    if estimator.needs_depth and not has_depth:
        raise ConfigurationError(
            f"method '{estimator.name}' needs depth maps: give a folder of per-frame depth "
            "files (--depth-dir DIR) or an ONNX depth model (--depth-model MODEL.onnx "
            "--depth-input-size WxH)"
        )
    if has_depth and not estimator.needs_depth:
        raise ConfigurationError(
            f"--depth-dir / --depth-model feed depth-map methods; method '{estimator.name}' "
            "does not use depth (use --method depthmap)"
        )
    if (
        getattr(estimator, "scaling", None) is DepthScaling.TRUTH
        and boxes is not None
        and CSV_TRUTH_COLUMN not in boxes.extra
    ):
        raise ConfigurationError(
            f"--depth-scaling truth needs the ground-truth distance column "
            f"'{CSV_TRUTH_COLUMN}' in the box file"
        )


def run_calibration(
    source: FrameSource,
    calib: Path | Intrinsics | None,
    height_m: float,
    mount_rad: float,
    image_size: tuple[int, int] | None = None,
) -> CameraCalibration:
    """The ``calib`` calibration (any form :func:`read_calibration` takes), else the drive
    log's ``camera_info``; the mount in metres and radians; ``image_size`` (``--image-size``,
    pixels) completes or is checked against it."""
    if calib is None:
        calib = log_calibration(source, height_m, mount_rad).intrinsics
    return read_calibration(calib, height_m, mount_rad, image_size=image_size)


def calibration_name(calib: Path | Intrinsics | None, source: FrameSource) -> str:
    """Where a run's calibration comes from, for messages: the file, the values, or the drive
    log's ``camera_info``."""
    if isinstance(calib, Path):
        return str(calib)
    if isinstance(calib, Intrinsics):
        return "the calibration of --fx/--fy/--cx/--cy"
    return f"the camera_info of {source.path}"


def rectified_inputs(
    calibration: CameraCalibration, boxes: BoxTable, detector: Detector | None
) -> tuple[BoxTable, Detector | None]:
    """Boxes (and the detector's future boxes) mapped into the calibration's ideal camera."""
    boxes = calibration.intrinsics.rectify_table(boxes)
    if detector is not None and not calibration.intrinsics.is_ideal:
        detector = RectifiedDetector(detector, calibration.intrinsics)
    return boxes, detector


def rotation_source(
    source: FrameSource,
    rotation_topic: str | None,
    odometry: str,
    vocab: Path | None,
    visual: tuple[Camera, float, PointMap | None],
) -> RotationOdometry | None:
    """The run's rotations: a drive log's IMU/odometry topic, else the ``odometry`` backend on
    the frames (``visual``: its camera, look-back in seconds and point map), else None."""
    if odometry == "none" and vocab is not None:
        raise ConfigurationError("--vocab is only used with --odometry orbslam3")
    if rotation_topic is not None:
        return log_rotation_source(source, rotation_topic)
    if odometry == "none":
        return None
    camera, lookback_s, point_map = visual
    return build_odometry(odometry, camera, vocab, lookback_s, point_map)


@dataclass(frozen=True)
class LogTopicNames:
    """The topics of a drive log that a run reads (None: not used).

    Attributes:
        image: the ``sensor_msgs/Image`` or ``CompressedImage`` topic (required for a log).
        rotation: an IMU / odometry / pose topic whose orientation replaces visual odometry.
        speed: an odometry / twist topic giving the ego speed (m/s), for headway times.
    """

    image: str | None = None
    rotation: str | None = None
    speed: str | None = None


@dataclass(frozen=True)
class RunOptions:
    """What a run reads, how, and what it writes (the options of ``slopedist run``).

    Attributes:
        frames: image folder, video file or drive log.
        out_dir: output folder (records.csv, frames.csv, tracks.csv, run.json).
        calib: calibration file or values; None takes a drive log's ``camera_info``.
        image_size: ``(width, height)`` pixels completing or checked against the calibration
            (``--image-size``), or None.
        boxes: box file, or None with ``detector``; ``score``: minimum box score or None.
        detector: builds the ONNX detector run on every frame instead of a box file.
        fps: frames per second (None: the source's default); ``timestamps``: a timestamps file.
        topics: the drive log's topics (:class:`LogTopicNames`).
        height_m: camera height above the road (metres); ``mount_angle_deg``: camera pitch
            relative to the vehicle (degrees).
        odometry: visual odometry backend
            (:data:`~slopedist.streaming.pipeline.ODOMETRY_CHOICES`); ``vocab``: ORB-SLAM3
            vocabulary; ``lookback_s``: look-back of the ego gradient (seconds).
        estimator: the estimator's configuration (its method included).
        depth: builds the depth source of depth-map methods, or None.
        overlay: also write annotated frames, as ``overlay_format`` (an
            :class:`~slopedist.streaming.config.OverlayFormat` value).
        exports: :class:`~slopedist.streaming.config.RunExport` values (MCAP, TUM trajectory).
        snapshots: frame indices whose overlay is also written as a JPEG.
        progress: show a progress bar on stderr.
        sequence: sequence name written to run.json (None: the frames' folder or video name).
        vehicle_classes: class names scored as vehicles.
        reference: the point of the vehicle every method's distances are moved to
            (``--reference``; :data:`~slopedist.estimators.references.DEFAULT_REFERENCE`, the
            nearest face, by default); None: each method's own point.
        decode_ahead: frames decoded ahead in a thread (0: all in the loop's thread).
        columns: the columns of ``records.csv`` (``--columns``; :class:`~slopedist.streaming.
            step.RecordColumns`).
        other_inputs: further files the run reads through ``detector`` or ``depth`` (a model,
            a depth folder), which no output may replace.
    """

    frames: Path
    out_dir: Path = Path("slopedist_run")
    calib: Path | Intrinsics | None = None
    image_size: tuple[int, int] | None = None
    boxes: Path | None = None
    score: float | None = None
    detector: Callable[[], Detector] | None = None
    fps: float | None = None
    timestamps: Path | None = None
    topics: LogTopicNames = field(default_factory=LogTopicNames)
    height_m: float = KITTI_CAMERA_HEIGHT_M
    mount_angle_deg: float = 0.0
    odometry: str = "builtin"
    vocab: Path | None = None
    lookback_s: float = LOOKBACK_S
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)
    depth: DepthFactory | None = None
    overlay: bool = False
    overlay_format: str = OverlayFormat.MP4.value
    exports: tuple[str, ...] = ()
    snapshots: tuple[int, ...] = ()
    progress: bool = True
    sequence: str | None = None
    vehicle_classes: tuple[str, ...] = DEFAULT_VEHICLE_CLASSES
    reference: ReferencePoint | None = DEFAULT_REFERENCE
    decode_ahead: int = DEFAULT_AHEAD
    columns: RecordColumns = RecordColumns.DEFAULT
    other_inputs: tuple[Path, ...] = ()

    def input_paths(self) -> list[Path | Intrinsics | None]:
        """Every file the run reads (a calibration given as values included)."""
        return [
            self.frames,
            self.calib,
            self.boxes,
            self.timestamps,
            self.vocab,
            *self.other_inputs,
        ]


@dataclass
class _OpenedRun:
    """The opened inputs of a run (:func:`open_run`); ``time_origin_ns`` is a drive log's
    first image stamp (0 otherwise) and ``ego_speed`` its speed topic (m/s) or None."""

    source: FrameSource
    calibration: CameraCalibration
    boxes: BoxTable
    detector: Detector | None
    estimator: Estimator
    depth: DepthSource | None
    odometry: RotationOdometry | None
    ego_speed: SpeedTrack | None
    time_origin_ns: int
    dropped_boxes: DroppedBoxes = field(default_factory=DroppedBoxes)


NO_BOXES = (
    "no boxes: give a box file (--boxes FILE) or an ONNX detector (--detector MODEL.onnx; "
    "export one yourself in two commands: docs/detectors.md)"
)
"""The error of a run given neither boxes nor a detector."""


def boxes_or_detector(
    inputs: RunOptions, dropped: DroppedBoxes | None = None
) -> tuple[BoxTable, Detector | None]:
    """The box file's boxes (the rows its reader left out counted in ``dropped``), or no boxes
    and the detector (exactly one must be given)."""
    if inputs.boxes is not None and inputs.detector is None:
        return read_box_file(inputs.boxes, inputs.score, dropped), None
    if inputs.detector is not None and inputs.boxes is None:
        return BoxTable.empty(), inputs.detector()
    if inputs.boxes is not None:
        raise ConfigurationError("give the boxes as a file (--boxes) or a detector, not both")
    raise ConfigurationError(NO_BOXES)


def open_run(inputs: RunOptions) -> _OpenedRun:
    """Open and check everything ``inputs`` names (see the module docstring).

    Raises:
        ConfigurationError: options that do not fit together (a log without an image topic,
            a folder or video without a calibration, a method the inputs cannot feed, ...).
        SlopedistError / OSError: unreadable inputs (file, line and field where known).
    """
    topics = inputs.topics
    source = open_source(inputs.frames, inputs.fps, inputs.timestamps, topics.image)
    mount_rad = math.radians(inputs.mount_angle_deg)
    calibration = run_calibration(
        source, inputs.calib, inputs.height_m, mount_rad, inputs.image_size
    )
    camera = with_frame_size(calibration.camera, source, calibration_name(inputs.calib, source))
    dropped = DroppedBoxes()
    boxes, detector = rectified_inputs(calibration, *boxes_or_detector(inputs, dropped))
    estimator = build_estimator(inputs.estimator, camera)
    check_runnable(estimator, inputs.depth is not None, boxes, topics.rotation is not None)
    depth = inputs.depth(source) if inputs.depth is not None else None
    visual = (camera, inputs.lookback_s, calibration.point_map)
    odometry = rotation_source(source, topics.rotation, inputs.odometry, inputs.vocab, visual)
    if odometry is None and estimator.self_calibrates:
        raise ConfigurationError(
            f"method '{estimator.name}' calibrates the mount angle and height from frames with a "
            "measured rotation, and --odometry none gives none: use --odometry builtin (or a "
            "drive log's --rotation-topic), or --method ours"
        )
    return _OpenedRun(
        source,
        calibration,
        boxes,
        detector,
        estimator,
        depth,
        odometry,
        ego_speed=log_speed(source, topics.speed) if topics.speed else None,
        time_origin_ns=int(getattr(source, "t0_ns", 0)),
        dropped_boxes=dropped,
    )


def run_to_folder(
    options: RunOptions,
    stop: StopFlag | None = None,
    wrap_frames: Callable[[FrameSource], FrameSource] | None = None,
) -> RunResult:
    """Run ``options`` into their output folder (see the module docstring): the inputs opened,
    the outputs checked against them before anything is written, the frames run until they
    end or ``stop`` is set (after a frame), and the earlier run's optional outputs that this
    one did not write removed. ``wrap_frames`` wraps the frame source (a test hook).

    Example::

        result = run_to_folder(
            RunOptions(Path("drive.mp4"), Path("run"), Path("calib.txt"), boxes=Path("boxes.csv"))
        )
        print(result.records, "records in run/records.csv")

    Raises:
        ConfigurationError: options that do not fit together, an output that would replace an
            input, a TUM trajectory asked for without a rotation source.
        RunAbortedError: the run stopped part-way (from :class:`~slopedist.io.outputs.
            RunStoppedError` on a stop request).
        SlopedistError / OSError: unreadable inputs.
    """
    opened = open_run(options)
    config = run_config(options, opened, stop or StopFlag())
    shots = [snapshot_path(options.out_dir, k) for k in options.snapshots]
    extras = [config.overlay, config.mcap, config.trajectory, *shots]
    check_run_outputs(options.out_dir, extras, options.input_paths())
    if config.trajectory is not None and opened.odometry is None:
        raise ConfigurationError(
            "--export tum writes the rotations of the visual odometry or of a drive log's "
            "--rotation-topic, and this run has none (--odometry none): use --odometry "
            "builtin, or leave out --export tum"
        )
    frames = wrap_frames(opened.source) if wrap_frames is not None else opened.source
    with OutputFolder(options.out_dir).lock():  # until the earlier run's stale outputs are gone
        result = run_frames(
            frames,
            opened.boxes,
            opened.odometry,
            opened.estimator,
            config,
            opened.depth,
            opened.detector,
            opened.dropped_boxes.reasons,
        )
        remove_earlier_outputs(options.out_dir, result, options.input_paths())
    return result


def run_config(options: RunOptions, opened: _OpenedRun, stop: StopFlag) -> RunConfig:
    """The loop's :class:`~slopedist.streaming.config.RunConfig` of ``options`` (output paths
    in their folder) and of the opened inputs (a log's time origin and ego speed)."""
    out_dir = options.out_dir
    mcap, trajectory = export_paths(out_dir, options.exports)
    return RunConfig(
        out_dir,
        options.lookback_s,
        overlay_path(out_dir, options.overlay_format) if options.overlay else None,
        overlay_fps(options.fps, opened.source),
        options.progress,
        options.sequence,
        mcap=mcap,
        trajectory=trajectory,
        time_origin_ns=opened.time_origin_ns,
        ego_speed=opened.ego_speed,
        vehicle_classes=options.vehicle_classes,
        reference=options.reference,
        stop=stop,
        decode_ahead=options.decode_ahead,
        snapshots=options.snapshots,
        columns=options.columns,
    )


def check_run_outputs(
    out_dir: Path, extras: list[Path | None], inputs: Sequence[Path | Intrinsics | None]
) -> None:
    """Fail before anything is written if an output of the run (or its temporary name) is one
    of its input files, or ``out_dir`` is; ``extras``: the optional outputs (overlay, exports);
    ``inputs`` may hold a calibration given as values (not a file)."""
    outputs = [out_dir / n for n in (RECORDS_NAME, FRAMES_NAME, SUMMARY_NAME, TRACKS_NAME)]
    outputs += [e for e in extras if e is not None]
    outputs += [partial_path(o) for o in outputs]
    check_outputs_spare_inputs(outputs, [p for p in inputs if isinstance(p, Path)], out_dir)


def remove_earlier_outputs(
    out_dir: Path, result: RunResult, inputs: Sequence[Path | Intrinsics | None]
) -> list[Path]:
    """Remove what an earlier run into ``out_dir`` wrote and this one did not (an overlay,
    exports, snapshots: :func:`~slopedist.streaming.config.earlier_outputs`), so that the folder
    holds one run; an input of this run, or a folder holding one, is never removed. Says in
    the log what went; returns the removed paths."""
    spared = [p.resolve() for p in inputs if isinstance(p, Path)]
    stale = [
        p
        for p in earlier_outputs(out_dir, [result.overlay, *result.exports])
        if not any(s == p.resolve() or s.is_relative_to(p.resolve()) for s in spared)
    ]
    for path in stale:
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink()
    if stale:
        names = ", ".join(p.name for p in stale)
        _log.warning("removed the outputs of an earlier run that this run did not write: %s", names)
    return stale
