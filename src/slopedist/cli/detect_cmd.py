"""``slopedist detect``: an ONNX detector over a video or image folder → the slopedist box CSV.

:func:`detector_options` and :func:`make_detector` are the detector's options, for any command
that runs one.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from slopedist.cli.options import parse_size
from slopedist.detections.layouts import LogitKind, OutputLayout
from slopedist.detections.onnx_detector import COCO_VEHICLES, OnnxDetector
from slopedist.detections.video import detect_video
from slopedist.io.frames import open_frames


def parse_class_map(value: str | None) -> dict[int, str] | None:
    """``"2=Car,7=Truck"`` → ``{2: "Car", 7: "Truck"}``; None or empty → None (the default)."""
    if not value:
        return None
    out: dict[int, str] = {}
    for item in value.split(","):
        index, sep, name = item.partition("=")
        if not sep or not index.strip().isdigit() or not name.strip():
            raise click.BadParameter(
                f"expected INDEX=NAME pairs such as 2=Car,7=Truck, got '{item}'",
                param_hint="--classes",
            )
        out[int(index)] = name.strip()
    return out


DEFAULT_CLASSES = ",".join(f"{k}={v}" for k, v in COCO_VEHICLES.items())


def detector_options(func: Callable[..., Any]) -> Callable[..., Any]:
    """The options :func:`make_detector` reads (model file excluded)."""
    options = (
        click.option(
            "--score",
            "detector_score",
            type=click.FloatRange(0, 1),
            default=0.25,
            show_default=True,
            help="Minimum detector score.",
        ),
        click.option(
            "--iou",
            "detector_iou",
            type=click.FloatRange(0, 1, min_open=True),
            default=0.45,
            show_default=True,
            help="NMS IoU threshold (per class).",
        ),
        click.option(
            "--classes",
            "detector_classes",
            default=DEFAULT_CLASSES,
            show_default=True,
            help="Model class index = slopedist class name; other classes are dropped.",
        ),
        click.option(
            "--layout",
            "detector_layout",
            type=click.Choice([v.value for v in OutputLayout]),
            default=OutputLayout.AUTO.value,
            show_default=True,
            help="Output layout of the model (auto: from its output shapes; docs/detectors.md).",
        ),
        click.option(
            "--input-size",
            "detector_input_size",
            help="WIDTHxHEIGHT network input, for models with a dynamic input size.",
        ),
        click.option(
            "--bgr", "detector_bgr", is_flag=True, help="Feed BGR instead of RGB (YOLOX)."
        ),
        click.option(
            "--pixel-scale",
            "detector_pixel_scale",
            type=float,
            default=1 / 255,
            help="Factor of the 0–255 pixel values [default: 1/255; YOLOX: 1].",
        ),
        click.option(
            "--pad-top-left",
            "detector_pad_top_left",
            is_flag=True,
            help="Letterbox padding at the bottom/right only (YOLOX) instead of centred.",
        ),
        click.option(
            "--logits",
            "detector_logits",
            type=click.Choice([v.value for v in LogitKind]),
            default=LogitKind.SIGMOID.value,
            show_default=True,
            help="DETR logits: one sigmoid per class, or softmax with a no-object class.",
        ),
        click.option(
            "--threads",
            "detector_threads",
            type=int,
            help="onnxruntime threads [default: its own].",
        ),
    )
    for option in reversed(options):
        func = option(func)
    return func


def make_detector(model: Path, **opts: Any) -> OnnxDetector:
    """An :class:`OnnxDetector` from ``model`` and the values of :func:`detector_options`."""
    return OnnxDetector(
        model,
        opts["detector_score"],
        opts["detector_iou"],
        parse_class_map(opts["detector_classes"]),
        opts["detector_layout"],
        parse_size(opts["detector_input_size"]),
        bgr_input=opts["detector_bgr"],
        pixel_scale=opts["detector_pixel_scale"],
        pad_centre=not opts["detector_pad_top_left"],
        logit_kind=opts["detector_logits"],
        threads=opts["detector_threads"],
    )


@click.command("detect")
@click.argument("frames", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--detector",
    "model",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="ONNX detector (YOLOv5/v8/v10/11, YOLOX, RT-DETR, DETR export; docs/detectors.md).",
)
@click.option(
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    default=Path("boxes.csv"),
    show_default=True,
    help="Box CSV to write (what `slopedist run --boxes` reads).",
)
@click.option(
    "--timing",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write per-frame detection times (ms) to this CSV.",
)
@detector_options
def detect(frames: Path, model: Path, out: Path, timing: Path | None, **opts: Any) -> None:
    """Detect vehicles in FRAMES (a video or image folder) with an ONNX model."""
    detector = make_detector(model, **opts)
    summary = detect_video(detector, open_frames(frames), out, timing)
    click.echo(
        f"{summary.boxes} boxes in {summary.detected_frames} of {summary.frames} frames "
        f"written to {out}; detection {summary.mean_detection_ms:.1f} ms/frame "
        f"(inference {summary.mean_inference_ms:.1f} ms)",
        err=True,
    )
