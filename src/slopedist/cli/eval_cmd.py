"""``slopedist eval``: evaluations against ground truth."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import click

from slopedist.cli.choice import SuggestingGroup
from slopedist.cli.method_options import (
    check_methods,
    estimator_options,
    evaluation_method_options,
    offline_option,
    with_offline_methods,
)
from slopedist.cli.options import given_list, kitti_eval_options, split_list
from slopedist.estimators import EstimatorConfig
from slopedist.evaluation.accuracy_tables import format_report_tables
from slopedist.evaluation.kitti import KittiEvalConfig, evaluate_kitti_tracking
from slopedist.io.formatting import STDOUT_PATH, write_json
from slopedist.io.outputs import check_outputs_spare_inputs


@click.group("eval", cls=SuggestingGroup)
def eval_group() -> None:
    """Evaluate estimators against ground truth."""


@eval_group.command("kitti-tracking")
@click.argument("data_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--sequences", help="Comma-separated sequence names, e.g. 0000,0004 (default: all).")
@click.option(
    "--methods",
    default="flat,ego,paper",
    show_default=True,
    help="Comma-separated estimator names, and learned-peer (a box-feature regressor trained "
    "leave-one-sequence-out; needs the extra 'learned').",
)
@kitti_eval_options("")
@click.option(
    "--depth-dir",
    type=click.Path(file_okay=False, path_type=Path),
    help="Depth maps of the depthmap method: DIR/<sequence>/<frame>.png|.npy.",
)
@click.option(
    "--json",
    "json_out",
    type=click.Path(dir_okay=False, allow_dash=True, path_type=Path),
    help="Write the full report as strict JSON here ('-': standard output, the tables then "
    "go to standard error).",
)
@offline_option
@estimator_options()
def kitti_tracking(
    data_dir: Path,
    sequences: str | None,
    methods: str,
    depth_dir: Path | None,
    json_out: Path | None,
    offline: bool,
    estimator_config: EstimatorConfig,
    kitti_config: KittiEvalConfig,
) -> None:
    """Evaluate on KITTI tracking sequences under DATA_DIR (label_02/, calib/, poses)."""
    names = check_methods(split_list(methods) or [], evaluation=True)
    if json_out is not None and str(json_out) != STDOUT_PATH:  # not onto a label, calib, ...
        check_outputs_spare_inputs([json_out], sorted(data_dir.glob("*/*.txt")))
    if offline:
        names = with_offline_methods(names)
    cfg = dataclasses.replace(
        kitti_config,
        sequences=given_list(sequences, "--sequences", "every sequence"),
        methods=names,
        method_options=evaluation_method_options(estimator_config, names),
        depth_dir=depth_dir,
    )
    report = evaluate_kitti_tracking(
        data_dir, cfg, on_sequence=lambda s: click.echo(f"sequence {s} ...", err=True)
    )
    to_stdout = json_out is not None and str(json_out) == STDOUT_PATH
    click.echo(format_report_tables(report), err=to_stdout)
    if json_out is None:
        return
    if not to_stdout:
        json_out.parent.mkdir(parents=True, exist_ok=True)
    write_json(json_out, report)
    if not to_stdout:
        click.echo(f"wrote {json_out}", err=True)
