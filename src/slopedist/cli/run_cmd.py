"""``slopedist run``: frames (image folder, video or drive log) + boxes → per-target distances.

Depth-map methods (``--method depthmap``) take their depth maps from a folder of per-frame files
(``--depth-dir``: KITTI depth PNG or ``.npy``) or from an ONNX depth model run on each frame
(``--depth-model``, optional extra ``onnx``).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click

from slopedist.camera import Camera
from slopedist.cli.options import (
    check_methods,
    detector_options,
    estimator_options,
    height_option,
    lookback_option,
    make_detector,
    mount_option,
    optional_calibration_options,
    parse_size,
    parse_triple,
    vehicle_classes_option,
)
from slopedist.depth import (
    DepthOutputKind,
    DepthSource,
    FileDepthSource,
    OnnxDepthConfig,
    OnnxDepthSource,
)
from slopedist.detections.boxes import BoxTable
from slopedist.detections.onnx_detector import Detector
from slopedist.detections.readers import CSV_TRUTH_COLUMN, read_box_file
from slopedist.errors import ConfigurationError
from slopedist.estimators import DEFAULT_METHOD, Estimator, EstimatorConfig, build_estimator
from slopedist.estimators.depthmap import DepthScaling
from slopedist.io.calibration import CameraCalibration, read_calibration
from slopedist.io.frames import FrameSource, with_frame_size
from slopedist.io.intrinsics import Intrinsics, RectifiedDetector
from slopedist.io.outputs import (
    RunStoppedError,
    check_outputs_spare_inputs,
    partial_path,
    stop_on_signals,
)
from slopedist.io.sources import log_calibration, log_rotation_source, log_speed, open_source
from slopedist.odometry import make_odometry
from slopedist.odometry.base import LOOKBACK_S, RotationOdometry
from slopedist.odometry.point_map import PointMap
from slopedist.run_config import (
    FRAMES_NAME,
    MCAP_NAME,
    RECORDS_NAME,
    SUMMARY_NAME,
    TRAJECTORY_NAME,
    RunAbortedError,
    RunConfig,
    RunExport,
    RunResult,
    snapshot_path,
)
from slopedist.runner import run_frames
from slopedist.tracks import TRACKS_NAME

ODOMETRY_BACKENDS = ("builtin", "orbslam3", "none")
DEPTH_OUTPUTS = {"depth": DepthOutputKind.DEPTH, "inverse": DepthOutputKind.INVERSE_DEPTH}
"""``--depth-output`` values: what the ONNX model's output means."""


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


@dataclass(frozen=True)
class DepthOptions:
    """The ``--depth-*`` options that choose and configure the depth source."""

    folder: Path | None = None
    model: Path | None = None
    input_size: str | None = None
    mean: str | None = None
    std: str | None = None
    output: str = "depth"
    scale: float = 1.0
    bgr: bool = False
    threads: int | None = None


def build_depth_source(opts: DepthOptions, frames: FrameSource) -> DepthSource | None:
    """The depth source the options ask for (files or an ONNX model), or None.

    Raises:
        ConfigurationError: both a folder and a model, or model options without a model.
        OptionalDependencyError: ``--depth-model`` without onnxruntime installed.
    """
    if opts.folder is not None and opts.model is not None:
        raise ConfigurationError("give either --depth-dir or --depth-model, not both")
    model_only = {
        "--depth-input-size": opts.input_size,
        "--depth-mean": opts.mean,
        "--depth-std": opts.std,
        "--depth-threads": opts.threads,
    }
    stray = [k for k, v in model_only.items() if v is not None]
    stray += ["--depth-output"] if opts.output != "depth" else []
    stray += ["--depth-scale"] if opts.scale != 1.0 else []
    stray += ["--depth-bgr"] if opts.bgr else []
    if opts.model is None and stray:
        raise ConfigurationError(
            f"{', '.join(stray)} configure an ONNX depth model: "
            "give it with --depth-model MODEL.onnx"
        )
    width, height = frames.frame_size()
    if opts.folder is not None:
        return FileDepthSource(opts.folder, missing_ok=True, expected_shape=(height, width))
    if opts.model is None:
        return None
    size = parse_size(opts.input_size, "--depth-input-size WIDTHxHEIGHT in pixels, e.g. 640x192")
    if size is None:
        raise ConfigurationError(
            "--depth-model needs the network's input size: "
            "--depth-input-size WIDTHxHEIGHT (e.g. 640x192)"
        )
    in_w, in_h = size
    config = OnnxDepthConfig(
        opts.model,
        in_w,
        in_h,
        mean=parse_triple(opts.mean, "--depth-mean") if opts.mean else (0.0, 0.0, 0.0),
        std=parse_triple(opts.std, "--depth-std") if opts.std else (1.0, 1.0, 1.0),
        output_kind=DEPTH_OUTPUTS[opts.output],
        output_scale=opts.scale,
        bgr_input=opts.bgr,
        threads=opts.threads,
    )
    return OnnxDepthSource(config)


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


