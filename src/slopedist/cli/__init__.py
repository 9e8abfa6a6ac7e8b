"""The ``slopedist`` command line.

Each command lives in its own module, listed in :data:`COMMANDS` and imported only when it runs
(:class:`LazyGroup`). :func:`main` is the one place errors end: every exception becomes one
line on stderr, ``slopedist: error: ...``, and an exit code:

- 2 for user errors: :class:`~slopedist.core.errors.SlopedistError` (bad file, bad option), click's
  usage errors (a mistyped option value or command with "did you mean", one line), and
  operating-system errors about files (not found, permission, disk full);
- 1 for internal errors (a bug): the line names the exception and points to ``--debug``;
- 130 when interrupted (Ctrl-C).

``slopedist --debug <command> ...`` or the environment variable ``SLOPEDIST_DEBUG=1`` adds the
traceback. A reader that closes the pipe early (``slopedist estimate ... | head -1``) ends the
program quietly with exit code 0. A path is printed whatever its bytes (one that is not UTF-8
as ``\\xNN``).

Internal: the names a user needs are those of :mod:`slopedist` itself (docs/python.md).
"""

from __future__ import annotations

import contextlib
import importlib
import os
import sys
import traceback
from typing import NamedTuple

import click

from slopedist import __version__
from slopedist.cli.choice import SuggestingGroup, needs_usage
from slopedist.core.errors import SlopedistError
from slopedist.core.paths import PATH_BYTES_ERRORS

DEBUG_ENV = "SLOPEDIST_DEBUG"
"""Environment variable that, set to ``1``, shows tracebacks (like ``--debug``)."""

EXIT_USER_ERROR = 2
EXIT_INTERNAL_ERROR = 1
EXIT_INTERRUPTED = 130


class _Session:
    """Whether this invocation asked for tracebacks (set by the ``--debug`` option)."""

    debug = False


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
        "Write the report of SOURCE: a KITTI tracking folder, `slopedist run` "
        "output(s) or a `slopedist batch` output (the fleet report).",
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
        "Estimate the mount angle θ0 and the camera height from the targets of one drive.",
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
        "YOLO folder) into TARGET (COCO if .json, else slopedist CSV; or --to).",
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
    "batch": _Lazy(
        "batch_cmd",
        "batch",
        "Run every drive of SOURCE (a CSV or TOML manifest, or a folder of drives) into OUT.",
    ),
}
"""Command name → module under ``slopedist.cli``, the click command in it, and the first
sentence of its help (shown by ``slopedist --help`` without importing the module; a test
checks it against the command's own help)."""


class LazyGroup(SuggestingGroup):
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
                summary = click.Command(name, help=lazy.summary).get_short_help_str(limit)
                rows.append((name, summary))
                continue
            command = super().get_command(ctx, name)
            if command is not None and not command.hidden:
                rows.append((name, command.get_short_help_str(limit)))
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="slopedist")
@click.option(
    "--debug",
    is_flag=True,
    help=f"Show the full traceback of an error (also: {DEBUG_ENV}=1).",
)
def cli(debug: bool) -> None:
    """Monocular inter-vehicle distance estimation that stays right on hills."""
    _Session.debug = _Session.debug or debug


def _error(message: str) -> None:
    click.echo(f"slopedist: error: {message}", err=True)


def _os_error_message(exc: OSError) -> str:
    where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
    return f"{exc.strerror or exc}{where}"


def _quiet_closed_pipe() -> int:
    """stdout's reader went away: point stdout at /dev/null so the exit flush stays silent."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # stdout without a file descriptor (tests)
        pass
    return 0


def _exit_code(exc: BaseException) -> int:
    """Report ``exc`` in one line (plus the traceback in debug mode) and return the exit code."""
    if isinstance(exc, click.exceptions.Abort | KeyboardInterrupt):
        click.echo("aborted", err=True)
        return EXIT_INTERRUPTED
    if isinstance(exc, click.ClickException):  # a mistyped command line: its usage first
        ctx = exc.ctx if isinstance(exc, click.UsageError) and needs_usage(exc) else None
        if ctx is not None:
            click.echo(ctx.get_usage(), err=True)
            if ctx.command.get_help_option(ctx) is not None:
                click.echo(f"Try '{ctx.command_path} --help' for help.", err=True)
        _error(exc.format_message())
        return EXIT_USER_ERROR
    if isinstance(exc, SlopedistError):
        _error(str(exc))
        return EXIT_USER_ERROR
    if isinstance(exc, OSError):
        _error(_os_error_message(exc))
        return EXIT_USER_ERROR
    _error(
        f"internal error: {type(exc).__name__}: {exc} (this is a bug in slopedist; run again "
        f"with --debug or {DEBUG_ENV}=1 for the traceback and report it)"
    )
    return EXIT_INTERNAL_ERROR


def _print_any_path() -> None:
    """Standard output and error write a file-name byte that is not UTF-8 as ``\\xNN``
    (:data:`~slopedist.core.paths.PATH_BYTES_ERRORS`), so a path of any bytes can be printed."""
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None:
            with contextlib.suppress(ValueError, OSError):  # (a closed or detached stream)
                reconfigure(errors=PATH_BYTES_ERRORS)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``slopedist`` program; returns the exit code (see the module
    docstring)."""
    _Session.debug = os.environ.get(DEBUG_ENV, "") not in ("", "0")
    _print_any_path()
    args = list(sys.argv[1:] if argv is None else argv)
    try:  # not cli.main(): it turns a closed pipe into exit code 1 and hides other errors' kind
        with cli.make_context("slopedist", args) as ctx:
            code = cli.invoke(ctx)
    except click.exceptions.Exit as exc:  # --help, --version
        return exc.exit_code
    except BrokenPipeError:
        return _quiet_closed_pipe()
    except Exception as exc:  # the one place every error ends
        return _report(exc)
    except KeyboardInterrupt as exc:
        return _report(exc)
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        return _quiet_closed_pipe()
    return code if isinstance(code, int) else 0


def _report(exc: BaseException) -> int:
    if _Session.debug:
        traceback.print_exception(exc, file=sys.stderr)
    return _exit_code(exc)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
