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

from slopedist.cli.choice import Choice
from slopedist.cli.method_options import (
    check_methods,
    estimator_options,
    generic_class_option,
    ours_config,
    parse_triple,
    user_reference,
)
from slopedist.cli.options import (
    FINITE_FLOAT,
    FPS,
    POSITIVE_FLOAT,
    detector_options,
    height_option,
    lookback_option,
    make_detector,
    mount_option,
    optional_calibration_options,
    parse_size,
    vehicle_classes_option,
)
from slopedist.cli.record_summary import not_vehicles_line
from slopedist.cli.run_options import (
    columns_option,
    export_option,
    image_topic_option,
    overlay_format_option,
    overlay_option,
    run_offline_option,
)
from slopedist.core.errors import ConfigurationError
from slopedist.estimators import DEFAULT_METHOD, EstimatorConfig, offline_method
from slopedist.io.depth import DepthOutputKind, OnnxDepthConfig, OnnxDepthSource
from slopedist.io.intrinsics import Intrinsics
from slopedist.io.outputs import RunStoppedError, StopFlag, stop_on_signals
from slopedist.streaming.config import (
    FRAMES_NAME,
    RECORDS_NAME,
    RunAbortedError,
    RunResult,
    snapshot_path,
)
from slopedist.streaming.pipeline import ODOMETRY_CHOICES
from slopedist.streaming.setup import (
    DepthFactory,
    LogTopicNames,
    RunOptions,
    folder_depth_source,
    run_to_folder,
)
from slopedist.streaming.step import RecordColumns

DEPTH_OUTPUTS = {"depth": DepthOutputKind.DEPTH, "inverse": DepthOutputKind.INVERSE_DEPTH}
"""``--depth-output`` values: what the ONNX model's output means."""


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


def depth_factory(opts: DepthOptions) -> DepthFactory | None:
    """What builds the depth source the options ask for (files or an ONNX model), or None;
    the options are checked here, before any input is opened.

    Raises:
        ConfigurationError: both a folder and a model, or model options without a model.
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
    if opts.folder is not None:
        return functools.partial(folder_depth_source, opts.folder)
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
    return lambda _frames: OnnxDepthSource(config)  # needs onnxruntime (a clear error without)


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
        type=Choice(list(DEPTH_OUTPUTS)),
        default="depth",
        show_default=True,
        help="ONNX model output: depth (metres = scale × output) or inverse depth / "
        "disparity (metres = scale / output).",
    ),
    click.option(
        "--depth-scale",
        type=POSITIVE_FLOAT,
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
@image_topic_option
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
@export_option
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
@run_offline_option
@click.option(
    "--odometry",
    type=Choice(ODOMETRY_CHOICES),
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
@columns_option
@overlay_option
@overlay_format_option
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
    type=FPS,
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
@click.option("--score", type=FINITE_FLOAT, default=None, help="Keep boxes with score >= SCORE.")
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
@generic_class_option
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
    offline: bool,
    odometry: str,
    vocab: Path | None,
    out_dir: Path,
    columns: str,
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
    generic_classes: tuple[str, ...],
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
    estimator_config, reference = user_reference(estimator_config)
    if offline:
        method = offline_method(method)
    model = detector_model
    read = (depth_opts.folder, depth_opts.model, detector_model)
    options = RunOptions(
        frames,
        out_dir,
        calib,
        image_size=image_size,
        boxes=boxes_path,
        score=score,
        detector=functools.partial(make_detector, model, "detector-", **detector_opts)
        if model
        else None,
        fps=fps,
        timestamps=timestamps,
        topics=LogTopicNames(image_topic, rotation_topic, speed_topic),
        height_m=height_m,
        mount_angle_deg=mount_angle_deg,
        odometry=odometry,
        vocab=vocab,
        lookback_s=lookback_s,
        estimator=ours_config(estimator_config, method, generic_classes, vehicle_classes),
        depth=depth_factory(depth_opts),
        overlay=overlay,
        overlay_format=overlay_format,
        exports=exports,
        snapshots=snapshots,
        progress=not quiet,
        sequence=sequence,
        vehicle_classes=vehicle_classes,
        reference=reference,
        columns=RecordColumns(columns),
        other_inputs=tuple(p for p in read if p is not None),
    )
    stop = StopFlag()
    with stop_on_signals(stop):
        try:
            result = run_to_folder(options, stop)
        except RunAbortedError as exc:
            if not isinstance(exc.__cause__, RunStoppedError):
                raise
            click.echo(f"slopedist: {exc}", err=True)
            raise SystemExit(128 + exc.__cause__.signum) from None
    click.echo(summary_text(result, out_dir, snapshots), err=True)


def summary_text(result: RunResult, out_dir: Path, snapshots: Sequence[int] = ()) -> str:
    """A few lines that tell what a run did and where its output is; ``snapshots``: the frames
    asked for with ``--snapshot`` (those not written, e.g. beyond the last frame or unreadable,
    get a warning)."""
    states = ", ".join(f"{k} {v}" for k, v in sorted(result.odometry_states.items())) or "none"
    status = ", ".join(f"{k} {v}" for k, v in sorted(result.frame_status.items()))
    lines = [
        f"wrote {result.records} records ({result.estimated} ok, {result.upper_bounds} upper "
        f"bounds, method {result.method}) to {out_dir / RECORDS_NAME}",
        f"frames: {result.frames} ({status}); odometry: {states}; per-frame log "
        f"{out_dir / FRAMES_NAME}",
        f"{result.frames_per_s:.1f} frames/s; "
        + (
            f"odometry {result.odometry_ms_mean:.1f} ms, "
            if math.isfinite(result.odometry_ms_mean)
            else "no odometry, "
        )
        + f"estimation {result.estimation_ms_mean:.2f} ms per frame",
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
            not_vehicles_line(
                result.not_vehicle_classes,
                result.records,
                result.estimated + result.upper_bounds,
            )
        )
    missing = result.frame_status.get("missing", 0)
    if 2 * missing > result.frames:
        lines.append(
            f"warning: {missing} of the {result.frames} frames are missing (gaps in the files' "
            "numbers; a file's number is its frame index): if they are named by time, number "
            "them 0, 1, 2, …"
        )
    if result.boxes_without_frame:
        lines.append(
            f"warning: {result.boxes_without_frame} boxes refer to frames that are not "
            "in FRAMES (or unreadable, out of time order) and were not used"
        )
    if result.overlay:
        lines.append(f"overlay: {result.overlay} ({result.overlay_codec})")
    if result.overlay_warning:
        lines.append(f"warning: {result.overlay_warning}")
    lines.extend(f"export: {path}" for path in result.exports)
    unwritten = sorted(
        {k for k in snapshots if str(snapshot_path(out_dir, k)) not in result.exports}
    )
    if unwritten:
        lines.append(
            f"warning: no snapshot of frame {', '.join(map(str, unwritten))}: not a readable "
            "frame of FRAMES (see frames.csv)"
        )
    return "\n".join(lines)
