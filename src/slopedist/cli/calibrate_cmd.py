"""``slopedist calibrate``: estimate the camera's mount angle θ0 and height from a sequence.

Runs ``ours-selfcal`` over one sequence (the same inputs as ``slopedist estimate``) and reports
its online self-calibration as it converges, then the final estimate with its 1σ uncertainty
and the options to pass to ``estimate``/``eval`` with it. The configured ``--height`` and
``--mount-angle`` are the prior (a rough calibration is enough).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import click

from slopedist.cli.options import lookback_option, sequence_file_options
from slopedist.datasets.sequence_files import SequenceFiles, read_sequence_files
from slopedist.errors import MissingInputError
from slopedist.estimators import EstimatorConfig, Method, build_estimator
from slopedist.estimators.ours import Calibration, OursEstimator
from slopedist.io.tables import write_json
from slopedist.pipeline import FrameStep, stream_track
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
@sequence_file_options
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
@lookback_option
def calibrate(
    files: SequenceFiles,
    every_s: float,
    json_out: Path | None,
    lookback_s: float,
) -> None:
    """Estimate the mount angle θ0 and the camera height from the targets of one sequence."""
    seq = read_sequence_files(files)
    if len(seq.boxes) == 0:
        raise MissingInputError(f"{files.boxes}: no boxes to calibrate from")
    est = build_estimator(EstimatorConfig(Method.OURS_SELFCAL.value), seq.camera)
    assert isinstance(est, OursEstimator)
    history = [_row(0.0, est.calibration())]
    next_report = every_s
    t0 = float(seq.track.timestamps_s[0]) if len(seq.track) else 0.0
    t = 0.0
    for _, t, _ in stream_track(FrameStep(est, lookback_s), seq.track, seq.boxes):
        if t - t0 >= next_report:
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
        f"{math.degrees(files.mount_angle_rad):g}°, {files.height_m:g} m)\n"
        f"use: --mount-angle {math.degrees(final.mount_angle_rad):.2f} "
        f"--height {final.height_m:.3f}"
    )
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        keys = ("t_s", "theta0_deg", "sigma_deg", "height_m", "sigma_m", "targets", "vehicles")
        prior = {"mount_angle_deg": math.degrees(files.mount_angle_rad), "height_m": files.height_m}
        write_json(
            json_out,
            {
                "final": _as_json(final),
                "prior": prior,
                "history": [dict(zip(keys, r)) for r in history],
            },
        )
        click.echo(f"wrote {json_out}", err=True)
