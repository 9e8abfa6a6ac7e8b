"""The ``slopedist`` command line.

Each command lives in its own module, listed in :data:`COMMANDS` and imported only when it runs
(:class:`LazyGroup`). User mistakes
(:class:`~slopedist.errors.SlopedistError`, unreadable files) end with one clear message on
stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import importlib
import sys
from typing import NamedTuple

import click
from click.utils import make_default_short_help

from slopedist import __version__
from slopedist.errors import SlopedistError


class _Lazy(NamedTuple):
    """Where a command lives, and its one-line summary for ``slopedist --help``."""

    module: str
    attribute: str
    summary: str


COMMANDS: dict[str, _Lazy] = {
    "eval": _Lazy("eval_cmd", "eval_group", "Evaluate estimators against ground truth."),
    "estimate": _Lazy(
        "estimate_cmd",
        "estimate",
        "Estimate per-target distances for one sequence, streaming frame by frame.",
    ),
    "odometry": _Lazy(
        "odometry_cmd", "odometry_group", "Visual odometry (camera rotations from pixels)."
    ),
    "report": _Lazy(
        "report_cmd",
        "report",
        "Write the comparison report of SOURCE: a KITTI tracking folder or `slopedist run` "
        "output(s).",
    ),
    "run": _Lazy(
        "run_cmd",
        "run",
        "Estimate distances from FRAMES (an image folder, a video file or a drive log) and "
        "per-frame boxes.",
    ),
    "simulate": _Lazy(
        "simulate_cmd",
        "simulate",
        "Render SCENARIO (a built-in name or a TOML file) with its ground truth to --out.",
    ),
    "demo": _Lazy(
        "demo_cmd",
        "demo",
        "Run every method on the synthetic hills, from rendered pixels, and print the tables.",
    ),
    "calibrate": _Lazy(
        "calibrate_cmd",
        "calibrate",
        "Estimate the mount angle θ0 and the camera height from the targets of one sequence.",
    ),
    "log": _Lazy(
        "log_cmd",
        "log_group",
        "Drive logs: ROS 1 bags, ROS 2 bags (sqlite3 or MCAP) and MCAP files.",
    ),
    "convert": _Lazy(
        "convert_cmd",
        "convert",
        "Convert box file SOURCE (slopedist CSV, KITTI, PointRCNN, MOTChallenge, COCO JSON, "
        "YOLO folder) into TARGET (slopedist CSV by default).",
    ),
    "camera": _Lazy(
        "camera_cmd",
        "camera_group",
        "Camera intrinsics (focal lengths, principal point, lens distortion).",
    ),
    "detect": _Lazy(
        "detect_cmd",
        "detect",
        "Detect vehicles in FRAMES (a video or image folder) with an ONNX model.",
    ),
}
"""Command name → module under ``slopedist.cli``, the click command in it, and the first
sentence of its help (shown by ``slopedist --help`` without importing the module; a test
checks it against the command's own help)."""


class LazyGroup(click.Group):
    """A click group that imports a command's module only when that command runs (or its own
    help is shown): ``slopedist --help`` and each command start without the others' imports
    (SciPy, the estimators, the renderer)."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*COMMANDS, *super().list_commands(ctx)})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        lazy = COMMANDS.get(cmd_name)
        if lazy is None:
            return super().get_command(ctx, cmd_name)
        module = importlib.import_module(f"slopedist.cli.{lazy.module}")
        command: click.Command = getattr(module, lazy.attribute)
        return command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The command list from :data:`COMMANDS` (no import), as click would write it."""
        names = self.list_commands(ctx)
        if not names:
            return
        limit = formatter.width - 6 - max(len(name) for name in names)
        rows = []
        for name in names:
            lazy = COMMANDS.get(name)
            if lazy is not None:
                rows.append((name, make_default_short_help(lazy.summary, limit)))
                continue
            command = super().get_command(ctx, name)
            if command is not None and not command.hidden:
                rows.append((name, command.get_short_help_str(limit)))
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="slopedist")
def cli() -> None:
    """Monocular inter-vehicle distance estimation that stays right on hills."""


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
