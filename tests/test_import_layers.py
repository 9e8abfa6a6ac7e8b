"""The import graph runs down the layers only: a module never imports one of a higher layer.

Layers, low to high (a module's layer is that of its longest matching prefix):

0. ``core.errors``, ``core.geometry``, ``core.limits``, ``core.rectangles``, ``core.suggest``,
   ``core.textfiles`` — pure equations, the exception hierarchy, the bounds on input, rectangle
   queries, strict text reading and the "did you mean" of a mistyped name;
1. ``core.camera``;
2. ``io``, ``odometry`` — inputs (frames, boxes, depth, logs, KITTI), outputs and rotation sources;
3. ``estimators``, ``synthetic`` — the methods and the synthetic world they are tested on;
4. ``streaming.step`` — the one per-frame step;
5. ``streaming``, ``evaluation``, ``synthetic.demo``, ``batch`` — the applications of the step;
6. ``cli`` — options in, library calls out; a command module imports no other command module;
   the package root (``slopedist/__init__.py``: the public names of every layer, imported on
   first use) is at this layer too.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "slopedist"

LAYERS: dict[str, int] = {
    "__main__": 6,
    "core": 0,
    "core.camera": 1,
    "io": 2,
    "odometry": 2,
    "estimators": 3,
    "synthetic": 3,
    "streaming.step": 4,
    "streaming": 5,
    "evaluation": 5,
    "synthetic.demo": 5,
    "synthetic.demo_scenario": 5,
    "batch": 5,
    "cli": 6,
}
"""Layer of each module prefix below ``slopedist`` (the longest matching prefix counts)."""

APPLICATION_LAYER = 5
PUBLIC_API_LAYER = 6
"""Layer of the package root, which re-exports the public names of every layer."""


def module_name(path: Path) -> str:
    """Dotted name below ``slopedist`` of a source file (``io/frames.py`` → ``io.frames``)."""
    parts = path.relative_to(SRC).with_suffix("").parts
    return ".".join(p for p in parts if p != "__init__")


def layer_of(name: str) -> int:
    """Layer of a dotted module name below ``slopedist`` (the package root itself:
    :data:`PUBLIC_API_LAYER`)."""
    if not name:
        return PUBLIC_API_LAYER
    parts = name.split(".")
    for n in range(len(parts), 0, -1):
        prefix = ".".join(parts[:n])
        if prefix in LAYERS:
            return LAYERS[prefix]
    return APPLICATION_LAYER


def imported_modules(path: Path) -> set[str]:
    """Dotted names below ``slopedist`` that ``path`` imports (absolute and relative imports)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = module_name(path).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.split(".")[0] == "slopedist"}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                target = ".".join(["slopedist", *base, *([node.module] if node.module else [])])
            else:
                target = node.module or ""
            if target.split(".")[0] == "slopedist":
                found.add(target)
                found |= {
                    f"{target}.{a.name}" for a in node.names if _is_module(f"{target}.{a.name}")
                }
    return {n.removeprefix("slopedist").lstrip(".") for n in found}


def _is_module(dotted: str) -> bool:
    rel = Path(*dotted.split(".")[1:])
    return (SRC / rel).with_suffix(".py").exists() or (SRC / rel / "__init__.py").exists()


def violations() -> list[str]:
    """Every import of a higher layer, and every command module importing another command."""
    found = []
    for path in sorted(SRC.rglob("*.py")):
        name = module_name(path)
        for target in imported_modules(path):
            if layer_of(target) > layer_of(name):
                found.append(
                    f"{name} (layer {layer_of(name)}) imports {target} ({layer_of(target)})"
                )
            if name.endswith("_cmd") and target.startswith("cli.") and target.endswith("_cmd"):
                found.append(f"command {name} imports command {target}")
    return found


def test_layer_of_hand_cases() -> None:
    assert layer_of("core.geometry") == 0
    assert layer_of("core.camera") == 1
    assert layer_of("io.frames") == 2
    assert layer_of("estimators.ours.cues") == 3
    assert layer_of("streaming.step") == 4
    assert layer_of("streaming.loop") == APPLICATION_LAYER
    assert layer_of("evaluation.report.tables") == APPLICATION_LAYER
    assert layer_of("cli.run_cmd") == 6
    assert layer_of("") == PUBLIC_API_LAYER


def test_checker_sees_an_upward_import(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pkg = tmp_path / "slopedist"
    (pkg / "io").mkdir(parents=True)
    (pkg / "io" / "__init__.py").write_text("")
    (pkg / "streaming").mkdir()
    (pkg / "streaming" / "__init__.py").write_text("")
    (pkg / "streaming" / "step.py").write_text("")
    (pkg / "io" / "bad.py").write_text(
        "from slopedist.streaming.step import x\nfrom ..core import E\n"
    )
    monkeypatch.setattr(f"{__name__}.SRC", pkg)
    assert violations() == ["io.bad (layer 2) imports streaming.step (4)"]


def test_no_import_runs_up_the_layers() -> None:
    assert violations() == []


METHOD_PACKAGE = "estimators.ours"
"""A method's own package: only it and the registry that names each method import from it."""

REGISTRY = "estimators"
"""The registry (:mod:`slopedist.estimators`): the one module outside a method's package that
names it (to build it by name and to share its option texts and vehicle priors)."""


def method_package_importers(src: Path = SRC) -> list[str]:
    """Modules outside :data:`METHOD_PACKAGE` and the :data:`REGISTRY` that import from it."""
    found = []
    for path in sorted(src.rglob("*.py")):
        name = module_name(path)
        if name == REGISTRY or _in_method_package(name):
            continue
        targets = sorted(t for t in imported_modules(path) if _in_method_package(t))
        found += [f"{name} imports {t}" for t in targets]
    return found


def _in_method_package(name: str) -> bool:
    return name == METHOD_PACKAGE or name.startswith(f"{METHOD_PACKAGE}.")


def test_method_check_sees_an_import_of_ours(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pkg = tmp_path / "slopedist"
    for sub in ("estimators", "estimators/ours", "streaming"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "__init__.py").write_text("")
    (pkg / "estimators" / "ours" / "selfcal.py").write_text("")
    (pkg / "estimators" / "__init__.py").write_text("from slopedist.estimators.ours import X\n")
    (pkg / "streaming" / "setup.py").write_text(
        "from slopedist.estimators.ours.selfcal import self_calibrates\n"
    )
    monkeypatch.setattr(f"{__name__}.SRC", pkg)
    assert method_package_importers(pkg) == ["streaming.setup imports estimators.ours.selfcal"]


def test_no_generic_layer_imports_a_method_package() -> None:
    assert method_package_importers() == []
