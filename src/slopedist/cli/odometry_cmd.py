"""``slopedist odometry``: visual odometry from pixels, checked against ground truth."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import click
import cv2
import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from slopedist.cli.choice import Choice, SuggestingGroup
from slopedist.cli.options import lookback_option
from slopedist.core.errors import DataMismatchError, InputFileError, MissingInputError
from slopedist.io.formatting import STDOUT_PATH, dumps_json, write_json
from slopedist.io.kitti.odometry import KittiOdometrySequence, read_kitti_odometry
from slopedist.io.outputs import check_outputs_spare_inputs
from slopedist.odometry.accuracy import OdometryEvaluation, run_odometry
from slopedist.odometry.factory import available_odometry, make_odometry


@click.group("odometry", cls=SuggestingGroup)
def odometry_group() -> None:
    """Visual odometry (camera rotations from pixels)."""


@odometry_group.command("eval")
@click.argument("seq_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--backend",
    type=Choice(available_odometry()),
    default="builtin",
    show_default=True,
    help="Visual-odometry backend.",
)
@click.option(
    "--json",
    "json_out",
    type=click.Path(dir_okay=False, allow_dash=True, path_type=Path),
    help="Also write the figures as JSON here ('-': standard output only).",
)
@lookback_option
def eval_command(seq_dir: Path, backend: str, json_out: Path | None, lookback_s: float) -> None:
    """Rotation accuracy and speed on a KITTI-odometry-style folder SEQ_DIR.

    SEQ_DIR holds image_l/ (grey frames), poses.txt (ground truth, 3×4 camera-to-world per
    line) and calib.txt (first line P0). Prints, as JSON: frames; theta_rms_deg, the RMS error
    of the ego gradient θ (eq. 2–4, θ0 = 0) from the estimated rotations against θ from the
    true ones over the same look-back pairs; rel_rot_median_deg, the median angle of the
    rotation error over full look-back windows (10 frames at 10 Hz); ms_per_frame, the time
    inside the odometry per frame after image decoding, with OpenCV limited to one thread.
    """
    inputs = [seq_dir / name for name in ("calib.txt", "poses.txt", "times.txt")]
    if json_out is not None and str(json_out) != STDOUT_PATH:
        check_outputs_spare_inputs([json_out], inputs)
    seq = read_kitti_odometry(seq_dir)
    if json_out is not None and str(json_out) != STDOUT_PATH:  # nor a frame of image_l/
        check_outputs_spare_inputs([json_out], seq.image_paths)
    if seq.ground_truth is None:  # pragma: no cover - read_kitti_odometry requires poses
        raise MissingInputError(f"no ground-truth poses in {seq_dir}")
    # the built-in backend estimates the rotation over exactly this look-back
    options = {"lookback_s": lookback_s} if backend == "builtin" else {}
    odometry = make_odometry(backend, seq.camera, **options)
    frames = _Frames(seq)
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # the figure is "on one core"
    try:
        with tqdm(
            total=len(seq), unit="frame", desc=seq.root.name, disable=None, leave=False
        ) as bar:
            run = run_odometry(odometry, frames, on_result=lambda k, r: bar.update())
    except DataMismatchError as err:  # a frame of another size: name its file
        if frames.current is None:
            raise
        raise InputFileError(frames.current, str(err)) from None
    finally:
        cv2.setNumThreads(threads)
    figures = OdometryEvaluation.from_run(run, seq.ground_truth, lookback_s).as_dict()
    click.echo(dumps_json(figures), nl=False)
    if json_out is not None and str(json_out) != STDOUT_PATH:  # "-": already on stdout
        json_out.parent.mkdir(parents=True, exist_ok=True)
        write_json(json_out, figures)
        click.echo(f"wrote {json_out}", err=True)


class _Frames:
    """``(timestamp, image)`` pairs of a sequence, decoded one at a time; ``current`` is the
    file of the frame last given (for an error about that frame)."""

    def __init__(self, seq: KittiOdometrySequence) -> None:
        self.seq = seq
        self.current: Path | None = None

    def __iter__(self) -> Iterator[tuple[float, NDArray[np.uint8]]]:
        for k, t, image in self.seq.frames():
            self.current = self.seq.image_paths[k]
            yield t, image
