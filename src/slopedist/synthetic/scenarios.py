"""The built-in scenarios (TOML files shipped in the package) and loading a scenario by name or
path.

``slopedist simulate --list`` names the built-in scenarios; they live in
``slopedist/synthetic/scenarios/``. Copy one and edit it: the file's layout is described
in :mod:`~slopedist.synthetic.scenario_file`, which checks every field and reports a
mistake as an :class:`~slopedist.core.errors.InputFileError` naming the file, the line and the
field.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from slopedist.core.errors import InputFileError, MissingInputError
from slopedist.core.textfiles import read_text
from slopedist.synthetic.scenario_file import load_scenario_text
from slopedist.synthetic.scene import Scenario

if TYPE_CHECKING:
    from importlib.abc import Traversable

BUILTIN_PACKAGE = "slopedist.synthetic"
BUILTIN_FOLDER = "scenarios"
"""The built-in TOML files live in this folder of that package (package data)."""
SUITE = (
    "same_flat",
    "same_downhill",
    "curve_flat",
    "bumps_and_curves",
    "target_steep_uphill",
    "ego_crest",
    "ego_sag",
)
"""The built-in scenarios, in the order of the demo's tables."""

MAX_SCENARIO_BYTES = 1_000_000
"""Largest scenario file read, bytes."""


def _builtin_dir() -> Traversable:
    return resources.files(BUILTIN_PACKAGE).joinpath(BUILTIN_FOLDER)


def builtin_names() -> list[str]:
    """Names of the built-in scenarios (the suite first, then any others shipped)."""
    files = sorted(p.name[:-5] for p in _builtin_dir().iterdir() if p.name.endswith(".toml"))
    return [n for n in SUITE if n in files] + [n for n in files if n not in SUITE]


def builtin_text(name: str) -> str:
    """TOML text of the built-in scenario ``name``."""
    if name not in builtin_names():
        raise MissingInputError(
            f"no built-in scenario '{name}' (built-in: {', '.join(builtin_names())})"
        )
    return (_builtin_dir() / f"{name}.toml").read_text(encoding="utf-8")


def load_scenario(name_or_path: str | Path) -> Scenario:
    """A built-in scenario by name, or a scenario TOML file by path.

    Raises:
        MissingInputError: neither a file nor a built-in name.
        InputFileError: the file is not valid (message names file, line and field).
    """
    p = Path(name_or_path)
    if p.is_file():
        if p.stat().st_size > MAX_SCENARIO_BYTES:
            raise InputFileError(p, f"larger than {MAX_SCENARIO_BYTES} bytes: not a scenario")
        return load_scenario_text(read_text(p, "scenario file"), str(p), p.stem)
    name = str(name_or_path)
    if name in builtin_names():
        return load_scenario_text(builtin_text(name), f"builtin:{name}", name)
    if p.suffix.lower() == ".toml" or "/" in name or "\\" in name:
        raise MissingInputError(f"scenario file not found: {p}")
    raise MissingInputError(
        f"'{name}' is neither a scenario file nor a built-in scenario (built-in: "
        f"{', '.join(builtin_names())})"
    )


@dataclass(frozen=True)
class ScenarioInfo:
    """Name and one-line description of a scenario, for listings."""

    name: str
    description: str


def describe_builtins() -> list[ScenarioInfo]:
    """The built-in scenarios with their descriptions."""
    out = []
    for n in builtin_names():
        s = load_scenario(n)
        out.append(ScenarioInfo(n, s.description.strip().splitlines()[0] if s.description else ""))
    return out
