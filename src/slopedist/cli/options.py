"""Option parsing helpers shared by the commands: lists and sizes, the camera's mount, the
calibration, one sequence given as files, the KITTI evaluation's sources, the detector and the
vehicle classes (the estimators' options are in :mod:`slopedist.cli.method_options`)."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from slopedist.cli.choice import Choice
from slopedist.core.camera import KITTI_CAMERA_HEIGHT_M, MAX_CAMERA_HEIGHT_M, MAX_MOUNT_ANGLE_RAD
from slopedist.core.errors import ConfigurationError
from slopedist.estimators.base import VEHICLE_REFERENCES, ReferencePoint
from slopedist.io.detections.boxes import DEFAULT_VEHICLE_CLASSES, vehicle_class_names
from slopedist.io.detections.layouts import LogitKind, OutputLayout
from slopedist.io.detections.onnx_detector import COCO_VEHICLES, DetectorSettings, OnnxDetector
from slopedist.io.detections.sizes import DEFAULT_SIZE_SIGMA_PCT, MAX_SIZE_SIGMA_PCT
from slopedist.io.intrinsics import Intrinsics
from slopedist.io.kitti.tracking import BoxSource, RotationSource
from slopedist.io.sequence_files import PoseFileLayout, SequenceFiles


def split_list(value: str | None) -> list[str] | None:
    """``"a,b , c"`` → ``["a", "b", "c"]``; None or empty → None."""
    if not value:
        return None
    return [v.strip() for v in value.split(",") if v.strip()]


def given_list(value: str | None, option: str, default: str) -> list[str] | None:
    """:func:`split_list` of an option whose absence means ``default`` (e.g. every sequence):
    None when it is not given; a value that names nothing (``""``, ``","``) is a usage error
    naming ``option``, not that default by surprise."""
    if value is None:
        return None
    names = split_list(value)
    if not names:
        raise click.BadParameter(
            f"names nothing; name at least one, or leave the option out for {default}",
            param_hint=f"'{option}'",
        )
    return names


class BoundedFloat(click.ParamType):
    """A finite number within ``(low, high]`` (``low`` included when ``low_open`` is False; no
    bounds: any finite number), so that an option's bad value is a usage error naming the
    option, with its unit."""

    name = "float"

    def __init__(
        self,
        low: float = -math.inf,
        high: float = math.inf,
        unit: str = "",
        low_open: bool = True,
    ) -> None:
        self.low, self.high, self.unit, self.low_open = low, high, unit, low_open

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        number = click.FLOAT.convert(value, param, ctx)
        above_low = number > self.low if self.low_open else number >= self.low
        if not (math.isfinite(number) and above_low and number <= self.high):
            self.fail(f"{value!r} is not {self.description()}", param, ctx)
        return number

    def description(self) -> str:
        """What the option takes: ``in (0, 50] m``, ``a finite number > 0 s``, ``a finite
        number``."""
        if math.isfinite(self.high):
            bracket = "(" if self.low_open else "["
            return f"in {bracket}{self.low:g}, {self.high:g}] {self.unit}".rstrip()
        if math.isfinite(self.low):
            op = ">" if self.low_open else ">="
            return f"a finite number {op} {self.low:g} {self.unit}".rstrip()
        return "a finite number"


FINITE_FLOAT = BoundedFloat()
"""Any finite number (a score threshold: ``nan`` would keep every box)."""

POSITIVE_FLOAT = BoundedFloat(0.0)
"""A finite number > 0 (a factor, a size: ``nan``, ``inf``, 0 or a negative one is refused)."""

SECONDS = BoundedFloat(0.0, unit="s")
"""A finite duration > 0, seconds (``--lookback``, ``--every``)."""

MIN_FPS, MAX_FPS = 1e-3, 1e5
"""The frame rates a ``--fps`` may give, frames per second (one frame per 1000 s to 100 kHz):
beyond them the frames' timestamps overflow or are not a camera's."""

FPS = BoundedFloat(MIN_FPS, MAX_FPS, "frames/s", low_open=False)
"""``--fps``: frames per second in :data:`MIN_FPS`..:data:`MAX_FPS`."""

FRAME_PERIOD = BoundedFloat(0.0, 1 / MIN_FPS, "s")
"""``--frame-period``: seconds between frames, up to one frame per 1000 s."""


height_option = click.option(
    "--height",
    "height_m",
    type=BoundedFloat(0.0, MAX_CAMERA_HEIGHT_M, "m"),
    default=KITTI_CAMERA_HEIGHT_M,
    show_default=True,
    help="Camera height above the road, metres.",
)

MAX_MOUNT_ANGLE_DEG = round(math.degrees(MAX_MOUNT_ANGLE_RAD), 9)
"""The camera's mount-angle bound in degrees, as typed (60, not 59.99999999999999)."""