_DEPTH_SOURCE_OPTIONS = (
    click.option(
        "--depth-dir",
        type=click.Path(file_okay=False, path_type=Path),
        default=None,
        help="depthmap: folder of per-frame depth maps named by frame number "
        "(KITTI depth PNG, uint16/256 = m, or .npy float metres).",
    ),
    click.option(
        "--depth-model",
        type=click.Path(dir_okay=False, path_type=Path),
        default=None,
        help="depthmap: ONNX depth model run on every frame with boxes (needs "
        "onnxruntime: pip install 'slopedist[onnx]').",
    ),
    click.option(
        "--depth-input-size",
        default=None,
        help="ONNX model input size WIDTHxHEIGHT in pixels (e.g. 640x192).",
    ),
    click.option(
        "--depth-mean",
        default=None,
        help="ONNX model input mean per channel (RGB, on values in [0, 1]) [default: 0,0,0].",
    ),
    click.option(
        "--depth-std", default=None, help="ONNX model input std per channel (RGB) [default: 1,1,1]."
    ),
    click.option(
        "--depth-output",
        type=click.Choice(list(DEPTH_OUTPUTS)),
        default="depth",
        show_default=True,
        help="ONNX model output: depth (metres = scale × output) or inverse depth / "
        "disparity (metres = scale / output).",
    ),
    click.option(
        "--depth-scale",
        type=click.FloatRange(min=0, min_open=True),
        default=1.0,
        show_default=True,
        help="ONNX model output scale (see --depth-output).",
    ),
    click.option("--depth-bgr", is_flag=True, help="Feed the ONNX model BGR instead of RGB."),
    click.option(
        "--depth-threads",
        type=click.IntRange(min=1),
        default=None,
        help="onnxruntime threads [default: its own].",
    ),
)
_DEPTH_PARAMS = {
    "depth_dir": "folder",
    "depth_model": "model",
    "depth_input_size": "input_size",
    "depth_mean": "mean",
    "depth_std": "std",
    "depth_output": "output",
    "depth_scale": "scale",
    "depth_bgr": "bgr",
    "depth_threads": "threads",
}


def depth_source_options(command: Callable[..., Any]) -> Callable[..., Any]:
    """The ``--depth-*`` options of the depth source, handed to ``command`` as one
    ``depth_opts`` (:class:`DepthOptions`)."""

    @functools.wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        values = {field: kwargs.pop(name) for name, field in _DEPTH_PARAMS.items()}
        return command(*args, depth_opts=DepthOptions(**values), **kwargs)

    for option in reversed(_DEPTH_SOURCE_OPTIONS):
        wrapper = option(wrapper)
    return wrapper


