"""``slopedist report``: the report of a KITTI tracking folder, of ``slopedist run`` outputs or
of a ``slopedist batch`` output (with a truth Tables 1 and 2, metrics, figures; without one the
per-track table and plots), as Markdown, HTML and CSV."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import click

from slopedist.cli.method_options import (
    check_methods,
    estimator_options,
    evaluation_method_options,
    offline_option,
    with_offline_methods,
)
from slopedist.cli.options import given_list, kitti_eval_options, split_list
from slopedist.estimators import EstimatorConfig
from slopedist.evaluation.kitti import KittiEvalConfig
from slopedist.evaluation.report import (
    SUMMARY_TABLES,
    ReportOptions,
    SourceKind,
    detect_source,
    report_data,
    write_report,
)
from slopedist.evaluation.report.data import NEAR_DISTANCE_M
from slopedist.evaluation.report.kitti import default_kitti_methods
from slopedist.evaluation.report.runs import run_folders
from slopedist.evaluation.table import format_text
from slopedist.io.outputs import OutputFolder, check_outputs_spare_inputs


def parse_tracks(value: str | None) -> list[tuple[str, int]] | None:
    """``"0001:12,0009:3"`` → ``[("0001", 12), ("0009", 3)]``."""
    out = []
    for item in split_list(value) or []:
        seq, sep, tid = item.partition(":")
        if not sep or not tid.strip().lstrip("-").isdigit():
            raise click.BadParameter(f"'{item}' is not SEQUENCE:TRACK_ID", param_hint="--tracks")
        out.append((seq.strip(), int(tid)))
    return out or None


@click.command("report")
@click.argument("source", type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("slopedist_report"),
    show_default=True,
    help="Output folder: report.md, report.html, figures/, CSV (and Parquet).",
)
@click.option(
    "--methods",
    help="Comma-separated methods [default: every method that can run; "
    "depthmap when --depth-dir is given]; learned-peer adds the box-feature regressor "
    "trained leave-one-sequence-out (KITTI; extra 'learned').",
)
@click.option("--sequences", help="KITTI: comma-separated sequences (default: all).")
@click.option(
    "--depth-dir",
    type=click.Path(file_okay=False, path_type=Path),
    help="Depth maps for the depthmap method: DIR/<sequence>/<frame>.png (KITTI "
    "depth PNG, uint16/256 m) or .npy (float metres).",
)
@kitti_eval_options("KITTI: ")
@click.option(
    "--tracks",
    help="Tracks to plot over time, SEQUENCE:TRACK_ID,... [default: the longest tracks].",
)
@click.option(
    "--near",
    "near_m",
    type=click.FloatRange(min=0.0, min_open=True, max=1000.0),
    default=NEAR_DISTANCE_M,
    show_default=True,
    metavar="M",
    help="Runs: the per-track table's threshold, how long each track was closer than M metres.",
)
@click.option("--no-parquet", is_flag=True, help="Do not write Parquet even if pyarrow exists.")
@offline_option
@estimator_options(depth=True)
def report(  # noqa: PLR0913 (a click command: one parameter per option)
    source: Path,
    out_dir: Path,
    methods: str | None,
    sequences: str | None,
    depth_dir: Path | None,
    tracks: str | None,
    near_m: float,
    no_parquet: bool,
    offline: bool,
    estimator_config: EstimatorConfig,
    kitti_config: KittiEvalConfig,
) -> None:
    """Write the report of SOURCE: a KITTI tracking folder, `slopedist run` output(s) or a
    `slopedist batch` output (the fleet report). With a truth, compares the methods and prints
    Table 1 (RMSE) and Table 2 (time per frame), and for a batch the pooled fleet tables;
    without one, the page has a table and a plot per track."""
    names = check_methods(split_list(methods) or [], evaluation=True)
    kind = detect_source(source)
    # the report's records.csv, tracks.csv... would replace a run's own
    check_outputs_spare_inputs([], [source, *run_folders(source)], out_dir)
    if offline:
        if kind is not SourceKind.KITTI_TRACKING:
            raise click.UsageError(
                "--offline runs the offline methods on a KITTI tracking folder; for run "
                "outputs, make the runs with `slopedist run --offline` (method ours-offline)"
            )
        names = with_offline_methods(names or default_kitti_methods(depth_dir is not None))
    cfg = dataclasses.replace(
        kitti_config,
        sequences=given_list(sequences, "--sequences", "every sequence"),
        methods=tuple(names),
        method_options=evaluation_method_options(estimator_config, names),
        depth_dir=depth_dir,
    )
    opts = ReportOptions(
        eval=cfg, methods=names or None, tracks=parse_tracks(tracks), near_m=near_m
    )
    with OutputFolder(out_dir).lock():
        data = report_data(
            source, opts, on_sequence=lambda s: click.echo(f"sequence {s} ...", err=True)
        )
        written = write_report(
            data, out_dir, opts.tracks, opts.n_tracks, parquet=False if no_parquet else None
        )
    for t in written.tables:
        if t.key in SUMMARY_TABLES:
            click.echo(format_text(t) + "\n")
    for warning in data.warnings:
        click.echo(f"warning: {warning}", err=True)
    if kind in (SourceKind.RUN, SourceKind.FLEET) and not data.has_truth:
        click.echo("no ground truth in the records: Table 1 is not available", err=True)
    click.echo(
        f"wrote {out_dir / 'report.html'}, {out_dir / 'report.md'} and "
        f"{len(written.files) - 2} other files",
        err=True,
    )
