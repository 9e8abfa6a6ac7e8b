"""Fuzzing every reader and command: mutated inputs, run in process, outcomes classified.

A *case* is one command line over a small valid corpus (a rendered synthetic scenario with its
calibration, poses, boxes, timestamps, depth maps and scenario file; KITTI-layout labels and
PointRCNN detections made from it; a finished ``run`` folder), with one input file mutated. Each
case ends in exactly one outcome:

- ``clean_error``: exit code 2 and a message (a user mistake, reported as such);
- ``same_output``: exit code 0 with the output of the unmutated input (the same records:
  status, reason and distance of every row): the mutation changed nothing that is read
  (line ends, a byte-order mark, a field a command does not use);
- ``states``: exit code 0 with another output, in which every row that differs from the
  unmutated input's is not ``ok``: per-item states cover what changed;
- ``ok``: exit code 0 with ``ok`` rows that the unmutated input does not give (another
  distance, or a row it does not have), each with a finite distance in ``(0, MAX_PLAUSIBLE_M]``
  and a box that meets the corpus' images: the mutation may have changed what the input says
  (a box, a timestamp), or the answer is silently wrong — the cases to read one by one (the
  unmutated corpus' own run counts here too);
- ``bad_ok``: exit code 0 but an ``ok`` row with a non-finite, negative or implausible
  distance, or with a box wholly outside the images;
- ``numpy_warning``: a numpy ``RuntimeWarning`` reached the user (before a clean error or
  not: each stands for an error or a state the program should say instead);
- ``internal_error``: exit code 1 (an exception the program did not expect);
- ``traceback``: an exception escaped :func:`slopedist.cli.main`;
- ``hang``: the case ran longer than :data:`CASE_TIMEOUT_S`.

Only the first four are allowed. Used by ``tests/fuzz/test_fuzz_cli.py`` (a fast hypothesis
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

ALLOWED = frozenset({"clean_error", "same_output", "states", "ok"})
"""Outcomes that are not defects."""

OUTCOMES = (
    "same_output",
    "states",
    "ok",
    "clean_error",
    "bad_ok",
    "numpy_warning",
    "internal_error",
    "traceback",
    "hang",
)
"""Every outcome, in the order the long profile prints their counts."""

IMAGE_SIZE_PX = (1242, 375)
"""The corpus' frames (the KITTI camera of ``slopedist simulate``)."""

NASTY_NUMBERS = (
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e23",
    "-1",
    "0",
    "",
    "1e-300",
    "1e-320",
)


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

    @property
    def outputs(self) -> Path:
        """The records of each case on the unmutated corpus (``NAME.json``)."""
        return self.root.parent / f"{self.root.name}-outputs"


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
    _write_video_log_and_pngs(corpus)
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


