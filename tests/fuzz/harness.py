"""Fuzzing every reader and command: mutated inputs, run in process, outcomes classified.

A *case* is one command line over a small valid corpus (a rendered synthetic scenario with its
calibration, poses, boxes, timestamps, depth maps and scenario file; KITTI-layout labels and
PointRCNN detections made from it; a finished ``run`` folder), with one input file mutated. Each
case ends in exactly one outcome:

- ``clean_error``: exit code 2 and a message (a user mistake, reported as such);
- ``ok``: exit code 0, and every ``records.csv`` row marked ``ok`` has a finite distance in
  ``(0, MAX_PLAUSIBLE_M]`` — a per-item state covers everything else;
- ``bad_ok``: exit code 0 but an ``ok`` row with a non-finite, negative or implausible distance;
- ``internal_error``: exit code 1 (an exception the program did not expect);
- ``traceback``: an exception escaped :func:`slopedist.cli.main`;
- ``hang``: the case ran longer than :data:`CASE_TIMEOUT_S`.

Only the first two are allowed. Used by ``tests/fuzz/test_fuzz_cli.py`` (a fast hypothesis
profile) and ``benchmarks/fuzz_inputs.py`` (the long profile, with counts per outcome).
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import random
import shutil
import signal
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

MAX_PLAUSIBLE_M = 1000.0
"""A distance marked ``ok`` beyond this many metres is implausible for a camera on a car."""

CASE_TIMEOUT_S = 60
"""A case running longer than this is a hang."""

ALLOWED = frozenset({"clean_error", "ok"})
"""Outcomes that are not defects."""

NASTY_NUMBERS = ("nan", "NaN", "inf", "-inf", "1e308", "-1e308", "1e23", "-1", "0", "", "1e-300")


# --------------------------------------------------------------------------------- the corpus
@dataclass(frozen=True)
class Corpus:
    """Paths of a valid input set (all under ``root``)."""

    root: Path

    @property
    def sim(self) -> Path:
        return self.root / "sim"

    @property
    def run_dir(self) -> Path:
        return self.root / "run"

    @property
    def kitti(self) -> Path:
        return self.root / "kitti"


def build_corpus(root: Path, frames: int = 12) -> Corpus:
    """Render a short scenario and derive every input kind from it (a few seconds)."""
    from slopedist.cli import main

    corpus = Corpus(root)
    code = main(
        [
            "simulate",
            "target_steep_uphill",
            "--out",
            str(corpus.sim),
            "--frames",
            str(frames),
            "--depth",
            "npy",
        ]
    )
    assert code == 0, "simulate failed while building the fuzz corpus"
    _write_kitti_layout(corpus)
    run_args = ["run", str(corpus.sim / "image_02"), "--calib", str(corpus.sim / "calib.txt")]
    run_args += ["--boxes", str(corpus.sim / "boxes.csv"), "--method", "paper", "--quiet"]
    code = main([*run_args, "--out", str(corpus.run_dir)])
    assert code == 0, "run failed while building the fuzz corpus"
    return corpus


def _write_kitti_layout(corpus: Corpus) -> None:
    """``kitti/{label_02,calib,orbslam3_poses}/0000.txt`` and a PointRCNN file from the truth."""
    rows = list(csv.DictReader((corpus.sim / "truth.csv").open(encoding="utf-8")))
    labels, pointrcnn = [], []
    for r in rows:
        if r["in_view"] != "1":
            continue
        box = " ".join(r[k] for k in ("left", "top", "right", "bottom"))
        xyz = f"{r['x_m']} {r['y_m']} {r['z_m']}"
        labels.append(f"{r['frame']} {r['track_id']} Car 0 0 0 {box} 1.5 1.6 3.9 {xyz} 0")
        pointrcnn.append(
            f"{r['frame']},2,{','.join(r[k] for k in ('left', 'top', 'right', 'bottom'))},"
            f"3.5,1.5,1.6,3.9,{r['x_m']},{r['y_m']},{r['z_m']},0,0"
        )
    for sub, text in (
        ("label_02", "\n".join(labels) + "\n"),
        ("calib", (corpus.sim / "calib.txt").read_text(encoding="utf-8")),
        ("orbslam3_poses", (corpus.sim / "poses.txt").read_text(encoding="utf-8")),
        ("pointrcnn_car", "\n".join(pointrcnn) + "\n"),
    ):
        (corpus.kitti / sub).mkdir(parents=True, exist_ok=True)
        (corpus.kitti / sub / "0000.txt").write_text(text, encoding="utf-8")


# ------------------------------------------------------------------------------ the mutations
Mutation = Callable[[bytes, random.Random], bytes]


def truncate(data: bytes, rng: random.Random) -> bytes:
    return data[: rng.randrange(len(data) + 1)]


def random_bytes(data: bytes, rng: random.Random) -> bytes:
    out = bytearray(data)
    for _ in range(rng.randint(1, 8)):
        out.insert(rng.randrange(len(out) + 1), rng.randrange(256))
    return bytes(out)


def non_utf8(data: bytes, rng: random.Random) -> bytes:
    pos = rng.randrange(len(data) + 1)
    return data[:pos] + rng.choice([b"\xff", b"\xc3\x28", b"\x80\x80", b"\xfe\xff"]) + data[pos:]


def empty(data: bytes, rng: random.Random) -> bytes:
    return b""


def header_only(data: bytes, rng: random.Random) -> bytes:
    return data.split(b"\n", 1)[0] + b"\n"


def nasty_number(data: bytes, rng: random.Random) -> bytes:
    """One numeric token replaced by NaN, ±inf, 1e308, -1, 0, empty, …."""
    text = data.decode("utf-8", "replace")
    tokens = _number_spans(text)
    if not tokens:
        return data
    a, b = rng.choice(tokens)
    return (text[:a] + rng.choice(NASTY_NUMBERS) + text[b:]).encode()


def _number_spans(text: str) -> list[tuple[int, int]]:
    import re

    return [m.span() for m in re.finditer(r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?", text)]


def drop_field(data: bytes, rng: random.Random) -> bytes:
    lines = data.split(b"\n")
    i = rng.randrange(len(lines))
    sep = b"," if b"," in lines[i] else b" "
    parts = lines[i].split(sep)
    if len(parts) > 1:
        parts.pop(rng.randrange(len(parts)))
    lines[i] = sep.join(parts)
    return b"\n".join(lines)


def add_field(data: bytes, rng: random.Random) -> bytes:
    lines = data.split(b"\n")
    i = rng.randrange(len(lines))
    sep = b"," if b"," in lines[i] else b" "
    lines[i] = lines[i] + sep + b"7"
    return b"\n".join(lines)


def duplicate_line(data: bytes, rng: random.Random) -> bytes:
    lines = data.split(b"\n")
    i = rng.randrange(len(lines))
    lines.insert(i, lines[i])
    return b"\n".join(lines)


def huge_field(data: bytes, rng: random.Random) -> bytes:
    pos = rng.randrange(len(data) + 1)
    return data[:pos] + b"9" * rng.choice([1000, 200_000, 1_200_000]) + data[pos:]


def crlf(data: bytes, rng: random.Random) -> bytes:
    return data.replace(b"\n", b"\r\n")


def bom(data: bytes, rng: random.Random) -> bytes:
    return b"\xef\xbb\xbf" + data


MUTATIONS: dict[str, Mutation] = {
    f.__name__: f
    for f in (
        truncate,
        random_bytes,
        non_utf8,
        empty,
        header_only,
        nasty_number,
        nasty_number,
        drop_field,
        add_field,
        duplicate_line,
        huge_field,
        crlf,
        bom,
    )
}


# ---------------------------------------------------------------------------------- the cases
@dataclass(frozen=True)
class Case:
    """A command line over the corpus with one file to mutate (paths relative to the corpus)."""

    name: str
    argv: tuple[str, ...]
    target: str

    def resolved(self, root: Path, out: Path) -> list[str]:
        """The command line with ``{root}`` and ``{out}`` filled in."""
        return [a.format(root=root, out=out) for a in self.argv]


S = "{root}/sim"
ESTIMATE = ("estimate", "--calib", f"{S}/calib.txt", "--poses", f"{S}/poses.txt")
DEMO = ("--frames", "4", "--no-video", "--out", "{out}/demo")
DEPTH = ("--odometry", "none", "--depth-dir", f"{S}/depth")
RUN = ("run", f"{S}/image_02", "--calib", f"{S}/calib.txt", "--quiet", "--out", "{out}/run")

CASES: tuple[Case, ...] = (
    *(
        Case(
            f"estimate-{m}-{t}",
            (*ESTIMATE, "--boxes", f"{S}/boxes.csv", "--method", m, "--out", "{out}/r.csv"),
            f"sim/{t}",
        )
        for m in ("flat", "paper", "ours")
        for t in ("calib.txt", "poses.txt", "boxes.csv")
    ),
    Case(
        "estimate-kitti-labels",
        (*ESTIMATE, "--boxes", "{root}/kitti/label_02/0000.txt", "--out", "{out}/r.csv"),
        "kitti/label_02/0000.txt",
    ),
    Case(
        "estimate-pointrcnn",
        (*ESTIMATE, "--boxes", "{root}/kitti/pointrcnn_car/0000.txt", "--out", "{out}/r.csv"),
        "kitti/pointrcnn_car/0000.txt",
    ),
    *(
        Case(f"run-{m}-{t}", (*RUN, "--boxes", f"{S}/boxes.csv", "--method", m), f"sim/{t}")
        for m in ("paper", "ours")
        for t in ("calib.txt", "boxes.csv")
    ),
    Case(
        "run-timestamps",
        (*RUN, "--boxes", f"{S}/boxes.csv", "--timestamps", f"{S}/times.txt"),
        "sim/times.txt",
    ),
    Case("run-frame-png", (*RUN, "--boxes", f"{S}/boxes.csv"), "sim/image_02/000003.png"),
    Case(
        "run-depth-npy",
        (*RUN, "--boxes", f"{S}/boxes.csv", "--method", "depthmap", *DEPTH),
        "sim/depth/000002.npy",
    ),
    Case("report-records", ("report", "{root}/run", "--out", "{out}/rep"), "run/records.csv"),
    Case("report-runjson", ("report", "{root}/run", "--out", "{out}/rep"), "run/run.json"),
    Case(
        "demo-scenario",
        ("demo", "--scenarios", f"{S}/scenario.toml", *DEMO),
        "sim/scenario.toml",
    ),
    Case(
        "simulate-scenario",
        ("simulate", f"{S}/scenario.toml", "--frames", "3", "--no-images", "--out", "{out}/s"),
        "sim/scenario.toml",
    ),
    *(
        Case(
            f"eval-{t.split('/')[0]}",
            ("eval", "kitti-tracking", "{root}/kitti", "--methods", "flat,paper,ours"),
            f"kitti/{t}",
        )
        for t in ("label_02/0000.txt", "calib/0000.txt", "orbslam3_poses/0000.txt")
    ),
    Case(
        "eval-pointrcnn",
        ("eval", "kitti-tracking", "{root}/kitti", "--boxes", "pointrcnn", "--score", "0.5"),
        "kitti/pointrcnn_car/0000.txt",
    ),
)


# ------------------------------------------------------------------------------- running one
@dataclass(frozen=True)
class Outcome:
    """What one case did."""

    case: str
    mutation: str
    kind: str
    detail: str


class _TimeoutError(Exception):
    pass


@contextlib.contextmanager
def _alarm(seconds: int) -> Iterator[None]:
    def fire(signum: int, frame: object) -> None:
        raise _TimeoutError

    old = signal.signal(signal.SIGALRM, fire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def run_case(corpus: Corpus, case: Case, mutation: str, seed: int, work: Path) -> Outcome:
    """Copy the corpus to ``work``, mutate the case's file, run the command, classify."""
    root = work / "corpus"
    if root.exists():
        shutil.rmtree(root)
    shutil.copytree(corpus.root, root)
    out = work / "out"
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    target = root / case.target
    target.write_bytes(MUTATIONS[mutation](target.read_bytes(), random.Random(seed)))
    argv = case.resolved(root, out)
    from slopedist.cli import main

    stderr = io.StringIO()
    try:
        with (
            _alarm(CASE_TIMEOUT_S),
            contextlib.redirect_stdout(io.StringIO()),
            contextlib.redirect_stderr(stderr),
        ):
            code = main(argv)
    except _TimeoutError:
        return Outcome(case.name, mutation, "hang", " ".join(argv))
    except SystemExit as exc:  # click may exit directly
        code = exc.code if isinstance(exc.code, int) else 1
    except BaseException as exc:
        tb = traceback.format_exception_only(type(exc), exc)[-1].strip()
        return Outcome(case.name, mutation, "traceback", tb)
    message = stderr.getvalue().strip().splitlines()
    if code == 2:
        return Outcome(case.name, mutation, "clean_error", message[-1] if message else "")
    if code != 0:
        return Outcome(case.name, mutation, "internal_error", message[-1] if message else "")
    bad = bad_ok_rows(out)
    if bad:
        return Outcome(case.name, mutation, "bad_ok", bad[0])
    return Outcome(case.name, mutation, "ok", "")


def bad_ok_rows(out: Path) -> list[str]:
    """Rows of any ``records.csv`` under ``out`` marked ``ok`` whose distance is not plausible."""
    bad = []
    for path in out.rglob("*.csv"):
        with path.open(encoding="utf-8", newline="") as fh:
            reader = csv.DictReader(fh)
            if not reader.fieldnames or "status" not in reader.fieldnames:
                continue
            for i, row in enumerate(reader, start=2):
                if row.get("status") != "ok" or "distance_m" not in row:
                    continue
                try:
                    d = float(row["distance_m"])
                except ValueError:
                    d = math.nan
                if not (math.isfinite(d) and 0.0 < d <= MAX_PLAUSIBLE_M):
                    bad.append(f"{path.name}:{i} ok with distance {row['distance_m']!r}")
    return bad


def log_outcome(outcome: Outcome) -> None:
    """Append the outcome as a JSON line to ``$SLOPEDIST_FUZZ_LOG`` when that is set."""
    path = os.environ.get("SLOPEDIST_FUZZ_LOG")
    if path:
        with open(path, "a", encoding="utf-8") as fh:
            fh.write(json.dumps(outcome.__dict__) + "\n")
