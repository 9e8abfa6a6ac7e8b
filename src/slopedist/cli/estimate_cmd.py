"""``slopedist estimate``: one sequence of precomputed rotations and boxes → per-target CSV."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import click

from slopedist.cli.method_options import (
    check_methods,
    estimator_options,
    generic_class_option,
    ours_config,
    user_reference,
)
from slopedist.cli.options import lookback_option, sequence_file_options, vehicle_classes_option
from slopedist.cli.record_summary import RecordTally
from slopedist.cli.run_options import columns_option
from slopedist.core.errors import ConfigurationError
from slopedist.estimators import ESTIMATORS, EstimatorConfig, build_estimator
from slopedist.io.detections.readers import CSV_TRUTH_COLUMN
from slopedist.io.formatting import STDOUT_PATH, CsvStreamWriter
from slopedist.io.outputs import check_outputs_spare_inputs, output_file, partial_path
from slopedist.io.sequence_files import SequenceFiles, SequenceInputs, read_sequence_files
from slopedist.streaming.pipeline import FinishResult, Pipeline, stream_rotations
from slopedist.streaming.step import RecordColumns, close_records, open_records


@click.command("estimate")
@sequence_file_options
@click.option("--method", default="paper", show_default=True, help="Estimator name.")
@click.option(
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the records CSV here (default: standard output).",
)
@columns_option
@vehicle_classes_option
@lookback_option
@estimator_options()
@generic_class_option
def estimate(
    files: SequenceFiles,
    method: str,
    out: Path | None,
    columns: str,
    vehicle_classes: tuple[str, ...],
    lookback_s: float,
    estimator_config: EstimatorConfig,
    generic_classes: tuple[str, ...],
) -> None:
    """Estimate per-target distances for one sequence, streaming frame by frame.

    An offline method (ours-offline) writes its records when the sequence ends."""
    check_methods([method])
    estimator_config, reference = user_reference(estimator_config)
    config = ours_config(estimator_config, method, generic_classes, vehicle_classes)
    if getattr(ESTIMATORS.get(method), "needs_depth", False):  # every record would be no_depth
        raise ConfigurationError(
            f"method '{method}' needs depth maps, which slopedist estimate does not take: use "
            "slopedist run FRAMES --depth-dir DIR or --depth-model MODEL.onnx, or slopedist "
            "eval kitti-tracking --depth-dir DIR"
        )
    if out is not None and str(out) == STDOUT_PATH:  # '-': standard output
        out = None
    written = [out, partial_path(out)] if out is not None else []
    check_outputs_spare_inputs(written, files.input_files)
    seq = read_sequence_files(files)  # the camera knows --image-size, if given
    estimator = build_estimator(config, seq.camera)
    pipe = Pipeline.from_parts(
        estimator, lookback_s=lookback_s, vehicle_classes=vehicle_classes, reference=reference
    )
    tally = RecordTally()
    chosen = RecordColumns(columns)
    if out is not None:  # whole: the file takes its name when every record is written
        with output_file(out) as stream:
            end = write_estimates(CsvStreamWriter(stream), pipe, seq, tally, chosen)
    else:
        try:
            end = write_estimates(open_records(None), pipe, seq, tally, chosen)
        except BrokenPipeError:
            quiet_closed_stdout()  # the reader (e.g. `| head -1`) has all it wanted
            return
    for line in [*tally.lines(out), *end.warnings]:
        click.echo(line, err=True)


def write_estimates(
    writer: CsvStreamWriter,
    pipe: Pipeline,
    seq: SequenceInputs,
    tally: RecordTally,
    columns: RecordColumns = RecordColumns.DEFAULT,
) -> FinishResult:
    """The records (of ``columns``) of every frame of ``seq`` through ``pipe``, frame by frame
    (an offline method's at the end, from its pass over the sequence), counted in ``tally``;
    then ``writer`` is closed. Returns the pipeline's end (:meth:`Pipeline.finish`)."""
    for result in stream_rotations(pipe, seq.track, seq.boxes):
        if not pipe.offline:  # an offline method's records come when the sequence ends
            writer.write_rows(tally.count(result.to_records(columns)))
    end = pipe.finish()
    writer.write_rows(tally.count(end.to_records(columns)))
    close_records(writer, columns, CSV_TRUTH_COLUMN in seq.boxes.extra)
    return end


def quiet_closed_stdout() -> None:
    """Point standard output at the null device, so that nothing more (not even Python's own
    flush at exit) fails on a pipe whose reader is gone."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
