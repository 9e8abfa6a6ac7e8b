"""Everything a run is made from, built one way for ``slopedist run`` and ``slopedist batch``.

:func:`prepare_run` turns :class:`RunInputs` (paths, drive-log topics and options) into a
:class:`PreparedRun`: the frame source (image folder, video or drive log), the calibration
(a file, values, or a log's ``camera_info``), the boxes or the detector mapped into the ideal
camera, the estimator, the depth source, the rotation source (a log's IMU / odometry topic or
visual odometry on the frames) and a log's ego speed. :meth:`PreparedRun.run` runs it with
:func:`slopedist.streaming.loop.run_frames`. The ``run`` command and each batch drive call this and
nothing else, so a drive of a batch gives the records of ``slopedist run`` with its options.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from slopedist.core.camera import KITTI_CAMERA_HEIGHT_M, Camera
from slopedist.core.errors import ConfigurationError
from slopedist.estimators import Estimator, EstimatorConfig, build_estimator
from slopedist.estimators.depthmap import DepthScaling
from slopedist.estimators.ours.selfcal import self_calibrates, warn_if_uncalibrated
from slopedist.io.calibration import CameraCalibration, read_calibration
from slopedist.io.depth import DepthSource, FileDepthSource
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.dropped import DroppedBoxes
from slopedist.io.detections.onnx_detector import Detector
from slopedist.io.detections.readers import CSV_TRUTH_COLUMN, read_box_file
from slopedist.io.frames import FrameSource, with_frame_size
from slopedist.io.intrinsics import Intrinsics, RectifiedDetector
from slopedist.io.sources import log_calibration, log_rotation_source, log_speed, open_source
from slopedist.odometry import make_odometry
from slopedist.odometry.base import LOOKBACK_S, RotationOdometry
from slopedist.odometry.imu import SpeedTrack
from slopedist.odometry.point_map import PointMap
from slopedist.streaming.config import RunConfig, RunResult
from slopedist.streaming.frame_times import SteppedFrames, long_step_warning
from slopedist.streaming.loop import run_frames

_log = logging.getLogger(__name__)

ODOMETRY_CHOICES = ("builtin", "orbslam3", "none")
"""Rotation sources on the frames (``--odometry``; ``none`` = no rotations, for methods that do
not use them)."""

DepthFactory = Callable[[FrameSource], DepthSource]
"""Builds a run's depth source once its frame source is open (the maps' expected size)."""


def build_odometry(
    name: str,
    camera: Camera,
    vocab: Path | None = None,
    lookback_s: float = LOOKBACK_S,
    point_map: PointMap | None = None,
) -> RotationOdometry:
    """The rotation source ``name`` (``builtin`` or ``orbslam3``) for ``camera``.

    The built-in backend estimates rotations directly over ``lookback_s`` seconds (the
    look-back of the gradient) and maps its tracked points into the ideal ``camera`` with
    ``point_map`` (lens distortion, fx ≠ fy); ORB-SLAM3 tracks a map and has neither setting.
    """
    if vocab is not None and name != "orbslam3":
        raise ConfigurationError("--vocab is only used with --odometry orbslam3")
    if name == "orbslam3":
        return make_odometry(name, camera, vocabulary=vocab)
    if point_map is not None:
        return make_odometry(name, camera, lookback_s=lookback_s, point_map=point_map)
    return make_odometry(name, camera, lookback_s=lookback_s)


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
class RunInputs:
    """What a run reads and how (the options of ``slopedist run``).

    Attributes:
        frames: image folder, video file or drive log.
        calib: calibration file or values; None takes a drive log's ``camera_info``.
        image_size: ``(width, height)`` pixels completing or checked against the calibration
            (``--image-size``), or None.
        boxes: box file, or None with ``detector``; ``score``: minimum box score or None.
        detector: builds the ONNX detector run on every frame instead of a box file.
        fps: frames per second (None: the source's default); ``timestamps``: a timestamps file.
        topics: the drive log's topics (:class:`LogTopicNames`).
        height_m: camera height above the road (metres); ``mount_angle_deg``: camera pitch
            relative to the vehicle (degrees).
        odometry: visual odometry backend (:data:`ODOMETRY_CHOICES`); ``vocab``: ORB-SLAM3
            vocabulary; ``lookback_s``: look-back of the ego gradient (seconds).
        estimator: the estimator's configuration (its method included).
        depth: builds the depth source of depth-map methods, or None.
    """

    frames: Path
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


@dataclass
class PreparedRun:
    """The opened inputs of a run (:func:`prepare_run`); ``time_origin_ns`` is a drive log's
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
    lookback_s: float = LOOKBACK_S

    def run(self, config: RunConfig, frames: FrameSource | None = None) -> RunResult:
        """:func:`~slopedist.streaming.loop.run_frames` on these inputs into ``config`` (``frames``
        replaces the source, e.g. a wrapped one).

        Raises:
            ConfigurationError: a TUM trajectory asked for without a rotation source (it would
                be a file with no pose), before anything is written.
        """
        if config.trajectory is not None and self.odometry is None:
            raise ConfigurationError(
                "--export tum writes the rotations of the visual odometry or of a drive log's "
                "--rotation-topic, and this run has none (--odometry none): use --odometry "
                "builtin, or leave out --export tum"
            )
        stepped = SteppedFrames(frames or self.source)
        result = run_frames(
            stepped,
            self.boxes,
            self.odometry,
            self.estimator,
            config,
            self.depth,
            self.detector,
            self.dropped_boxes.reasons,
        )
        warn_if_uncalibrated(self.estimator)
        long_steps = long_step_warning(stepped.steps_s, self.lookback_s)
        if long_steps is not None and self.odometry is not None:  # θ from those rotations
            _log.warning("%s", long_steps)
        return result


def boxes_or_detector(
    inputs: RunInputs, dropped: DroppedBoxes | None = None
) -> tuple[BoxTable, Detector | None]:
    """The box file's boxes (the rows its reader left out counted in ``dropped``), or no boxes
    and the detector (exactly one must be given)."""
    if inputs.boxes is not None and inputs.detector is None:
        return read_box_file(inputs.boxes, inputs.score, dropped), None
    if inputs.detector is not None and inputs.boxes is None:
        return BoxTable.empty(), inputs.detector()
    raise ConfigurationError("give the boxes as a file (--boxes) or a detector (--detector)")


def prepare_run(inputs: RunInputs) -> PreparedRun:
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
    if odometry is None and self_calibrates(estimator):
        raise ConfigurationError(
            f"method '{estimator.name}' calibrates the mount angle and height from frames with a "
            "measured rotation, and --odometry none gives none: use --odometry builtin (or a "
            "drive log's --rotation-topic), or --method ours"
        )
    return PreparedRun(
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
        lookback_s=inputs.lookback_s,
    )
