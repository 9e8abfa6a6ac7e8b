"""``slopedist camera calibrate``: camera intrinsics from a checkerboard video or image folder."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import click
import numpy as np
from numpy.typing import NDArray

from slopedist.cli.choice import SuggestingGroup
from slopedist.cli.options import BoundedFloat, parse_size
from slopedist.io.checkerboard import calibrate_checkerboard, write_opencv_yaml
from slopedist.io.frames import open_frames
from slopedist.io.outputs import check_outputs_spare_inputs


def _every(path: Path, step: int) -> Iterator[NDArray[np.uint8]]:
    """Every ``step``-th readable frame of a video or image folder."""
    for frame in open_frames(path):
        if frame.index % step == 0 and frame.ok and frame.image is not None:
            yield frame.image


@click.group("camera", cls=SuggestingGroup)
def camera_group() -> None:
    """Camera intrinsics (focal lengths, principal point, lens distortion)."""


@camera_group.command("calibrate")
@click.argument("frames", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--pattern",
    required=True,
    help="Inner corners of the checkerboard, COLUMNSxROWS (e.g. 9x6 for a 10×7-square board).",
)
@click.option(
    "--square",
    "square_m",
    type=BoundedFloat(0.0, unit="m"),
    default=1.0,
    show_default=True,
    help="Side of one square, metres (does not change the intrinsics).",
)
@click.option(
    "--every",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Use every N-th frame (videos: consecutive frames add little).",
)
@click.option(
    "--max-views",
    type=click.IntRange(min=3),
    default=40,
    show_default=True,
    help="Fit at most this many views, spread evenly over those with the board found.",
)
@click.option(
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="OpenCV YAML to write (what --calib reads).",
)
def calibrate_camera(
    frames: Path, pattern: str, square_m: float, every: int, max_views: int, out: Path
) -> None:
    """Calibrate the camera from FRAMES (a video or image folder) showing a checkerboard."""
    check_outputs_spare_inputs([out], [frames])
    size = parse_size(pattern, "COLUMNSxROWS of inner corners", "--pattern")
    fit = calibrate_checkerboard(_every(frames, every), size or (0, 0), square_m, max_views)
    write_opencv_yaml(fit, out)
    K = fit.intrinsics.K
    click.echo(
        f"board found in {fit.n_found} of {fit.n_frames} frames, {fit.n_views} views fitted; "
        f"RMS reprojection error {fit.rms_px:.3f} px\nfx {K[0, 0]:.2f}  fy {K[1, 1]:.2f}  "
        f"cx {K[0, 2]:.2f}  cy {K[1, 2]:.2f}  "
        f"distortion {np.array2string(fit.intrinsics.dist, precision=5)}\n"
        f"written to {out}"
    )
    for warning in fit.warnings:
        click.echo(f"warning: {warning}", err=True)
