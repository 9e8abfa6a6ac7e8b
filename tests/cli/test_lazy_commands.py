"""The lazy command group: ``slopedist --help`` imports no command module, and lists what the
commands themselves say."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from slopedist.cli import COMMANDS, cli

SRC = Path(__file__).resolve().parents[2] / "src"


def _commands() -> dict[str, click.Command]:
    return {
        name: getattr(importlib.import_module(f"slopedist.cli.{lazy.module}"), lazy.attribute)
        for name, lazy in COMMANDS.items()
    }


def test_every_command_module_of_the_package_is_listed() -> None:
    modules = {p.stem for p in (SRC / "slopedist" / "cli").glob("*_cmd.py")}
    assert modules == {lazy.module for lazy in COMMANDS.values()}
    for name, command in _commands().items():
        assert command.name == name


@pytest.mark.parametrize("limit", [30, 45, 70, 200])
def test_summaries_are_the_commands_own_short_help(limit: int) -> None:
    for name, command in _commands().items():
        summary = click.Command(name, help=COMMANDS[name].summary).get_short_help_str(limit)
        assert summary == command.get_short_help_str(limit), name


def test_help_equals_the_eager_group() -> None:
    eager = click.Group("slopedist", help=cli.help, params=list(cli.params))
    eager.context_settings = cli.context_settings
    for command in _commands().values():
        eager.add_command(command)
    lazy = CliRunner().invoke(cli, ["--help"], prog_name="slopedist", terminal_width=100)
    expected = CliRunner().invoke(eager, ["--help"], prog_name="slopedist", terminal_width=100)
    assert lazy.exit_code == 0 and lazy.output == expected.output
    assert "  run " in lazy.output


def test_help_imports_no_command_module() -> None:
    code = (
        "import sys\n"
        "from slopedist.cli import main\n"
        "try:\n"
        "    main(['--help'])\n"
        "except SystemExit:\n"
        "    pass\n"
        "light = {'slopedist.cli.choice'}  # the root group's 'did you mean' (click alone)\n"
        "heavy = sorted(m for m in sys.modules if m.startswith(('scipy', 'slopedist.cli.')))\n"
        "heavy = [m for m in heavy if m not in light]\n"
        "print(heavy)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
        env={"PYTHONPATH": str(SRC), "PATH": ""},
    ).stdout
    assert out.strip().splitlines()[-1] == "[]"


def test_a_command_still_runs_and_fails_cleanly() -> None:
    from slopedist.cli import main

    assert main(["run", "--help"]) == 0
    assert main(["no-such-command"]) == 2