mount_option = click.option(
    "--mount-angle",
    "mount_angle_deg",
    type=BoundedFloat(-MAX_MOUNT_ANGLE_DEG, MAX_MOUNT_ANGLE_DEG, "°", low_open=False),
    default=0.0,
    show_default=True,
    help="Camera mount angle θ0 in the yz plane, degrees (paper eq. 2).",
)
lookback_option = click.option(
    "--lookback",
    "lookback_s",
    type=SECONDS,
    default=1.0,
    show_default=True,
    help="Look-back of the ego road gradient, seconds.",
)


def apply_options(options: tuple[Any, ...], func: Callable[..., Any]) -> Callable[..., Any]:
    """``func`` decorated with each of ``options`` (click options), the first one outermost
    (as if written above ``func`` in this order)."""
    for option in reversed(options):
        func = option(func)
    return func


CALIBRATION_FLAGS = ("fx", "fy", "cx", "cy")
"""The explicit intrinsics options (pixels), the alternative to ``--calib``."""

_CALIBRATION_OPTIONS = (
    click.option(
        "--calib",
        type=click.Path(dir_okay=False, path_type=Path),
        default=None,
        help="Calibration: KITTI (P2; P0 for odometry calib.txt), 3×3 K text, OpenCV or ROS "
        "camera_info YAML/JSON (docs/calibration.md); lens distortion and fx ≠ fy are removed "
        "from the boxes. Or give --fx --fy --cx --cy instead. [run, a drive log: default its "
        "camera_info topic]",
    ),
    *(
        click.option(
            f"--{name}",
            type=float,
            default=None,
            help=f"Intrinsics instead of --calib: {text}, pixels (all four together).",
        )
        for name, text in zip(
            CALIBRATION_FLAGS,
            (
                "focal length along x",
                "focal length along y",
                "principal point column",
                "principal point row",
            ),
        )
    ),
    click.option(
        "--image-size",
        default=None,
        help="Size WIDTHxHEIGHT (pixels, e.g. 1242x375) of the calibrated images: completes "
        "--fx --fy --cx --cy or a calibration file without one (KITTI, 3×3 K), as an OpenCV or "
        "ROS file's own size; must agree with a file's and the frames' size. Boxes cut by the "
        "image border are flagged only when the size is known (from the frames, the file or "
        "this).",
    ),
)


def calibration_source(
    calib: Path | None,
    values: dict[str, float | None],
    required: bool = True,
    image_size: tuple[int, int] | None = None,
) -> Path | Intrinsics | None:
    """The calibration of ``--calib FILE`` or of ``--fx --fy --cx --cy`` (exactly one form, or
    none when not ``required``; usage errors name the options); ``image_size`` (``--image-size``)
    goes into the values' :class:`Intrinsics` (a file gets it in
    :func:`~slopedist.io.calibration.read_calibration`)."""
    given = [f"--{k}" for k, v in values.items() if v is not None]
    if calib is not None:
        if given:
            raise click.UsageError(
                f"give the calibration as --calib or as {', '.join(given)}, not both"
            )
        return calib
    if not given:
        if not required:
            return None
        raise click.UsageError(
            "give the camera calibration: --calib FILE, or --fx --fy --cx --cy (pixels)"
        )
    missing = [f"--{k}" for k, v in values.items() if v is None]
    if missing:
        raise click.UsageError(f"--fx --fy --cx --cy go together: missing {', '.join(missing)}")
    fx, fy, cx, cy = (float(values[k] or 0.0) for k in CALIBRATION_FLAGS)
    try:
        return Intrinsics.from_values(fx, fy, cx, cy, image_size=image_size)
    except ConfigurationError as exc:
        raise click.BadParameter(str(exc), param_hint="--fx/--fy/--cx/--cy") from None


