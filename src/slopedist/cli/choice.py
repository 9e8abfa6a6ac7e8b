"""Option values and command names with a "did you mean": :class:`Choice` for every option
of fixed values, :class:`SuggestingGroup` for every group of commands. Their errors (and every
bad option value) are one line, without the usage preamble (:func:`needs_usage`)."""

from __future__ import annotations

from typing import Any

import click

from slopedist.core.suggest import did_you_mean


class Choice(click.Choice):
    """``click.Choice`` whose error for a value it does not know names the closest choice:
    ``'builtn' is not one of 'builtin', 'orbslam3', 'none'; did you mean 'builtin'?``."""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        try:
            return super().convert(value, param, ctx)
        except click.BadParameter as exc:
            hint = did_you_mean(str(value), [str(c) for c in self.choices])
            if not hint:
                raise
            message = exc.message.rstrip(".")
            raise click.BadParameter(f"{message}{hint}", ctx, param) from None


class UnknownCommandError(click.UsageError):
    """A command name the group does not have, with the closest one it has."""


class SuggestingGroup(click.Group):
    """A group whose error for a command it does not have names the closest one:
    ``No such command 'rn'; did you mean 'run'?``."""

    def resolve_command(
        self, ctx: click.Context, args: list[str]
    ) -> tuple[str | None, click.Command | None, list[str]]:
        name = args[0] if args else ""
        if name and not name.startswith("-") and self.get_command(ctx, name) is None:
            hint = did_you_mean(name, self.list_commands(ctx))
            if hint:
                raise UnknownCommandError(f"No such command '{name}'{hint}", ctx)
        return super().resolve_command(ctx, args)


def needs_usage(exc: click.ClickException) -> bool:
    """Whether the message of a command-line error needs the command's usage before it: not
    for a bad option value (the message names the option and the value) nor for an unknown
    command with a suggestion."""
    return isinstance(exc, click.UsageError) and not isinstance(
        exc, click.BadParameter | UnknownCommandError
    )
