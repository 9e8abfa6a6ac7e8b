"""A "did you mean" for a mistyped name (a method, an option value, a command)."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

CUTOFF = 0.6
"""How alike a name must be to be suggested (:func:`difflib.get_close_matches`, 0..1)."""


def close_match(value: str, choices: Iterable[str]) -> str | None:
    """The choice most like ``value`` (ignoring case), or None when none is alike."""
    names = list(choices)
    lowered = {c.lower(): c for c in names}
    found = difflib.get_close_matches(str(value).lower(), list(lowered), n=1, cutoff=CUTOFF)
    return lowered[found[0]] if found else None


def did_you_mean(value: str, choices: Iterable[str]) -> str:
    """``"; did you mean 'ours'?"`` for the choice most like ``value``, else ``""``.

    Example:
        >>> did_you_mean("our", ["flat", "paper", "ours"])
        "; did you mean 'ours'?"
    """
    match = close_match(value, choices)
    return f"; did you mean '{match}'?" if match is not None else ""


def unknown_choice(what: str, value: str, choices: Iterable[str]) -> str:
    """The message for a ``value`` of ``what`` that is none of ``choices``, with the closest.

    Example:
        >>> unknown_choice("method", "our", ["flat", "ours"])
        "unknown method 'our'; did you mean 'ours'? (choose from flat, ours)"
    """
    names = list(choices)
    return f"unknown {what} '{value}'{did_you_mean(value, names)} (choose from {', '.join(names)})"