def _calibration_decorator(required: bool) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    def decorate(command: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(command)
        def wrapper(*args: Any, calib: Path | None, image_size: str | None, **kwargs: Any) -> Any:
            values = {k: kwargs.pop(k) for k in CALIBRATION_FLAGS}
            size = parse_size(image_size, "--image-size WIDTHxHEIGHT in pixels, e.g. 1242x375")
            kwargs["calib"] = calibration_source(calib, values, required, size)
            kwargs["image_size"] = size
            return command(*args, **kwargs)

        return apply_options(_CALIBRATION_OPTIONS, wrapper)

    return decorate


calibration_options = _calibration_decorator(required=True)
"""``--calib`` or ``--fx --fy --cx --cy``, and ``--image-size``, handed to the command as one
``calib`` (a file path or :class:`~slopedist.io.intrinsics.Intrinsics`; both are what
:func:`~slopedist.io.calibration.read_calibration` reads) and ``image_size`` (width, height in
pixels, or None)."""

optional_calibration_options = _calibration_decorator(required=False)
""":data:`calibration_options`, with ``calib`` None when neither form is given (``run`` takes a
drive log's ``camera_info`` then)."""


def _sequence_file_options(required: bool) -> tuple[Callable[..., Any], ...]:
    """The options of one sequence given as files; ``--poses`` and ``--boxes`` are optional
    unless ``required``."""
    return (
        click.option(
            "--poses",
            required=required,
            type=click.Path(dir_okay=False, path_type=Path),
            help="Pose file: KITTI 3x4 per line, TUM, or OXTS (see --pose-format).",
        ),
        click.option(
            "--boxes",
            "boxes_path",
            required=required,
            type=click.Path(dir_okay=False, path_type=Path),
            help="Boxes: slopedist CSV, KITTI labels, PointRCNN, MOTChallenge or COCO JSON file.",
        ),
        click.option(
            "--pose-format",
            type=Choice([p.value for p in PoseFileLayout]),
            default=PoseFileLayout.AUTO.value,
            show_default=True,
            help="Pose layout; 'oxts' = vehicle-frame TUM poses (x forward, y left, z up).",
        ),
        click.option(
            "--frame-period",
            type=FRAME_PERIOD,
            default=0.1,
            show_default=True,
            help="Seconds between frames (KITTI and OXTS poses).",
        ),
        click.option(
            "--score", type=FINITE_FLOAT, default=None, help="Keep boxes with score >= SCORE."
        ),
        height_option,
        mount_option,
    )


def _files_decorator(required: bool) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    def decorate(command: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(command)
        def wrapper(
            *args: Any,
            calib: Path | Intrinsics,
            image_size: tuple[int, int] | None,
            poses: Path | None,
            boxes_path: Path | None,
            pose_format: str,
            frame_period: float,
            score: float | None,
            height_m: float,
            mount_angle_deg: float,
            **kwargs: Any,
        ) -> Any:
            period_source = click.get_current_context().get_parameter_source("frame_period")
            kwargs["files"] = SequenceFiles(
                calib,
                poses,
                boxes_path,
                PoseFileLayout(pose_format),
                frame_period,
                score,
                height_m,
                math.radians(mount_angle_deg),
                image_size,
                period_source is not click.core.ParameterSource.DEFAULT,
            )
            return command(*args, **kwargs)

        return calibration_options(apply_options(_sequence_file_options(required), wrapper))

    return decorate


sequence_file_options = _files_decorator(required=True)
"""``--calib`` (or ``--fx --fy --cx --cy``), ``--poses``, ``--boxes``, ``--pose-format``,
``--frame-period``, ``--score``, ``--height``, ``--mount-angle``: one sequence given as files,
handed to the command as one ``files`` (:class:`~slopedist.io.sequence_files.
SequenceFiles`)."""

drive_file_options = _files_decorator(required=False)
""":data:`sequence_file_options` with ``--poses`` and ``--boxes`` optional (``calibrate FRAMES``
computes the rotations from the frames and may detect the boxes)."""


GT_REFERENCES = VEHICLE_REFERENCES
"""The reference points a ground truth can declare (``--gt-reference``)."""


def _kitti_eval_option_list(prefix: str) -> tuple[Callable[..., Any], ...]:
    """The click options of :func:`kitti_eval_options`; ``prefix`` starts the help text of
    ``--rotation``, ``--boxes``, ``--score``, ``--workers`` and ``--generic-class``."""
    return (
        click.option(
            "--rotation",
            type=Choice([r.value for r in RotationSource]),
            default=RotationSource.ORBSLAM3.value,
            show_default=True,
            help=f"{prefix}Rotation source of the visual-odometry methods "
            "(imu and imu-ego always use oxts).",
        ),
        click.option(
            "--boxes",
            type=Choice([b.value for b in BoxSource]),
            default=BoxSource.GT.value,
            show_default=True,
            help=f"{prefix}Ground-truth boxes, PointRCNN or RRC (camera) detections.",
        ),
        click.option(
            "--score",
            type=FINITE_FLOAT,
            default=None,
            help=f"{prefix}Keep detections with score >= SCORE (PointRCNN, RRC boxes).",
        ),
        height_option,
        mount_option,
        lookback_option,
        click.option(
            "--workers",
            type=click.IntRange(min=1),
            default=1,
            show_default=True,
            help=f"{prefix}Run the sequences on N CPUs, one Ray task per sequence (needs "
            "pip install 'slopedist[batch]'); the results are those of 1.",
        ),
        click.option(
            "--generic-class/--class-as-given",
            default=False,
            show_default=True,
            help=f"{prefix}With detector boxes (every box 'Car'), let ours read the class as "
            "generic: a mixture of car/van/truck/bus (option generic_classes).",
        ),
        click.option(
            "--box-sizes/--no-box-sizes",
            default=False,
            show_default=True,
            help=f"{prefix}Feed the vehicle sizes the boxes know to ours, in place of its "
            "class prior: PointRCNN's h, w, l (LiDAR-derived, closer to the truth than a "
            "camera detector's), the labels' own with --boxes gt; RRC has none.",
        ),
        click.option(
            "--box-size-sigma",
            "box_size_sigma_pct",
            type=BoundedFloat(0.0, MAX_SIZE_SIGMA_PCT, "%"),
            default=None,
            help=f"{prefix}1σ of the sizes of --box-sizes, percent of each dimension "
            f"[default: {DEFAULT_SIZE_SIGMA_PCT:g}].",
        ),
        click.option(
            "--gt-reference",
            type=Choice([r.value for r in GT_REFERENCES]),
            default=None,
            help="Declare the point of the vehicle the truth's distance refers to "
            "(KITTI labels: centre): every method's distance is moved to it (ground-contact "
            "methods by half their class's length prior; ours reports it itself). Default: "
            "undeclared, each method scored at its own point (the published protocol).",
        ),
    )


def kitti_eval_options(prefix: str = "") -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """The options every KITTI tracking evaluation shares — ``--rotation``, ``--boxes``,
    ``--score`` (help text starts with ``prefix``), ``--height``, ``--mount-angle``,
    ``--lookback``, ``--generic-class``, ``--box-sizes``, ``--box-size-sigma``,
    ``--gt-reference`` and ``--workers`` — handed to the
    command as one ``kitti_config`` (:class:`~slopedist.evaluation.kitti.KittiEvalConfig`; the
    command
    adds its sequences, methods and method options with :func:`dataclasses.replace`)."""
    source_options = _kitti_eval_option_list(prefix)

    def decorate(command: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(command)
        def wrapper(
            *args: Any,
            rotation: str,
            boxes: str,
            score: float | None,
            height_m: float,
            mount_angle_deg: float,
            lookback_s: float,
            workers: int,
            generic_class: bool,
            gt_reference: str | None,
            **kwargs: Any,
        ) -> Any:
            from slopedist.evaluation.kitti import KittiEvalConfig

            kwargs["kitti_config"] = KittiEvalConfig(
                rotation=RotationSource(rotation),
                boxes=BoxSource(boxes),
                min_score=score,
                height_m=height_m,
                mount_angle_rad=math.radians(mount_angle_deg),
                lookback_s=lookback_s,
                workers=workers,
                generic_detector_class=generic_class,
                box_sizes=kwargs.pop("box_sizes"),
                box_size_sigma_pct=kwargs.pop("box_size_sigma_pct"),
                gt_reference=ReferencePoint(gt_reference) if gt_reference else None,
            )
            return command(*args, **kwargs)

        return apply_options(source_options, wrapper)

    return decorate


def parse_size(
    value: str | None, what: str = "WIDTHxHEIGHT in pixels", option: str | None = None
) -> tuple[int, int] | None:
    """``"1280x720"`` → ``(1280, 720)`` (positive integers); None or empty → None; a usage error
    names ``option`` (``--pattern``) when ``what`` does not."""
    if not value:
        return None
    try:
        a, b = (int(v) for v in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected {what}, got '{value}'", param_hint=option) from None
    if a <= 0 or b <= 0:
        raise click.BadParameter(f"expected {what} (positive), got '{value}'", param_hint=option)
    return a, b


def parse_class_map(value: str | None) -> dict[int, str] | None:
    """``"2=Car,7=Truck"`` → ``{2: "Car", 7: "Truck"}``; None or empty → None (the default)."""
    if not value:
        return None
    out: dict[int, str] = {}
    for item in value.split(","):
        index, sep, name = item.partition("=")
        if not sep or not index.strip().isdigit() or not name.strip():
            raise click.BadParameter(
                f"class map: expected INDEX=NAME pairs such as 2=Car,7=Truck, got '{item}'"
            )
        out[int(index)] = name.strip()
    return out


DEFAULT_CLASSES = ",".join(f"{k}={v}" for k, v in COCO_VEHICLES.items())


DETECTOR_OPTION_SPECS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    (
        "score",
        "detector_score",
        {
            "type": BoundedFloat(0.0, 1.0, low_open=False),
            "default": 0.25,
            "show_default": True,
            "help": "Minimum detector score.",
        },
    ),
    (
        "iou",
        "detector_iou",
        {
            "type": BoundedFloat(0.0, 1.0),
            "default": 0.45,
            "show_default": True,
            "help": "NMS IoU threshold (per class).",
        },
    ),
    (
        "classes",
        "detector_classes",
        {
            "default": DEFAULT_CLASSES,
            "show_default": True,
            "help": "Model class index = slopedist class name; other classes are dropped.",
        },
    ),
    (
        "layout",
        "detector_layout",
        {
            "type": Choice([v.value for v in OutputLayout]),
            "default": OutputLayout.AUTO.value,
            "show_default": True,
            "help": "Output layout of the model (auto: from its output shapes; docs/detectors.md).",
        },
    ),
    (
        "input-size",
        "detector_input_size",
        {"help": "WIDTHxHEIGHT network input, for models with a dynamic input size."},
    ),
    ("bgr", "detector_bgr", {"is_flag": True, "help": "Feed BGR instead of RGB (YOLOX)."}),
    (
        "pixel-scale",
        "detector_pixel_scale",
        {
            "type": POSITIVE_FLOAT,
            "default": 1 / 255,
            "help": "Factor of the 0–255 pixel values [default: 1/255; YOLOX: 1].",
        },
    ),
    (
        "pad-top-left",
        "detector_pad_top_left",
        {
            "is_flag": True,
            "help": "Letterbox padding at the bottom/right only (YOLOX) instead of centred.",
        },
    ),
    (
        "logits",
        "detector_logits",
        {
            "type": Choice([v.value for v in LogitKind]),
            "default": LogitKind.SIGMOID.value,
            "show_default": True,
            "help": "DETR logits: one sigmoid per class, or softmax with a no-object class.",
        },
    ),
    (
        "threads",
        "detector_threads",
        {"type": click.IntRange(min=1), "help": "onnxruntime threads [default: its own]."},
    ),
)
"""``(option name without prefix, parameter, click keywords)`` of each detector option."""


def detector_options(prefix: str = "") -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """The options :func:`make_detector` reads (model file excluded), named ``--<prefix>score``
    etc. (``run`` uses the prefix ``detector-``, its ``--score`` being the box files')."""

    def decorate(func: Callable[..., Any]) -> Callable[..., Any]:
        for name, param, kwargs in reversed(DETECTOR_OPTION_SPECS):
            func = click.option(f"--{prefix}{name}", param, **kwargs)(func)
        return func

    return decorate


def make_detector(model: Path, prefix: str = "", **opts: Any) -> OnnxDetector:
    """An :class:`OnnxDetector` from ``model`` and the values of :func:`detector_options`
    (named with ``prefix`` in a usage error)."""
    settings = DetectorSettings(
        score_threshold=opts["detector_score"],
        iou_threshold=opts["detector_iou"],
        class_map=parse_class_map(opts["detector_classes"]),
        layout=opts["detector_layout"],
        input_size=parse_size(opts["detector_input_size"], option=f"--{prefix}input-size"),
        bgr_input=opts["detector_bgr"],
        pixel_scale=opts["detector_pixel_scale"],
        pad_centre=not opts["detector_pad_top_left"],
        logit_kind=opts["detector_logits"],
        threads=opts["detector_threads"],
    )
    return OnnxDetector(model, settings)


def _vehicle_classes(ctx: click.Context, param: click.Parameter, value: str) -> tuple[str, ...]:
    try:
        return vehicle_class_names(split_list(value) or [])
    except ConfigurationError as exc:
        raise click.BadParameter(str(exc), param_hint="--vehicle-classes") from None


vehicle_classes_option = click.option(
    "--vehicle-classes",
    "vehicle_classes",
    default=",".join(DEFAULT_VEHICLE_CLASSES),
    show_default=True,
    callback=_vehicle_classes,
    help="Comma-separated class names scored as vehicles (case-insensitive); boxes of other "
    "classes (Pedestrian, Cyclist, Tram, Misc, DontCare, ...) keep a row with status missing, "
    "reason not_a_vehicle.",
)
