"""``slopedist estimate``: one sequence of precomputed rotations and boxes → per-target CSV."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import click
import numpy as np

from slopedist.cli.method_options import (
    check_methods,
    estimator_options,
    generic_class_option,
    ours_config,
)
from slopedist.cli.options import lookback_option, sequence_file_options, vehicle_classes_option
from slopedist.cli.record_summary import RecordTally
from slopedist.core.errors import ConfigurationError
from slopedist.estimators import ESTIMATORS, EstimatorConfig, build_estimator
from slopedist.estimators.ours.selfcal import estimator_calibration_warning
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.formatting import CsvStreamWriter
from slopedist.io.outputs import check_outputs_spare_inputs, output_file, partial_path
from slopedist.io.sequence_files import SequenceFiles, read_sequence_files
from slopedist.odometry.base import RotationTrack
from slopedist.streaming.frame_times import long_step_warning
from slopedist.streaming.step import (
    FrameStep,
    close_records,
    iter_records,
    open_records,
    stream_track,
)


@click.command("estimate")
@sequence_file_options
@click.option("--method", default="paper", show_default=True, help="Estimator name.")
@click.option(
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the records CSV here (default: standard output).",
)
@vehicle_classes_option
@lookback_option
@estimator_options()
@generic_class_option
def estimate(
    files: SequenceFiles,
    method: str,
    out: Path | None,
    vehicle_classes: tuple[str, ...],
    lookback_s: float,
    estimator_config: EstimatorConfig,
    generic_classes: tuple[str, ...],
) -> None:
    """Estimate per-target distances for one sequence, streaming frame by frame.

    An offline method (ours-offline) writes its records when the sequence ends."""
    check_methods([method])
    config = ours_config(estimator_config, method, generic_classes, vehicle_classes)
    if getattr(ESTIMATORS.get(method), "needs_depth", False):  # every record would be no_depth
        raise ConfigurationError(
            f"method '{method}' needs depth maps, which slopedist estimate does not take: use "
            "slopedist run FRAMES --depth-dir DIR or --depth-model MODEL.onnx, or slopedist "
            "eval kitti-tracking --depth-dir DIR"
        )
    written = [out, partial_path(out)] if out is not None else []
    check_outputs_spare_inputs(written, files.input_files)
    seq = read_sequence_files(files)  # the camera knows --image-size, if given
    estimator = build_estimator(config, seq.camera)
    step = FrameStep(estimator, lookback_s, vehicle_classes)
    tally = RecordTally()
    if out is not None:  # whole: the file takes its name when every record is written
        with output_file(out) as stream:
            write_estimates(CsvStreamWriter(stream), step, seq.track, seq.boxes, method, tally)
    else:
        try:
            write_estimates(open_records(None), step, seq.track, seq.boxes, method, tally)
        except BrokenPipeError:
            quiet_closed_stdout()  # the reader (e.g. `| head -1`) has all it wanted
            return
    for line in tally.lines(out):
        click.echo(line, err=True)
    notes = (
        long_step_warning(np.diff(seq.track.timestamps_s), lookback_s),
        estimator_calibration_warning(estimator),
    )
    for note in notes:
        if note is not None:
            click.echo(note, err=True)


def write_estimates(
    writer: CsvStreamWriter,
    step: FrameStep,
    track: RotationTrack,
    boxes: BoxTable,
    method: str,
    tally: RecordTally,
) -> None:
    """The records (of ``method``) of every frame of ``track`` with ``boxes``, frame by frame
    (an offline method's at the end, from its pass over the sequence), counted in ``tally``;
    then ``writer`` is closed."""
    estimator = step.estimator
    held: list[tuple[BoxTable, float]] = []  # an offline method's frames, written at the end
    for frame_boxes, t, result in stream_track(step, track, boxes):
        if estimator.offline:
            if len(frame_boxes):
                held.append((frame_boxes, t))
            continue
        writer.write_rows(tally.count(iter_records(frame_boxes, t, result.estimates, method)))
    if held:
        for (frame_boxes, t), est in zip(held, step.finish(), strict=True):
            writer.write_rows(tally.count(iter_records(frame_boxes, t, est, method)))
    close_records(writer)


def quiet_closed_stdout() -> None:
    """Point standard output at the null device, so that nothing more (not even Python's own
    flush at exit) fails on a pipe whose reader is gone."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
