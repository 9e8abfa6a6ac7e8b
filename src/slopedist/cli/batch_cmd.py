"""``slopedist batch``: run many drives on Ray, resumably, into one output folder."""

from __future__ import annotations

from pathlib import Path

import click

from slopedist.batch import BatchOptions, BatchResult, DriveDefaults, DriveStatus, load_drives
from slopedist.batch.engine import DEFAULT_MAX_RETRIES, run_batch
from slopedist.batch.settings import RunSettings, unapplied
from slopedist.cli.choice import Choice
from slopedist.cli.method_options import (
    check_methods,
    generic_class_option,
    ours_option,
    parse_ours_options,
    reference_option,
)
from slopedist.cli.options import (
    height_option,
    lookback_option,
    mount_option,
    vehicle_classes_option,
)
from slopedist.cli.run_options import (
    columns_option,
    export_option,
    image_topic_option,
    overlay_format_option,
    overlay_option,
    run_offline_option,
)
from slopedist.estimators import DEFAULT_METHOD
from slopedist.streaming.pipeline import ODOMETRY_CHOICES


@click.command("batch")
@click.argument("source", type=click.Path(path_type=Path))
@click.option(
    "--out",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Output folder: OUT/<drive>/ per drive, status.csv, records.parquet/, fleet/.",
)
@click.option(
    "--method", default=None, help=f"Method of drives that name none [default: {DEFAULT_METHOD}]."
)
@click.option(
    "--odometry",
    type=Choice(ODOMETRY_CHOICES),
    default="builtin",
    show_default=True,
    help="Odometry of drives that name none.",
)
@click.option(
    "--workers",
    type=click.IntRange(min=1),
    default=None,
    help="CPUs of the embedded Ray instance [default: all cores]; not with --address.",
)
@click.option(
    "--address",
    default=None,
    help="Ray cluster address, e.g. 10.0.0.5:6379 [default: $RAY_ADDRESS, else an "
    "embedded Ray instance on this machine].",
)
@click.option("--fail-fast", is_flag=True, help="Stop at the first failed drive (exit code 1).")
@click.option("--force", is_flag=True, help="Run every drive again, complete or not.")
@click.option(
    "--max-retries",
    type=click.IntRange(min=0),
    default=DEFAULT_MAX_RETRIES,
    show_default=True,
    help="Retries of a drive whose worker process died.",
)
@click.option("--no-parquet", is_flag=True, help="Do not write the records.parquet dataset.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@height_option
@mount_option
@lookback_option
@reference_option
@ours_option
@generic_class_option
@vehicle_classes_option
@run_offline_option
@overlay_option
@overlay_format_option
@export_option
@columns_option
@image_topic_option
def batch(  # noqa: PLR0913 (a click command: one parameter per option)
    source: Path,
    out_dir: Path,
    method: str | None,
    odometry: str,
    workers: int | None,
    address: str | None,
    fail_fast: bool,
    force: bool,
    max_retries: int,
    no_parquet: bool,
    quiet: bool,
    height_m: float,
    mount_angle_deg: float,
    lookback_s: float,
    reference: str | None,
    ours_options: tuple[str, ...],
    generic_classes: tuple[str, ...],
    vehicle_classes: tuple[str, ...],
    offline: bool,
    overlay: bool,
    overlay_format: str,
    exports: tuple[str, ...],
    columns: str,
    image_topic: str | None,
) -> None:
    """Run every drive of SOURCE (a CSV or TOML manifest, or a folder of drives) into OUT.

    A manifest row names drive, frames (image folder, video or drive log), calib (a log may
    use its camera_info instead), boxes and optionally method, the log's image_topic,
    rotation_topic and speed_topic and other `run` options (paths relative to the manifest;
    list cells such as ours_options separate their items with ';'). The options here are the
    values of the drives that leave a cell empty (--ours-option, --generic-class and --offline
    apply to the drives whose method takes them; --image-topic to drive logs; --reference to
    every drive, whose distances are to the vehicles' nearest face without it).
    Complete drives with unchanged inputs and settings are skipped; a failed drive is recorded in
    OUT/status.csv and does not stop the others. Exit code 1 when every drive failed, or at a
    failure with --fail-fast. Needs Ray: pip install 'slopedist[batch]'.
    """
    method = method or DEFAULT_METHOD
    check_methods([method])
    settings = RunSettings(
        reference,
        parse_ours_options(ours_options),
        vehicle_classes,
        offline,
        overlay,
        overlay_format,
        exports,
        generic_classes,
        columns,
    )
    defaults = DriveDefaults(
        method, odometry, height_m, mount_angle_deg, lookback_s, settings, image_topic
    )
    drives = load_drives(source, defaults)
    for warning in unapplied(settings, [d.method for d in drives]):
        click.echo(f"slopedist: warning: {warning}", err=True)
    options = BatchOptions(
        workers=workers,
        address=address,
        fail_fast=fail_fast,
        force=force,
        max_retries=max_retries,
        progress=not quiet,
        parquet=not no_parquet,
    )
    result = run_batch(drives, out_dir, options)
    click.echo(batch_summary_text(result), err=True)
    if result.all_failed or (fail_fast and result.count(DriveStatus.FAILED)):
        click.get_current_context().exit(1)


def batch_summary_text(result: BatchResult) -> str:
    """A few lines: counts per status, throughput, the drives' warnings (e.g. box rows their
    reader left out), the failures and where the outputs are."""
    counts = ", ".join(f"{result.count(s)} {s.value}" for s in DriveStatus if result.count(s))
    lines = [
        f"{len(result.outcomes)} drives: {counts}; {result.frames_run} frames in "
        f"{result.elapsed_s:.1f} s ({result.frames_per_s:.1f} frames/s)",
    ]
    lines += [
        f"warning: drive {o.drive}: {w.removeprefix('warning: ')}"
        for o in result.outcomes
        for w in o.warnings
    ]
    lines += [
        f"failed: {o.drive}: {o.error}" for o in result.outcomes if o.status is DriveStatus.FAILED
    ]
    lines.append(f"status: {result.out_dir / 'status.csv'}; fleet tables: {result.out_dir}/fleet/")
    if result.dataset is not None:
        lines.append(f"records dataset (partitioned by drive): {result.dataset}")
    return "\n".join(lines)
