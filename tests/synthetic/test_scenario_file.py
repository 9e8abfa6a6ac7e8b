"""Parsing a scenario file: any edit of a valid file gives a scenario or an error naming the
file, never a crash."""

from __future__ import annotations

import copy
import math
import sys
from typing import Any

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist.core.errors import InputFileError
from slopedist.synthetic.scenario_file import load_scenario_text, parse_scenario
from slopedist.synthetic.scenarios import builtin_text
from slopedist.synthetic.scene import Scenario

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def test_text_and_parsed_data_give_the_same_scenario() -> None:
    text = builtin_text("ego_crest")
    a = load_scenario_text(text, "a.toml", "ego_crest")
    b = parse_scenario(tomllib.loads(text), "a.toml", text, "ego_crest")
    assert a == b and a.name == "ego_crest" and a.source == "a.toml"


BASE = tomllib.loads(builtin_text("bumps_and_curves"))


def _leaves(d: Any, prefix: tuple = ()) -> list[tuple]:
    if isinstance(d, dict):
        out = [(*prefix, k) for k in d]
        for k, v in d.items():
            out += _leaves(v, (*prefix, k))
        return out
    if isinstance(d, list):
        out = []
        for i, v in enumerate(d):
            out += _leaves(v, (*prefix, i))
        return out
    return []


PATHS = sorted(set(_leaves(BASE)), key=str)
VALUES = st.one_of(
    st.integers(-(10**6), 10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=5),
    st.booleans(),
    st.lists(st.floats(-100, 100), max_size=4),
    st.dictionaries(st.sampled_from(["x", "at_m", "speed_kmh"]), st.integers(-5, 5), max_size=2),
)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(PATHS), VALUES), min_size=1, max_size=3))
def test_edited_files_never_crash(edits: list[tuple[tuple, Any]]) -> None:
    data = copy.deepcopy(BASE)
    for path, value in edits:
        node = data
        try:
            for key in path[:-1]:
                node = node[key]
            node[path[-1]] = value
        except (KeyError, IndexError, TypeError):
            continue
    try:
        sc = parse_scenario(data, "edited.toml")
    except InputFileError as exc:
        assert "edited.toml" in str(exc)
        return
    assert isinstance(sc, Scenario)
    assert math.isfinite(sc.duration_s) and np.isfinite(sc.road.start_grade_pct)
