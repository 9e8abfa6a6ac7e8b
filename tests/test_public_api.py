"""``import slopedist`` gives the names a user needs and nothing else: ``__all__`` exactly,
each with a docstring of its own, each public function with an example that runs, and an
import that loads none of the package until a name is used."""

from __future__ import annotations

import doctest
import inspect
import subprocess
import sys
from pathlib import Path

import pytest

import slopedist

SRC = Path(slopedist.__file__).resolve().parent


def test_star_import_gives_exactly_all() -> None:
    namespace: dict[str, object] = {}
    exec("from slopedist import *", namespace)
    assert set(namespace) - {"__builtins__"} == set(slopedist.__all__)
    assert len(slopedist.__all__) == len(set(slopedist.__all__))


def test_every_public_name_has_a_docstring_of_its_own() -> None:
    for name in slopedist.__all__:
        obj = getattr(slopedist, name)
        doc = obj.__doc__
        assert doc and doc.strip(), f"slopedist.{name} has no docstring"
        if inspect.isclass(obj):
            assert "__doc__" in vars(obj), f"slopedist.{name} inherits its docstring"


def public_functions() -> list[str]:
    return [n for n in slopedist.__all__ if inspect.isfunction(getattr(slopedist, n))]


def test_every_public_function_shows_an_example() -> None:
    assert {"read_calibration", "read_boxes", "open_frames", "as_box_table"} <= set(
        public_functions()
    )
    for name in public_functions():
        assert "Example" in (getattr(slopedist, name).__doc__ or ""), name


def test_the_examples_of_the_public_names_run() -> None:
    """Every ``>>>`` example in the docstrings of the public names (their methods too)."""
    finder = doctest.DocTestFinder()
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    attempted = 0
    for name in slopedist.__all__:
        obj = getattr(slopedist, name)
        module = inspect.getmodule(obj)
        assert module is not None
        for test in finder.find(obj, name, module=module, globs=vars(module)):
            result = runner.run(test)
            assert result.failed == 0, f"the example of {test.name} fails"
            attempted += result.attempted
    assert attempted >= 20


def test_an_unknown_name_is_an_attribute_error() -> None:
    with pytest.raises(AttributeError, match="no attribute 'FrameStep'"):
        _ = slopedist.FrameStep  # type: ignore[attr-defined]


def test_import_slopedist_loads_nothing_else() -> None:
    """``import slopedist`` imports no subpackage and no numpy: a name loads on first use."""
    code = (
        "import sys, slopedist; "
        "print(sorted(m for m in sys.modules if m.startswith(('slopedist.', 'numpy', 'cv2'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_every_subpackage_says_it_is_internal() -> None:
    for init in sorted(SRC.glob("*/__init__.py")):
        doc = (init.read_text(encoding="utf-8").split('"""')[1:2] or [""])[0]
        assert "Internal" in doc, f"{init.parent.name}/__init__.py does not say it is internal"
