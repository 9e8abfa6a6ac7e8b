"""``slopedist detect``: an ONNX detector over a video or image folder → the slopedist box CSV."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from slopedist.cli.options import detector_options, make_detector
from slopedist.io.detections.video import detect_video
from slopedist.io.frames import open_frames
from slopedist.io.outputs import check_outputs_spare_inputs


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
@detector_options()
def detect(frames: Path, model: Path, out: Path, timing: Path | None, **opts: Any) -> None:
    """Detect vehicles in FRAMES (a video or image folder) with an ONNX model."""
    check_outputs_spare_inputs([out, timing], [frames, model])
    detector = make_detector(model, **opts)
    summary = detect_video(detector, open_frames(frames), out, timing)
    click.echo(
        f"{summary.boxes} boxes in {summary.detected_frames} of {summary.frames} frames "
        f"written to {out}; detection {summary.mean_detection_ms:.1f} ms/frame "
        f"(inference {summary.mean_inference_ms:.1f} ms)",
        err=True,
    )
