"""Every benchmark script imports against the current package: a refactor that moves a name a
benchmark uses breaks here, not when someone next runs the benchmark for a figure."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
SCRIPTS = sorted(p.stem for p in BENCHMARKS.glob("*.py") if not p.name.startswith("_"))


def test_there_are_benchmarks() -> None:
    assert "realtime" in SCRIPTS and "kitti_raw_lead" in SCRIPTS


@pytest.mark.parametrize("name", SCRIPTS)
def test_benchmark_imports(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    module = importlib.import_module(name)
    if "__main__" in (BENCHMARKS / f"{name}.py").read_text(encoding="utf-8"):  # a script
        assert callable(getattr(module, "main", None)), f"benchmarks/{name}.py has no main()"
    sys.modules.pop(name, None)
