"""``slopedist demo``: the synthetic-hill suite from rendered pixels, every method, tables."""

from __future__ import annotations

import time
from pathlib import Path

import click

from slopedist.cli.choice import Choice
from slopedist.cli.method_options import check_methods, estimator_options
from slopedist.cli.options import given_list
from slopedist.estimators import EstimatorConfig
from slopedist.io.outputs import OutputFolder
from slopedist.synthetic.demo import (
    DEFAULT_OUT,
    DemoConfig,
    format_demo_tables,
    iter_outputs,
    run_demo,
)
from slopedist.synthetic.scenarios import SUITE, builtin_names


@click.command("demo")
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=DEFAULT_OUT,
    show_default=True,
    help="Output folder (created).",
)
@click.option(
    "--scenarios",
    default=",".join(SUITE),
    show_default=True,
    help="Comma-separated built-in scenario names or TOML files.",
)
@click.option(
    "--methods", default=None, help="Comma-separated methods (default: every available one)."
)
@click.option(
    "--odometry",
    type=Choice(["visual", "truth"]),
    default="visual",
    show_default=True,
    help="'visual': built-in visual odometry on the rendered frames; 'truth': the true "
    "rotations (a diagnostic that removes odometry error).",
)
@click.option(
    "--frames",
    "max_frames",
    type=click.IntRange(min=1),
    help="Only the first N frames of each scenario.",
)
@click.option("--no-video", is_flag=True, help="Do not write the overlay videos.")
@click.option("--no-plots", is_flag=True, help="Do not write the plots.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@click.option(
    "--jobs",
    type=click.IntRange(min=1),
    default=None,
    help="Scenarios run at once, each in a process [default: one per usable core].",
)
@estimator_options(depth=True)
def demo(
    out_dir: Path,
    scenarios: str,
    methods: str | None,
    odometry: str,
    max_frames: int | None,
    no_video: bool,
    no_plots: bool,
    quiet: bool,
    jobs: int | None,
    estimator_config: EstimatorConfig,
) -> None:
    """Run every method on the synthetic hills, from rendered pixels, and print the tables."""
    names = given_list(methods, "--methods", "every method")
    if names is not None:
        check_methods(names)
    scenario_names = given_list(
        scenarios, "--scenarios", f"the whole suite (built-in: {', '.join(builtin_names())})"
    )
    assert scenario_names is not None  # the option has a default
    cfg = DemoConfig(
        out_dir,
        tuple(scenario_names),
        tuple(names) if names is not None else None,
        odometry,
        not no_video,
        not no_plots,
        max_frames,
        not quiet,
        estimator_config,
        jobs,
    )
    t0 = time.perf_counter()
    with OutputFolder(out_dir).lock():
        result = run_demo(cfg, echo=lambda s: click.echo(s, err=True))
    click.echo(format_demo_tables(result))
    click.echo("")
    click.echo(f"finished in {time.perf_counter() - t0:.0f} s; files:")
    for path in iter_outputs(result):
        click.echo(f"  {path}")
