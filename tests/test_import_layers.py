"""Imports run down the layers only: the building blocks never import the loops, evaluations
or commands built on them, and a command module shares code through the library or
``cli/options.py``, not through a sibling command."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import slopedist

PACKAGE = Path(slopedist.__file__).parent
LOWER = ("camera", "geometry", "errors", "detections", "estimators", "odometry", "io", "depth")
LOWER += ("datasets",)
UPPER = ("pipeline", "runner", "demo", "demo_scenario", "report", "kitti_eval", "evaluation")
UPPER += ("viz", "cli")
CLI_SHARED = ("slopedist.cli.options",)


def _imports(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = [n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
    return [n for n in names if n.startswith("slopedist.")]


def _modules(top: str) -> list[Path]:
    target = PACKAGE / top
    return sorted(target.rglob("*.py")) if target.is_dir() else [target.with_suffix(".py")]


@pytest.mark.parametrize("layer", LOWER)
def test_building_blocks_do_not_import_upper_layers(layer: str) -> None:
    bad = [
        f"{path.relative_to(PACKAGE)} imports {name}"
        for path in _modules(layer)
        for name in _imports(path)
        if name.split(".")[1] in UPPER
    ]
    assert not bad


def test_commands_do_not_import_each_other() -> None:
    bad = [
        f"{path.name} imports {name}"
        for path in _modules("cli")
        if path.name != "__init__.py"
        for name in _imports(path)
        if name.startswith("slopedist.cli") and name not in CLI_SHARED
    ]
    assert not bad