def _write_video_log_and_pngs(corpus: Corpus) -> None:
    """``sim/video.mp4`` (MPEG-4 Part 2, a key frame every 6 frames), ``sim/log.mcap`` (the
    frames as a ROS 2 MCAP log written in small chunks with CRCs) and ``sim/depth_png/`` (the
    depth maps as KITTI depth PNGs) from the rendered scenario."""
    import av
    import cv2
    import numpy as np
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    from slopedist.io.calibration import read_calibration
    from slopedist.io.depth.files import read_npy_depth, write_kitti_depth_png
    from slopedist.io.rosbag_write import ImageEncoding, LogFormat, LogFrame, write_log

    sim = corpus.sim
    frames = sorted((sim / "image_02").glob("*.png"))
    images = [cv2.imread(str(f)) for f in frames]
    with av.open(str(sim / "video.mp4"), "w") as container:
        stream = container.add_stream("mpeg4", rate=10)
        stream.width, stream.height = images[0].shape[1], images[0].shape[0]
        stream.pix_fmt, stream.gop_size, stream.bit_rate = "yuv420p", 6, 4_000_000
        for image in images:
            for packet in stream.encode(av.VideoFrame.from_ndarray(image, format="bgr24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    camera = read_calibration(sim / "calib.txt").camera.with_image_size(*IMAGE_SIZE_PX)
    log_frames = [LogFrame(k * 100_000_000, im) for k, im in enumerate(images)]
    bag = write_log(sim / "bag", log_frames, camera, LogFormat.ROS2_MCAP, ImageEncoding.JPEG)
    with next(bag.glob("*.mcap")).open("rb") as src, (sim / "log.mcap").open("wb") as out:
        writer = Writer(out, chunk_size=64_000, compression=CompressionType.NONE)
        writer.start(profile="ros2", library="slopedist fuzz corpus")
        ids: dict[tuple[str, int], int] = {}
        for schema, channel, message in make_reader(src).iter_messages():
            if schema is not None and ("s", schema.id) not in ids:
                ids["s", schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if ("c", channel.id) not in ids:
                ids["c", channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, ids.get(("s", channel.schema_id), 0)
                )
            writer.add_message(
                ids["c", channel.id], message.log_time, message.data, message.publish_time
            )
        writer.finish()
    shutil.rmtree(bag)
    (sim / "depth_png").mkdir()
    for path in sorted((sim / "depth").glob("*.npy")):
        write_kitti_depth_png(sim / "depth_png" / f"{path.stem}.png", read_npy_depth(path))
    assert np.isfinite(read_npy_depth(next((sim / "depth").glob("*.npy")))).any()


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


def flip_bytes(data: bytes, rng: random.Random) -> bytes:
    """200 bytes inverted somewhere in the middle half (a damaged sector)."""
    if len(data) < 400:
        return bytes(b ^ 0xFF for b in data)
    start = rng.randrange(len(data) // 4, 3 * len(data) // 4 - 200)
    return data[:start] + bytes(b ^ 0xFF for b in data[start : start + 200]) + data[start + 200 :]


def truncate_half(data: bytes, rng: random.Random) -> bytes:
    """Cut at half (a recorder that lost power)."""
    return data[: len(data) // 2]


def shuffle_lines(data: bytes, rng: random.Random) -> bytes:
    """Every line but the first in random order."""
    lines = data.split(b"\n")
    rest = lines[1:]
    rng.shuffle(rest)
    return b"\n".join([lines[0], *rest])


FAR_BOXES = ([b"5000", b"5000", b"5100", b"5100"], [b"-900", b"170", b"-800", b"230"])
"""Boxes no image of the corpus' camera holds."""


def far_box(data: bytes, rng: random.Random) -> bytes:
    """A copy of a row of a box CSV with its box far outside any image (``5000, 5000, 5100,
    5100`` or left of it, ``−900 … −800``)."""
    lines = data.rstrip(b"\n").split(b"\n")
    rows = [ln for ln in lines[1:] if ln.count(b",") >= 4]
    if not rows:
        return data
    fields = rng.choice(rows).split(b",")
    fields[1:5] = rng.choice(
        [[b"5000", b"5000", b"5100", b"5100"], [b"-900", b"170", b"-800", b"230"]]
    )
    return b"\n".join([*lines, b",".join(fields)]) + b"\n"


def principal_row(data: bytes, rng: random.Random) -> bytes:
    """The principal point's row ``c_y`` of a KITTI calib file's ``P2:`` line set to −1, 0 or
    1e-320 (a calibration of no image: checked against the image only when a size is known)."""
    lines = data.split(b"\n")
    for i, line in enumerate(lines):
        tokens = line.split()
        if tokens[:1] == [b"P2:"] and len(tokens) == 13:
            tokens[7] = rng.choice([b"-1", b"0", b"1e-320"])  # P2 row 1, column 2
            lines[i] = b" ".join(tokens)
    return b"\n".join(lines)


def saturated_depth(data: bytes, rng: random.Random) -> bytes:
    """A 16-bit depth PNG with every pixel 65535 (255.996 m in KITTI's units: beyond any valid
    depth, never to be capped into one)."""
    import cv2
    import numpy as np

    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None or image.dtype != np.uint16:
        return data
    ok, png = cv2.imencode(".png", np.full_like(image, 65535))
    return png.tobytes() if ok else data


def tiny_value(data: bytes, rng: random.Random) -> bytes:
    """One ``key = number`` value of a TOML file (a scenario) set to 1e-300 (a wheelbase, a
    length that makes a vehicle vanish)."""
    import re

    spans = [
        m.span(1) for m in re.finditer(rb"^\s*\w+\s*=\s*(-?[\d.]+(?:[eE][-+]?\d+)?)", data, re.M)
    ]
    if not spans:
        return data
    a, b = rng.choice(spans)
    return data[:a] + b"1e-300" + data[b:]


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
        flip_bytes,
        truncate_half,
        shuffle_lines,
        far_box,
        principal_row,
        saturated_depth,
        tiny_value,
    )
}

UNMUTATED = "unmutated"
"""The name :func:`run_case` takes for running a case on the corpus as it is."""


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
    Case(
        "run-video",
        ("run", f"{S}/video.mp4", *RUN[2:], "--boxes", f"{S}/boxes.csv", "--method", "paper"),
        "sim/video.mp4",
    ),
    Case(
        "run-mcap",
        (
            "run",
            f"{S}/log.mcap",
            "--image-topic",
            "/camera/image_raw",
            "--quiet",
            "--out",
            "{out}/run",
            "--boxes",
            f"{S}/boxes.csv",
            "--method",
            "paper",
        ),
        "sim/log.mcap",
    ),
    Case(
        "run-depth-png",
        (
            *RUN,
            "--boxes",
            f"{S}/boxes.csv",
            "--method",
            "depthmap",
            "--odometry",
            "none",
            "--depth-dir",
            f"{S}/depth_png",
        ),
        "sim/depth_png/000004.png",
    ),
    Case(
        "run-depth-window",
        (
            *RUN,
            "--boxes",
            f"{S}/boxes.csv",
            "--method",
            "depthmap",
            *DEPTH,
            "--depth-sample",
            "window",
            "--depth-window",
            "100001",
        ),
        "sim/depth/000003.npy",
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
    """Copy the corpus to ``work``, mutate the case's file (:data:`UNMUTATED`: leave it), run
    the command, classify (comparing with the records of the unmutated run)."""
    root = work / "corpus"
    if root.exists():
        shutil.rmtree(root)
    shutil.copytree(corpus.root, root)
    out = work / "out"
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    if mutation != UNMUTATED:
        target = root / case.target
        target.write_bytes(MUTATIONS[mutation](target.read_bytes(), random.Random(seed)))
    argv = case.resolved(root, out)
    code, message, numpy_warnings = _run(argv)
    if isinstance(code, Outcome):
        return Outcome(case.name, mutation, code.kind, code.detail)
    if numpy_warnings:
        return Outcome(case.name, mutation, "numpy_warning", numpy_warnings[0])
    if code == 2:
        return Outcome(case.name, mutation, "clean_error", message)
    if code != 0:
        return Outcome(case.name, mutation, "internal_error", message)
    bad = bad_ok_rows(out)
    if bad:
        return Outcome(case.name, mutation, "bad_ok", bad[0])
    records = output_records(out, root)
    if mutation == UNMUTATED:
        corpus.outputs.mkdir(parents=True, exist_ok=True)
        (corpus.outputs / f"{case.name}.json").write_text(json.dumps(records), encoding="utf-8")
        return Outcome(case.name, mutation, "ok", "")
    unmutated = unmutated_records(corpus, case, work.parent / f"{work.name}-unmutated")
    if records == unmutated:
        return Outcome(case.name, mutation, "same_output", "")
    changed = changed_ok_rows(records, unmutated)
    if changed:
        return Outcome(case.name, mutation, "ok", changed[0])
    return Outcome(case.name, mutation, "states", "")


def _run(argv: list[str]) -> tuple[int | Outcome, str, list[str]]:
    """``(exit code, or the outcome of a hang or escaped exception; the last line of the
    messages; the numpy RuntimeWarnings raised, as "file:line: text")`` of one command."""
    import warnings

    from slopedist.cli import main

    stderr = io.StringIO()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        try:
            with (
                _alarm(CASE_TIMEOUT_S),
                contextlib.redirect_stdout(io.StringIO()),
                contextlib.redirect_stderr(stderr),
            ):
                code = main(argv)
        except _TimeoutError:
            return Outcome("", "", "hang", " ".join(argv)), "", []
        except SystemExit as exc:  # click may exit directly
            code = exc.code if isinstance(exc.code, int) else 1
        except BaseException as exc:
            tb = traceback.format_exception_only(type(exc), exc)[-1].strip()
            return Outcome("", "", "traceback", tb), "", []
    numpy_warnings = [
        f"{Path(w.filename).name}:{w.lineno}: {w.message}"
        for w in caught
        if issubclass(w.category, RuntimeWarning)
    ]
    message = stderr.getvalue().strip().splitlines()
    return code, message[-1] if message else "", numpy_warnings


def unmutated_records(corpus: Corpus, case: Case, work: Path) -> list[list[str]]:
    """The records of ``case`` on the unmutated corpus (run once, then kept)."""
    path = corpus.outputs / f"{case.name}.json"
    if not path.exists():
        outcome = run_case(corpus, case, UNMUTATED, 0, work)
        if not path.exists():
            raise AssertionError(f"the unmutated corpus fails {case.name}: {outcome}")
    records: list[list[str]] = json.loads(path.read_text(encoding="utf-8"))
    return records


def output_records(out: Path, root: Path) -> list[list[str]]:
    """What a command's output says of the targets: every row of every CSV under ``out``
    with a ``status`` column, as ``[file, frame, track, status, reason, distance]`` (no
    timings, no paths), and for a command without such a file the names of its files."""
    rows: list[list[str]] = []
    for path in sorted(out.rglob("*.csv")):
        with path.open(encoding="utf-8", newline="") as fh:
            reader = csv.DictReader(fh)
            if not reader.fieldnames or "status" not in reader.fieldnames:
                continue
            keys = ("frame", "track_id", "status", "reason", "distance_m")
            name = str(path.relative_to(out))
            rows += [[name, *(row.get(k) or "" for k in keys)] for row in reader]
    if not rows:
        rows = [[str(p.relative_to(out))] for p in sorted(out.rglob("*")) if p.is_file()]
    return rows


def changed_ok_rows(records: list[list[str]], unmutated: list[list[str]]) -> list[str]:
    """Rows of ``records`` (:func:`output_records`) marked ``ok`` that the unmutated records
    do not hold as they are (the same file, frame and track, ``ok``, the same distance)."""
    before = {tuple(r[:3]): r for r in unmutated if len(r) == 6}
    changed = []
    for r in records:
        if len(r) == 6 and r[3] == "ok" and before.get(tuple(r[:3])) != r:
            was = before.get(tuple(r[:3]))
            then = f"{was[3]} {was[5]}" if was else "no row"
            changed.append(f"{r[0]} frame {r[1]} track {r[2]}: ok {r[5]} m (unmutated: {then})")
    return changed


def bad_ok_rows(out: Path) -> list[str]:
    """Rows of any records CSV under ``out`` marked ``ok`` whose distance is not plausible, or
    whose box lies wholly outside the corpus' images (:data:`IMAGE_SIZE_PX`)."""
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
                elif _outside_image(row):
                    box = ", ".join(row[k] for k in ("left", "top", "right", "bottom"))
                    bad.append(f"{path.name}:{i} ok for a box outside the images ({box})")
    return bad


def _outside_image(row: dict[str, str]) -> bool:
    """Whether a records row's box lies wholly outside the corpus' images."""
    try:
        left, top, right, bottom = (float(row[k]) for k in ("left", "top", "right", "bottom"))
    except (KeyError, TypeError, ValueError):
        return False
    width, height = IMAGE_SIZE_PX
    return right <= -0.5 or bottom <= -0.5 or left >= width - 0.5 or top >= height - 0.5


def log_outcome(outcome: Outcome) -> None:
    """Append the outcome as a JSON line to ``$SLOPEDIST_FUZZ_LOG`` when that is set."""
    path = os.environ.get("SLOPEDIST_FUZZ_LOG")
    if path:
        with open(path, "a", encoding="utf-8") as fh:
            fh.write(json.dumps(outcome.__dict__) + "\n")
