"""The ``slopedist`` command line.

Each command lives in its own module and is registered on :data:`cli` here. :func:`main` is the
one place errors end: every exception becomes one line on stderr, ``slopedist: error: ...``,
and an exit code:

- 2 for user errors: :class:`~slopedist.errors.SlopedistError` (bad file, bad option), click's
  usage errors, and operating-system errors about files (not found, permission, disk full);
- 1 for internal errors (a bug): the line names the exception and points to ``--debug``;
- 130 when interrupted (Ctrl-C).

``slopedist --debug <command> ...`` or the environment variable ``SLOPEDIST_DEBUG=1`` adds the
traceback. A reader that closes the pipe early (``slopedist estimate ... | head -1``) ends the
program quietly with exit code 0.
"""

from __future__ import annotations

import os
import sys
import traceback

import click

from slopedist import __version__
from slopedist.cli.batch_cmd import batch
from slopedist.cli.calibrate_cmd import calibrate
from slopedist.cli.camera_cmd import camera_group
from slopedist.cli.convert_cmd import convert
from slopedist.cli.demo_cmd import demo
from slopedist.cli.detect_cmd import detect
from slopedist.cli.estimate_cmd import estimate
from slopedist.cli.eval_cmd import eval_group
from slopedist.cli.log_cmd import log_group
from slopedist.cli.odometry_cmd import odometry_group
from slopedist.cli.report_cmd import report
from slopedist.cli.run_cmd import run
from slopedist.cli.simulate_cmd import simulate
from slopedist.errors import SlopedistError

DEBUG_ENV = "SLOPEDIST_DEBUG"
"""Environment variable that, set to ``1``, shows tracebacks (like ``--debug``)."""

EXIT_USER_ERROR = 2
EXIT_INTERNAL_ERROR = 1
EXIT_INTERRUPTED = 130


class _Session:
    """Whether this invocation asked for tracebacks (set by the ``--debug`` option)."""

    debug = False


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="slopedist")
@click.option(
    "--debug",
    is_flag=True,
    help=f"Show the full traceback of an error (also: {DEBUG_ENV}=1).",
)
def cli(debug: bool) -> None:
    """Monocular inter-vehicle distance estimation that stays right on hills."""
    _Session.debug = _Session.debug or debug


cli.add_command(eval_group)
cli.add_command(estimate)
cli.add_command(odometry_group)
cli.add_command(report)
cli.add_command(run)
cli.add_command(simulate)
cli.add_command(demo)
cli.add_command(calibrate)
cli.add_command(log_group)
cli.add_command(convert)
cli.add_command(camera_group)
cli.add_command(detect)
cli.add_command(batch)


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
    if isinstance(exc, click.ClickException):
        exc.show()
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


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``slopedist`` program; returns the exit code (see the module
    docstring)."""
    _Session.debug = os.environ.get(DEBUG_ENV, "") not in ("", "0")
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