@click.command("run")
@click.argument("frames", type=click.Path(path_type=Path))
@optional_calibration_options
@click.option(
    "--image-topic",
    default=None,
    help="Drive log (.bag, .mcap, .db3, ROS 2 bag folder): the sensor_msgs/Image or "
    "CompressedImage topic (see: slopedist log info LOG).",
)
@click.option(
    "--rotation-topic",
    default=None,
    help="Drive log: a sensor_msgs/Imu, nav_msgs/Odometry or pose topic whose orientation "
    "replaces the visual odometry (body x forward, y left, z up; see docs/viewers.md).",
)
@click.option(
    "--speed-topic",
    default=None,
    help="Drive log: a nav_msgs/Odometry or TwistStamped topic giving the ego speed, for the "
    "headway time in OUT/tracks.csv.",
)
@click.option(
    "--export",
    "exports",
    type=click.Choice([e.value for e in RunExport]),
    multiple=True,
    help="Also write OUT/run.mcap (Foxglove schemas) and/or OUT/trajectory.tum (rotations, "
    "for evo). Repeatable.",
)
@click.option(
    "--boxes",
    "boxes_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Boxes per frame: slopedist CSV, KITTI labels, PointRCNN, MOTChallenge or COCO JSON "
    "file (or --detector).",
)
@click.option(
    "--detector",
    "detector_model",
    type=click.Path(dir_okay=False, path_type=Path),
    help="ONNX detector run on every frame instead of --boxes (needs onnxruntime: pip install "
    "'slopedist[onnx]'; docs/detectors.md); options --detector-*.",
)
@click.option("--method", default=None, help=f"Estimator name [default: {DEFAULT_METHOD}].")
@click.option(
    "--odometry",
    type=click.Choice(ODOMETRY_BACKENDS),
    default="builtin",
    show_default=True,
    help="Visual odometry backend (orbslam3 is an optional extra; none = no rotations, "
    "for methods that do not use them: flat, depthmap).",
)
@click.option(
    "--vocab",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="ORB vocabulary (ORBvoc.txt) for --odometry orbslam3 [default: $PYORBSLAM3_VOCAB].",
)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("slopedist_run"),
    show_default=True,
    help="Output folder: records.csv, frames.csv, run.json, overlay.",
)
@click.option("--overlay", is_flag=True, help="Also write annotated frames (paper Fig. 3 style).")
@click.option(
    "--overlay-format",
    type=click.Choice(["mp4", "png"]),
    default="mp4",
    show_default=True,
    help="Overlay as OUT/overlay.mp4 or as PNG files in OUT/overlay/.",
)
@click.option(
    "--snapshot",
    "snapshots",
    type=click.IntRange(min=0),
    multiple=True,
    help="Also write the overlay of frame N as OUT/snapshot_NNNNNN.jpg (with or without "
    "--overlay). Repeatable.",
)
@click.option(
    "--fps",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="Frames per second for timestamps [default: 10 for an image folder, the "
    "container's rate for a video].",
)
@click.option(
    "--timestamps",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Timestamps file, one per frame (seconds or KITTI date-times); overrides --fps.",
)
@click.option("--score", type=float, default=None, help="Keep boxes with score >= SCORE.")
@click.option(
    "--sequence",
    default=None,
    help="Sequence name written to OUT/run.json, so that `slopedist report` puts runs "
    "of different methods on one sequence in one row [default: the frames' "
    "folder or video name].",
)
@depth_source_options
@click.option("--quiet", is_flag=True, help="No progress bar.")
@vehicle_classes_option
@height_option
@mount_option
@lookback_option
@estimator_options(depth=True)
@detector_options("detector-")
def run(  # noqa: PLR0913 (a click command: one parameter per option)
    frames: Path,
    calib: Path | Intrinsics | None,
    image_size: tuple[int, int] | None,
    image_topic: str | None,
    rotation_topic: str | None,
    speed_topic: str | None,
    exports: tuple[str, ...],
    boxes_path: Path | None,
    detector_model: Path | None,
    method: str | None,
    odometry: str,
    vocab: Path | None,
    out_dir: Path,
    overlay: bool,
    overlay_format: str,
    snapshots: tuple[int, ...],
    fps: float | None,
    timestamps: Path | None,
    score: float | None,
    sequence: str | None,
    quiet: bool,
    vehicle_classes: tuple[str, ...],
    height_m: float,
    mount_angle_deg: float,
    lookback_s: float,
    estimator_config: EstimatorConfig,
    depth_opts: DepthOptions,
    **detector_opts: Any,
) -> None:
    """Estimate distances from FRAMES (an image folder, a video file or a drive log) and
    per-frame boxes.

    The camera rotation comes from visual odometry on the frames (or a log's IMU / odometry
    topic); records are written to OUT/records.csv frame by frame, with a per-frame log in
    OUT/frames.csv. A box file with a gt_distance_m column (metres) makes the run scorable by
    `slopedist report OUT`.

    Files are renamed from *.partial.* when the run ends; SIGTERM or Ctrl-C stops it after the
    current frame (OUT/run.json says how far it got; exit code 128 + signal).
    """
    method = method or DEFAULT_METHOD
    check_methods([method])
    source = open_source(frames, fps, timestamps, image_topic)
    mount = (height_m, math.radians(mount_angle_deg))
    calibration = run_calibration(source, calib, *mount, image_size)
    camera = with_frame_size(calibration.camera, source)
    boxes, detector = boxes_or_detector(boxes_path, score, detector_model, detector_opts)
    boxes, detector = rectified_inputs(calibration, boxes, detector)
    estimator = build_estimator(estimator_config.with_method(method), camera)
    has_depth = depth_opts.folder is not None or depth_opts.model is not None
    check_runnable(estimator, has_depth, boxes, rotation_topic is not None)
    depth = build_depth_source(depth_opts, source)
    backend = rotation_source(
        source, rotation_topic, odometry, vocab, (camera, lookback_s, calibration.point_map)
    )
    overlay_path = (
        out_dir / ("overlay.mp4" if overlay_format == "mp4" else "overlay") if overlay else None
    )
    overlay_fps = fps or getattr(source, "container_fps", 0.0) or 10.0
    inputs = [frames, calib, boxes_path, timestamps, depth_opts.folder, depth_opts.model]
    inputs += [vocab, detector_model]
    mcap_path = out_dir / MCAP_NAME if RunExport.MCAP.value in exports else None
    tum_path = out_dir / TRAJECTORY_NAME if RunExport.TUM.value in exports else None
    shots = [snapshot_path(out_dir, k) for k in snapshots]
    check_run_outputs(out_dir, [overlay_path, mcap_path, tum_path, *shots], inputs)
    config = RunConfig(
        out_dir,
        lookback_s,
        overlay_path,
        overlay_fps,
        not quiet,
        sequence,
        mcap=mcap_path,
        trajectory=tum_path,
        time_origin_ns=int(getattr(source, "t0_ns", 0)),
        ego_speed=log_speed(source, speed_topic) if speed_topic else None,
        vehicle_classes=vehicle_classes,
        snapshots=snapshots,
    )
    result = run_until_stopped(
        lambda: run_frames(source, boxes, backend, estimator, config, depth, detector), config
    )
    click.echo(summary_text(result, out_dir), err=True)


