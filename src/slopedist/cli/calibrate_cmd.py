"""``slopedist calibrate``: estimate the camera's mount angle θ0 and height from a sequence.

Runs ``ours-selfcal`` over one sequence (the same inputs as ``slopedist estimate``) and reports
its online self-calibration as it converges, then the final estimate with its 1σ uncertainty
and the options to pass to ``estimate``/``eval`` with it. The configured ``--height`` and
``--mount-angle`` are the prior (a rough calibration is enough).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import click
import numpy as np

from slopedist.cli.estimate_cmd import read_sequence_inputs, sequence_input_options
from slopedist.cli.options import height_option, lookback_option, mount_option
from slopedist.errors import MissingInputError
from slopedist.estimators.ours import Calibration, OursEstimator
from slopedist.pipeline import StreamingEstimator
from slopedist.tables import format_table


def _row(t: float, c: Calibration) -> list[Any]:
    return [
        t,
        math.degrees(c.mount_angle_rad),
        math.degrees(c.mount_angle_sigma_rad),
        c.height_m,
        c.height_sigma_m,
        c.n_observations,
        c.n_tracks,
    ]


def _as_json(c: Calibration) -> dict[str, Any]:
    return {
        "mount_angle_deg": math.degrees(c.mount_angle_rad),
        "mount_angle_sigma_deg": math.degrees(c.mount_angle_sigma_rad),
        "height_m": c.height_m,
        "height_sigma_m": c.height_sigma_m,
        "n_observations": c.n_observations,
        "n_tracks": c.n_tracks,
    }


@click.command("calibrate")
@sequence_input_options
@click.option(
    "--every",
    "every_s",
    type=click.FloatRange(min=0, min_open=True),
    default=5.0,
    show_default=True,
    help="Print the running estimate every EVERY seconds.",
)
@click.option(
    "--json",
    "json_out",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write the final estimate and its history as JSON here.",
)
@height_option
@mount_option
@lookback_option
def calibrate(
    calib: Path,
    poses: Path,
    boxes_path: Path,
    pose_format: str,
    frame_period: float,
    score: float | None,
    every_s: float,
    json_out: Path | None,
    height_m: float,
    mount_angle_deg: float,
    lookback_s: float,
) -> None:
    """Estimate the mount angle θ0 and the camera height from the targets of one sequence."""
    camera, track, boxes = read_sequence_inputs(
        calib, poses, boxes_path, pose_format, frame_period, score, height_m, mount_angle_deg
    )
    if len(boxes) == 0:
        raise MissingInputError(f"{boxes_path}: no boxes to calibrate from")
    est = OursEstimator(camera, self_calibrate=True)
    stream = StreamingEstimator(est, lookback_s)
    by_frame = boxes.frame_index()
    empty = boxes.select(np.zeros(len(boxes), dtype=bool))
    history = [_row(0.0, est.calibration())]
    next_report = every_s
    t = 0.0
    for k in range(len(track)):
        t = float(track.timestamps_s[k])
        R = track.R_world_cam[k] if track.valid[k] else None
        stream.update(k, t, R, by_frame.get(k, empty))
        if t - float(track.timestamps_s[0]) >= next_report:
            history.append(_row(t, est.calibration()))
            next_report += every_s
    final = est.calibration()
    if history[-1][0] != t:
        history.append(_row(t, final))
    click.echo(
        format_table(
            ["t_s", "theta0_deg", "sigma_deg", "height_m", "sigma_m", "targets", "vehicles"],
            history,
        )
    )
    click.echo(
        f"\nmount angle θ0 = {math.degrees(final.mount_angle_rad):.2f}° "
        f"± {math.degrees(final.mount_angle_sigma_rad):.2f}°, camera height h = "
        f"{final.height_m:.3f} m ± {final.height_sigma_m:.3f} m "
        f"(from {final.n_observations} targets of {final.n_tracks} vehicles; prior "
        f"{mount_angle_deg:g}°, {height_m:g} m)\n"
        f"use: --mount-angle {math.degrees(final.mount_angle_rad):.2f} "
        f"--height {final.height_m:.3f}"
    )
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        keys = ("t_s", "theta0_deg", "sigma_deg", "height_m", "sigma_m", "targets", "vehicles")
        json_out.write_text(
            json.dumps(
                {
                    "final": _as_json(final),
                    "prior": {"mount_angle_deg": mount_angle_deg, "height_m": height_m},
                    "history": [dict(zip(keys, r)) for r in history],
                },
                indent=2,
            )
            + "\n"
        )
        click.echo(f"wrote {json_out}", err=True)
