"""The ``slopedist`` command line.

Each command lives in its own module and is registered on :data:`cli` here. User mistakes
(:class:`~slopedist.errors.SlopedistError`, unreadable files) end with one clear message on
stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import sys

import click

from slopedist import __version__
from slopedist.cli.calibrate_cmd import calibrate
from slopedist.cli.camera_cmd import camera_group
from slopedist.cli.convert_cmd import convert
from slopedist.cli.demo_cmd import demo
from slopedist.cli.detect_cmd import detect
from slopedist.cli.estimate_cmd import estimate
from slopedist.cli.eval_cmd import eval_group
from slopedist.cli.odometry_cmd import odometry_group
from slopedist.cli.report_cmd import report
from slopedist.cli.run_cmd import run
from slopedist.cli.simulate_cmd import simulate
from slopedist.errors import SlopedistError


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="slopedist")
def cli() -> None:
    """Monocular inter-vehicle distance estimation that stays right on hills."""


cli.add_command(eval_group)
cli.add_command(estimate)
cli.add_command(odometry_group)
cli.add_command(report)
cli.add_command(run)
cli.add_command(simulate)
cli.add_command(demo)
cli.add_command(calibrate)
cli.add_command(convert)
cli.add_command(camera_group)
cli.add_command(detect)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``slopedist`` program; returns the exit code."""
    try:
        cli.main(args=argv, prog_name="slopedist", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("aborted", err=True)
        return 130
    except click.ClickException as exc:
        exc.show()
        return 2
    except SlopedistError as exc:
        click.echo(f"slopedist: error: {exc}", err=True)
        return 2
    except OSError as exc:
        where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
        click.echo(f"slopedist: error: {exc.strerror or exc}{where}", err=True)
        return 2
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
