"""``slopedist calibrate``: estimate the camera's mount angle θ0 and height from a drive.

Runs ``ours-selfcal`` over one drive and reports its online self-calibration as it converges,
then the final estimate with an honest 1σ (the fit, the spread of independent stretches of the
drive and the model floor; :mod:`slopedist.streaming.mount_calibration`) and either the options to
pass to
``estimate``/``eval``/``run`` or, when the data cannot tell the estimate from the configured
mount, the advice to keep that. The drive is files (``--poses`` and ``--boxes``, as
``estimate``), or FRAMES (an image folder or video): the built-in odometry computes the
rotations and the boxes come from ``--boxes`` or an ONNX ``--detector``. The configured
``--height`` and ``--mount-angle`` are the prior (a rough calibration is enough).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import click
from tqdm import tqdm

from slopedist.cli.options import (
    FPS,
    SECONDS,
    detector_options,
    drive_file_options,
    lookback_option,
    make_detector,
)
from slopedist.core.errors import ConfigurationError, MissingInputError
from slopedist.estimators.base import SelfCalibration
from slopedist.evaluation.table import format_table
from slopedist.io.formatting import write_json
from slopedist.io.frames import open_frames
from slopedist.io.outputs import check_outputs_spare_inputs
from slopedist.io.sequence_files import SequenceFiles, read_sequence_files
from slopedist.streaming.mount_calibration import (
    MountAdvice,
    MountSigma,
    advise_from_frames,
    advise_mount,
)

HISTORY_KEYS = ("t_s", "theta0_deg", "sigma_deg", "height_m", "sigma_m", "targets", "vehicles")


class _History:
    """The running estimate every ``every_s`` seconds of the drive."""

    def __init__(self, every_s: float) -> None:
        self.every_s = every_s
        self.rows: list[list[Any]] = []
        self.t0: float | None = None
        self.next_report = 0.0
        self.last: tuple[float, SelfCalibration] | None = None

    def __call__(self, t: float, c: SelfCalibration) -> None:
        if self.t0 is None:
            self.t0 = t
        if t - self.t0 >= self.next_report:
            self.rows.append(_row(t - self.t0, c))
            self.next_report += self.every_s
        self.last = (t - self.t0, c)

    def finish(self) -> list[list[Any]]:
        if self.last is not None and (not self.rows or self.rows[-1][0] != self.last[0]):
            self.rows.append(_row(*self.last))
        return self.rows


def _row(t: float, c: SelfCalibration) -> list[Any]:
    return [
        t,
        math.degrees(c.mount_angle_rad),
        math.degrees(c.mount_angle_sigma_rad),
        c.height_m,
        c.height_sigma_m,
        c.n_observations,
        c.n_tracks,
    ]


def _sigma_part(name: str, sigma: MountSigma, unmeasured: str | None) -> str:
    """``"name 0.24°, 0.075 m"`` (θ0 in degrees, h in metres), or why the part was not
    measured (its zeros are no evidence of a small error)."""
    if unmeasured is not None:
        return f"{name} not measured ({unmeasured})"
    return f"{name} {math.degrees(sigma.mount_angle_rad):.2f}°, {sigma.height_m:.3f} m"


def advice_text(advice: MountAdvice) -> str:
    """The final estimate, its uncertainty and what to do (several lines)."""
    e, s = advice.estimate, advice.sigma
    deg = math.degrees
    n_seen = sum(c.n_observations > 0 for c in advice.segments)
    spread = _sigma_part(
        f"spread of {len(advice.segments)} stretches",
        advice.spread,
        f"targets in {n_seen} of them" if n_seen < 2 else None,
    )
    vehicles = _sigma_part(
        "leave-one-vehicle-out",
        advice.vehicles,
        f"{e.n_tracks} vehicle{'s' * (e.n_tracks != 1)}" if e.n_tracks < 3 else None,
    )
    told = "the data cannot tell it"
    mount = (
        told
        if "mount_angle" in advice.untold
        else f"{deg(e.mount_angle_rad):.2f}° ± {deg(s.mount_angle_rad):.2f}°"
    )
    height = told if "height" in advice.untold else f"{e.height_m:.3f} m ± {s.height_m:.3f} m"
    lines = [
        f"mount angle θ0 = {mount}, camera height h = {height} (1σ; from {e.n_observations} "
        f"targets of {e.n_tracks} vehicles; configured {deg(advice.prior.mount_angle_rad):g}°, "
        f"{advice.prior.height_m:g} m)",
        f"1σ parts: {_sigma_part('fit', advice.fit, None)}; {spread}; {vehicles}; "
        f"{_sigma_part('model floor', advice.floor, None)}",
        f"box shapes: {advice.estimate.n_shape_outliers} of {advice.estimate.n_shape_checked} "
        "targets unlike their class (left out)",
        *advice.reasons,
    ]
    if advice.declined:
        lines.append("no advice: keep the configured mount")
    else:
        lines.append(
            f"use: --mount-angle {deg(advice.mount_angle_rad):.2f} --height {advice.height_m:.3f}"
            " (the configured mount moved only as far as needed to agree with the estimate)"
        )
    return "\n".join(lines)


def final_dict(advice: MountAdvice) -> dict[str, Any]:
    """The final estimate as the text gives it (degrees and metres): the whole drive's θ0 and
    h with the total 1σ (``advice.sigma``), not the fit's alone; ``None`` for a parameter the
    drive cannot tell (``advice.untold``: its estimate rests on the configured value)."""
    final = {
        **advice.as_dict()["estimate"],
        "mount_angle_sigma_deg": math.degrees(advice.sigma.mount_angle_rad),
        "height_sigma_m": advice.sigma.height_m,
    }
    for name, keys in (
        ("mount_angle", ("mount_angle_deg", "mount_angle_sigma_deg")),
        ("height", ("height_m", "height_sigma_m")),
    ):
        if name in advice.untold:
            final.update(dict.fromkeys(keys))
    return final


@click.command("calibrate")
@click.argument("frames", required=False, type=click.Path(path_type=Path))
@drive_file_options
@click.option(
    "--detector",
    "detector_model",
    type=click.Path(dir_okay=False, path_type=Path),
    help="With FRAMES: ONNX detector run on every frame instead of --boxes (docs/detectors.md).",
)
@click.option(
    "--fps",
    type=FPS,
    default=None,
    help="With FRAMES: frames per second [default: 10 for an image folder, the video's rate].",
)
@click.option(
    "--timestamps",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="With FRAMES: timestamps file, one per frame; overrides --fps.",
)
@click.option(
    "--every",
    "every_s",
    type=SECONDS,
    default=5.0,
    show_default=True,
    help="Print the running estimate every EVERY seconds.",
)
@click.option(
    "--json",
    "json_out",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write the final estimate, the advice and the history as JSON here.",
)
@lookback_option
@detector_options("detector-")
def calibrate(
    frames: Path | None,
    files: SequenceFiles,
    detector_model: Path | None,
    fps: float | None,
    timestamps: Path | None,
    every_s: float,
    json_out: Path | None,
    lookback_s: float,
    **detector_opts: Any,
) -> None:
    """Estimate the mount angle θ0 and the camera height from the targets of one drive.

    Give the drive as --poses and --boxes files, or as FRAMES (image folder or video) with
    --boxes or --detector: the built-in visual odometry then computes the rotations.
    """
    inputs = [*files.input_files, frames, timestamps, detector_model]
    check_outputs_spare_inputs([json_out], inputs)
    history = _History(every_s)
    if frames is None:
        if files.poses is None or files.boxes is None or detector_model is not None:
            raise click.UsageError(
                "give FRAMES (with --boxes or --detector), or --poses and --boxes"
            )
        seq = read_sequence_files(files)
        if len(seq.boxes) == 0:
            raise MissingInputError(f"{files.boxes}: no boxes to calibrate from")
        advice = advise_mount(seq.camera, seq.track, seq.boxes, lookback_s, on_frame=history)
    else:
        if files.poses is not None:
            raise ConfigurationError(
                "FRAMES gives the rotations (built-in odometry): leave out --poses"
            )
        detector = (
            None
            if detector_model is None
            else make_detector(detector_model, "detector-", **detector_opts)
        )
        source = open_frames(frames, fps, timestamps)
        if files.image_size is None:  # the frames' size for the border test, as in `run`
            files = dataclasses.replace(files, image_size=source.frame_size())
        bar = tqdm(total=source.expected_frames(), unit="frame", desc="odometry", disable=None)
        with bar:
            advice = advise_from_frames(
                source,
                files,
                detector,
                lookback_s,
                on_frame=history,
                on_read=lambda _: bar.update(),
            )
    rows = history.finish()
    click.echo(format_table(list(HISTORY_KEYS), rows))
    click.echo("\n" + advice_text(advice))
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        write_json(
            json_out,
            {
                "final": final_dict(advice),
                "advice": advice.as_dict(),
                "history": [dict(zip(HISTORY_KEYS, r)) for r in rows],
            },
        )
        click.echo(f"wrote {json_out}", err=True)
