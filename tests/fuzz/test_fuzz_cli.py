"""Fuzz every reader and command with mutated inputs: only a clean error or a trustworthy output.

The fast profile runs ``SLOPEDIST_FUZZ_EXAMPLES`` cases (default 40) here; the long profile is
``python benchmarks/fuzz_inputs.py`` (≥ 2,000 cases, counts by outcome).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).parent))
from harness import (
    ALLOWED,
    CASES,
    MUTATIONS,
    UNMUTATED,
    Case,
    Corpus,
    bad_ok_rows,
    build_corpus,
    log_outcome,
    run_case,
)

EXAMPLES = int(os.environ.get("SLOPEDIST_FUZZ_EXAMPLES", "40"))


@pytest.fixture(scope="module")
def corpus(tmp_path_factory: pytest.TempPathFactory) -> Corpus:
    return build_corpus(tmp_path_factory.mktemp("fuzz_corpus"))


@pytest.fixture(scope="module")
def work(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("fuzz_work")


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_unmutated_corpus_runs_clean(corpus: Corpus, work: Path, case: Case) -> None:
    """The harness's baseline: every command succeeds on the valid corpus, without a numpy
    warning, and gives its records again when nothing it reads changed."""
    assert run_case(corpus, case, UNMUTATED, 0, work).kind == "ok"
    if case.target.endswith((".csv", ".txt")):  # crlf keeps a text file as it was
        assert run_case(corpus, case, "crlf", 0, work).kind == "same_output"


def test_bad_ok_rows_sees_implausible_distances(tmp_path: Path) -> None:
    (tmp_path / "records.csv").write_text(
        "frame,distance_m,status\n0,12.5,ok\n1,,missing\n2,-3,ok\n3,1e9,ok\n4,nan,ok\n"
    )
    assert len(bad_ok_rows(tmp_path)) == 3


def test_bad_ok_rows_sees_boxes_outside_the_images(tmp_path: Path) -> None:
    (tmp_path / "records.csv").write_text(
        "frame,left,top,right,bottom,distance_m,status\n0,500,150,600,250,12.5,ok\n"
        "1,5000,5000,5100,5100,0.24,ok\n2,-900,170,-800,230,9.36,ok\n"
        "3,5000,5000,5100,5100,,missing\n"
    )
    assert len(bad_ok_rows(tmp_path)) == 2


@settings(
    max_examples=EXAMPLES,
    deadline=None,
    derandomize=os.environ.get("SLOPEDIST_FUZZ_RANDOM") is None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(
    case=st.sampled_from(CASES),
    mutation=st.sampled_from(sorted(MUTATIONS)),
    seed=st.integers(0, 2**16),
)
def test_mutated_inputs_give_a_clean_error_or_trustworthy_output(
    corpus: Corpus, work: Path, case: Case, mutation: str, seed: int
) -> None:
    outcome = run_case(corpus, case, mutation, seed, work)
    log_outcome(outcome)
    assert outcome.kind in ALLOWED, outcome
