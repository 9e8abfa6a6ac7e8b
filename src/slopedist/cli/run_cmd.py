"""``slopedist run``: frames (image folder or video) + boxes → per-target distances, from pixels."""

from __future__ import annotations

import math
from pathlib import Path

import click

from slopedist.camera import Camera
from slopedist.cli.options import (
    alphas_option,
    check_methods,
    height_option,
    lookback_option,
    mount_option,
    paper_options,
    thresholds_option,
)
from slopedist.detections.readers import read_box_file
from slopedist.errors import ConfigurationError
from slopedist.estimators import Estimator, available_methods, make_estimator
from slopedist.io.frames import open_frames
from slopedist.odometry import make_odometry
from slopedist.odometry.base import RotationOdometry
from slopedist.runner import FRAMES_NAME, RECORDS_NAME, RunResult, run_frames

ODOMETRY_BACKENDS = ("builtin", "orbslam3")


def default_method() -> str:
    """``ours`` once it is registered, else the paper's method."""
    return "ours" if "ours" in available_methods() else "paper"


def build_odometry(name: str, camera: Camera, vocab: Path | None = None) -> RotationOdometry:
    """The rotation source ``name`` (``builtin`` or ``orbslam3``) for ``camera``."""
    if name == "orbslam3":
        return make_odometry(name, camera, vocabulary=vocab)
    if vocab is not None:
        raise ConfigurationError("--vocab is only used with --odometry orbslam3")
    return make_odometry(name, camera)


def check_runnable(estimator: Estimator) -> None:
    """Fail for methods ``run`` cannot feed: those defined on another rotation source (IMU) or
    needing depth maps."""
    source = getattr(estimator, "rotation_source", None)
    if source is not None:
        raise ConfigurationError(
            f"method '{estimator.name}' is defined on '{source}' rotations; slopedist run feeds "
            "visual-odometry rotations from the frames (use slopedist estimate with pose files)"
        )
    if estimator.needs_depth:
        raise ConfigurationError(
            f"method '{estimator.name}' needs depth maps, which slopedist run does not produce"
        )


@click.command("run")
@click.argument("frames", type=click.Path(path_type=Path))
@click.option("--calib", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="KITTI calib file of the frames' camera (P2; P0 for odometry calib.txt).")
@click.option("--boxes", "boxes_path", required=True,
              type=click.Path(dir_okay=False, path_type=Path),
              help="Boxes per frame: slopedist CSV, KITTI labels or PointRCNN file.")
@click.option("--method", default=None,
              help="Estimator name [default: ours when available, else paper].")
@click.option("--odometry", type=click.Choice(ODOMETRY_BACKENDS), default="builtin",
              show_default=True, help="Visual odometry backend (orbslam3 is an optional extra).")
@click.option("--vocab", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="ORB vocabulary (ORBvoc.txt) for --odometry orbslam3 "
                   "[default: $PYORBSLAM3_VOCAB].")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              default=Path("slopedist_run"), show_default=True,
              help="Output folder: records.csv, frames.csv, run.json, overlay.")
@click.option("--overlay", is_flag=True,
              help="Also write annotated frames (paper Fig. 3 style).")
@click.option("--overlay-format", type=click.Choice(["mp4", "png"]), default="mp4",
              show_default=True, help="Overlay as OUT/overlay.mp4 or as PNG files in OUT/overlay/.")
@click.option("--fps", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Frames per second for timestamps [default: 10 for an image folder, the "
                   "container's rate for a video].")
@click.option("--timestamps", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Timestamps file, one per frame (seconds or KITTI date-times); "
                   "overrides --fps.")
@click.option("--score", type=float, default=None, help="Keep boxes with score >= SCORE.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@height_option
@mount_option
@lookback_option
@alphas_option
@thresholds_option
def run(
    frames: Path, calib: Path, boxes_path: Path, method: str | None, odometry: str,
    vocab: Path | None, out_dir: Path, overlay: bool, overlay_format: str, fps: float | None,
    timestamps: Path | None, score: float | None, quiet: bool, height_m: float,
    mount_angle_deg: float, lookback_s: float, alphas: str, thresholds: str,
) -> None:
    """Estimate distances from FRAMES (an image folder or a video file) and per-frame boxes.

    The camera rotation comes from visual odometry on the frames; records are written to
    OUT/records.csv frame by frame, with a per-frame log in OUT/frames.csv.
    """
    method = method or default_method()
    check_methods([method])
    camera = Camera.from_kitti_calib(calib, "P2", height_m, math.radians(mount_angle_deg))
    source = open_frames(frames, fps, timestamps)
    boxes = read_box_file(boxes_path, score)
    options = paper_options(alphas, thresholds) if method == "paper" else {}
    estimator = make_estimator(method, camera, **options)
    check_runnable(estimator)
    backend = build_odometry(odometry, camera, vocab)
    overlay_path = None
    if overlay:
        overlay_path = out_dir / ("overlay.mp4" if overlay_format == "mp4" else "overlay")
    overlay_fps = fps or getattr(source, "container_fps", 0.0) or 10.0
    result = run_frames(
        source, camera, boxes, backend, estimator, out_dir, lookback_s=lookback_s,
        overlay=overlay_path, overlay_fps=overlay_fps, progress=not quiet,
    )
    click.echo(summary_text(result, out_dir), err=True)


def summary_text(result: RunResult, out_dir: Path) -> str:
    """A few lines that tell what a run did and where its output is."""
    states = ", ".join(f"{k} {v}" for k, v in sorted(result.odometry_states.items())) or "none"
    status = ", ".join(f"{k} {v}" for k, v in sorted(result.frame_status.items()))
    lines = [
        f"wrote {result.records} records ({result.estimated} with a distance, method "
        f"{result.method}) to {out_dir / RECORDS_NAME}",
        f"frames: {result.frames} ({status}); odometry: {states}; per-frame log "
        f"{out_dir / FRAMES_NAME}",
        f"{result.frames_per_s:.1f} frames/s; odometry {result.odometry_ms_mean:.1f} ms, "
        f"estimation {result.estimation_ms_mean:.2f} ms per frame",
    ]
    if result.boxes_without_frame:
        lines.append(f"warning: {result.boxes_without_frame} boxes refer to frames that are not "
                     "in FRAMES and were not used")
    if result.overlay:
        lines.append(f"overlay: {result.overlay}")
    return "\n".join(lines)
