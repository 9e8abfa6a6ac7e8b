"""The fuzz suite's long profile: mutated inputs over every reader and command, counts by outcome.

Builds the small valid corpus of ``tests/fuzz/harness.py`` once (a rendered scenario with its
calibration, poses, boxes, depth maps as ``.npy`` and KITTI PNG, a video and an MCAP log of its
frames, KITTI-layout labels, a finished run), then runs ``--cases`` cases (default 2,000), each
a command with one input file mutated (truncation, cut at half, 200 bytes inverted, random or
non-UTF-8 bytes, NaN/inf/1e308/1e-320 numbers, empty files, header only, wrong column counts,
huge fields, BOM, lines shuffled, a box far outside the image, a calibration's principal row at
−1, 0 or 1e-320, a depth PNG saturated at 65535, a scenario value of 1e-300), drawn with a
fixed seed (``--seed``), commands and mutations both in turn. Unlike the fast profile in the
tests (hypothesis, which stops at the first defect), every case runs, and the counts by outcome
are printed: the allowed ``same_output`` (accepted, with the records of the unmutated input),
``states`` (accepted with other records, every changed row in a state other than ``ok``),
``ok`` (accepted with ``ok`` rows the unmutated input does not give: examples are printed, to
read one by one) and ``clean_error``, and the defects ``bad_ok``, ``numpy_warning``,
``internal_error``, ``traceback`` and ``hang`` with examples; then the outcomes per mutation.

Usage (from the repository root)::

    python benchmarks/fuzz_inputs.py [--cases 2000] [--seed 0]
"""

from __future__ import annotations

import argparse
import collections
import math
import random
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "fuzz"))
from harness import ALLOWED, CASES, MUTATIONS, OUTCOMES, build_corpus, run_case


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = random.Random(args.seed)
    mutations = sorted(MUTATIONS)
    counts: collections.Counter[str] = collections.Counter()
    per_case: dict[str, collections.Counter[str]] = collections.defaultdict(collections.Counter)
    per_mutation: dict[str, collections.Counter[str]] = collections.defaultdict(collections.Counter)
    defects = []
    changed_ok = []
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        corpus = build_corpus(Path(tmp) / "corpus")
        for i in range(args.cases):
            # command lines and mutations both in turn (any hundred cases cover every
            # mutation), shifted by one once their cycles meet so that other pairs come next
            case = CASES[i % len(CASES)]
            mutation = mutations[(i + i // math.lcm(len(CASES), len(mutations))) % len(mutations)]
            outcome = run_case(corpus, case, mutation, rng.randrange(2**31), Path(tmp) / "work")
            counts[outcome.kind] += 1
            per_case[case.name][outcome.kind] += 1
            per_mutation[mutation][outcome.kind] += 1
            if outcome.kind not in ALLOWED:
                defects.append(outcome)
            elif outcome.kind == "ok":
                changed_ok.append(outcome)
    print(f"{args.cases} cases over {len(CASES)} command lines × {len(mutations)} mutations")
    print(f"({time.perf_counter() - start:.0f} s)")
    for kind in OUTCOMES:
        print(f"  {kind:15s} {counts.get(kind, 0)}")
    allowed = [k for k in OUTCOMES if k in ALLOWED]
    print("per mutation (" + ", ".join(allowed) + ", defects):")
    for name in mutations:
        c = per_mutation[name]
        defects_here = sum(v for k, v in c.items() if k not in ALLOWED)
        print(f"  {name:15s} " + " ".join(f"{c.get(k, 0):5d}" for k in allowed), end="")
        print(f" {defects_here:5d}")
    for o in changed_ok[:12]:
        print(f"  ok with other rows: {o.case} / {o.mutation}: {o.detail[:140]}")
    for o in defects[:25]:
        print(f"  DEFECT {o.kind}: {o.case} / {o.mutation}: {o.detail[:160]}")
    if defects:
        worst = collections.Counter(o.case for o in defects).most_common(8)
        print("defects per command line:", ", ".join(f"{k} {v}" for k, v in worst))
    return 1 if defects else 0


if __name__ == "__main__":
    sys.exit(main())