def run_calibration(
    source: FrameSource,
    calib: Any,
    height_m: float,
    mount_rad: float,
    image_size: tuple[int, int] | None = None,
) -> CameraCalibration:
    """The ``--calib`` calibration (any form :func:`read_calibration` takes), else the drive
    log's ``camera_info``; ``image_size`` (``--image-size``) completes or is checked against it."""
    if calib is None:
        calib = log_calibration(source, height_m, mount_rad).intrinsics
    return read_calibration(calib, height_m, mount_rad, image_size=image_size)


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


def boxes_or_detector(
    boxes_path: Path | None,
    score: float | None,
    detector_model: Path | None,
    detector_opts: dict[str, Any],
) -> tuple[BoxTable, Detector | None]:
    """The box file's boxes, or no boxes and the ONNX detector (exactly one must be given)."""
    if boxes_path is not None and detector_model is None:
        return read_box_file(boxes_path, score), None
    if detector_model is not None and boxes_path is None:
        return BoxTable.empty(), make_detector(detector_model, **detector_opts)
    raise ConfigurationError("give the boxes as a file (--boxes) or a detector (--detector)")


def run_until_stopped(start: Callable[[], RunResult], config: RunConfig) -> RunResult:
    """``start()`` (a :func:`~slopedist.runner.run_frames` call with ``config``) with
    SIGTERM/SIGINT turned into a stop after the current frame (:attr:`RunConfig.stop`); a
    stopped run exits with code 128 + the signal number."""
    with stop_on_signals(config.stop):
        try:
            return start()
        except RunAbortedError as exc:
            if not isinstance(exc.__cause__, RunStoppedError):
                raise
            click.echo(f"slopedist: {exc}", err=True)
            raise SystemExit(128 + exc.__cause__.signum) from None


def summary_text(result: RunResult, out_dir: Path) -> str:
    """A few lines that tell what a run did and where its output is."""
    states = ", ".join(f"{k} {v}" for k, v in sorted(result.odometry_states.items())) or "none"
    status = ", ".join(f"{k} {v}" for k, v in sorted(result.frame_status.items()))
    lines = [
        f"wrote {result.records} records ({result.estimated} ok, {result.upper_bounds} upper "
        f"bounds, method {result.method}) to {out_dir / RECORDS_NAME}",
        f"frames: {result.frames} ({status}); odometry: {states}; per-frame log "
        f"{out_dir / FRAMES_NAME}",
        f"{result.frames_per_s:.1f} frames/s; odometry {result.odometry_ms_mean:.1f} ms, "
        f"estimation {result.estimation_ms_mean:.2f} ms per frame",
    ]
    if result.detector:
        lines.append(f"detector ({result.detector}): {result.detection_ms_mean:.1f} ms per frame")
    if result.depth_source:
        lines.append(f"depth maps ({result.depth_source}): {result.depth_ms_mean:.1f} ms per map")
    if result.frames_without_depth:
        lines.append(
            f"warning: {result.frames_without_depth} frames with boxes had no depth map "
            "(their targets are missing with reason no_depth)"
        )
    lines.append(
        f"sequence '{result.sequence}'; "
        + (
            "ground truth (gt_distance_m) kept in the records: score with slopedist report "
            f"{out_dir}"
            if result.ground_truth
            else "no ground truth in the boxes (add a gt_distance_m column to score the run)"
        )
    )
    if result.not_vehicles:
        lines.append(
            f"{result.not_vehicles} boxes are not of a vehicle class (missing, reason "
            "not_a_vehicle; see --vehicle-classes)"
        )
    if result.boxes_without_frame:
        lines.append(
            f"warning: {result.boxes_without_frame} boxes refer to frames that are not "
            "in FRAMES and were not used"
        )
    if result.overlay:
        lines.append(f"overlay: {result.overlay}")
    lines.extend(f"export: {path}" for path in result.exports)
    return "\n".join(lines)
