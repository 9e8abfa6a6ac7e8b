"""``slopedist estimate``: one sequence of precomputed rotations and boxes → per-target CSV."""

from __future__ import annotations

from pathlib import Path

import click

from slopedist.cli.options import (
    check_methods,
    estimator_options,
    lookback_option,
    sequence_file_options,
)
from slopedist.datasets.sequence_files import SequenceFiles, read_sequence_files
from slopedist.estimators import EstimatorConfig, build_estimator
from slopedist.pipeline import FrameStep, close_records, iter_records, open_records, stream_track


@click.command("estimate")
@sequence_file_options
@click.option("--method", default="paper", show_default=True, help="Estimator name.")
@click.option(
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the records CSV here (default: standard output).",
)
@lookback_option
@estimator_options()
def estimate(
    files: SequenceFiles,
    method: str,
    out: Path | None,
    lookback_s: float,
    estimator_config: EstimatorConfig,
) -> None:
    """Estimate per-target distances for one sequence, streaming frame by frame."""
    check_methods([method])
    seq = read_sequence_files(files)
    step = FrameStep(build_estimator(estimator_config.with_method(method), seq.camera), lookback_s)
    writer = open_records(out)
    n = 0
    try:
        for frame_boxes, t, result in stream_track(step, seq.track, seq.boxes):
            n += writer.write_rows(iter_records(frame_boxes, t, result.estimates, method))
    finally:
        close_records(writer)
    if out:
        click.echo(f"wrote {n} records to {out}", err=True)
