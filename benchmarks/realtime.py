"""Real-time budget of ``slopedist run``: time per frame per stage, and the odometry against a
naive OpenCV reference.

Inputs (made from the shared data, written under ``--out``):

- ``kitti``: the 78 colour PNG frames of ``kitti_raw_lead`` (1242×375), its calibration, and
  vehicle boxes from its LiDAR scans (as ``benchmarks/kitti_raw_lead.py`` makes them);
- ``1080p``: the same frames scaled by 1080/375 = 2.88 in both axes and centre-cropped to
  1920×1080, encoded as H.264 (PyAV, libx264, CRF 18) at 10 fps; the camera and the boxes
  scaled and cropped to match.

Part 1, the run: ``run_frames`` with method ``ours`` and the built-in odometry, each run in a
fresh subprocess pinned to one core (``os.sched_setaffinity``, ``cv2.setNumThreads(1)``, frames
decoded in the loop, or ahead in a thread: ``ahead 4``) or to two cores (two OpenCV threads,
frames decoded ahead in a thread),
with and without an MP4 overlay. Per frame: wall and processor time of each stage (decode,
odometry, estimation, writing the CSV rows, overlay draw, overlay encode; processor time of the
thread running the stage: OpenCV's own worker threads are not in it) and of the whole run (wall,
and processor time of all threads). ``other`` = the loop's wall time outside the named stages
(grey conversion, bookkeeping, waiting for a decoded frame or for room in the overlay queue;
with ``ahead 4`` decoding, and the overlay's drawing and encoding, run in threads of their
own). Runs alternate
between the configurations; min and median of ``--repeats`` runs.

Part 2, the odometry alone (frames decoded beforehand, one core, one process): the built-in
odometry at its default working size (frames over 1280 px wide are scaled down), the built-in
odometry at full resolution, and a naive reference (Shi–Tomasi corners, 250, on every frame,
pyramidal Lucas–Kanade into the next, ``findEssentialMat`` RANSAC, ``recoverPose``, rotations
chained), alternated in one process, on the two KITTI odometry excerpts at their size and scaled
to 1920 px wide, and on ``kitti``/``1080p``. Accuracy: θ RMS and median one-second rotation error
against the ground truth (the excerpts), and θ RMS against the built-in odometry at full
resolution (``kitti_raw_lead``, which has no ground-truth rotations); ``÷ naive``: median time
per frame over the naive reference's, wall / processor.

Part ``startup``: wall and processor time of ``python -m slopedist --help`` with a warm bytecode
cache, against a bare interpreter (and another source tree with ``--compare-src``).

Part ``demo``: wall and processor time of ``slopedist demo`` with its scenarios in worker
processes (the default) and one after the other (``--jobs 1``), and from ``--compare-src``.

Part ``widths``: the built-in odometry's accuracy and processor time per working width
(``VisualOdometryConfig.max_width_px``) on the inputs wider than 1280 px.

Usage::

    python benchmarks/realtime.py [--data ../shared/data] [--out bench_out/realtime]
        [--repeats 3] [--part run|odometry|widths|startup|demo|all] [--compare-src ../main/src]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any
from unittest import mock

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.estimators import make_estimator
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.readers import read_box_file
from slopedist.io.detections.writers import write_box_csv
from slopedist.io.formatting import CsvStreamWriter
from slopedist.io.frames import Frame, FrameSource, open_frames
from slopedist.io.kitti.odometry import read_kitti_odometry
from slopedist.io.kitti.raw import KittiRawDrive
from slopedist.odometry.accuracy import OdometryEvaluation, OdometryRun, rotation_errors
from slopedist.odometry.base import OdometryResult, OdometryState, RotationOdometry
from slopedist.odometry.visual import BuiltinVisualOdometry, VisualOdometryConfig
from slopedist.streaming import loop as runner
from slopedist.streaming.step import FrameStep

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data"
HD = (1920, 1080)
KITTI_SIZE = (1242, 375)
STAGES = ("decode", "odometry", "estimation", "writing", "overlay draw", "overlay encode")
NAIVE_POINTS = 250

Gray = NDArray[np.uint8]


# ----------------------------------------------------------------------------- inputs
@dataclass(frozen=True)
class RunInput:
    """A frame source for ``run``: frames (folder or video), camera, box CSV."""

    name: str
    frames: Path
    camera: Camera
    boxes: Path


def crop_camera(camera: Camera, scale: float, x0: int, size: tuple[int, int]) -> Camera:
    """``camera`` of frames scaled by ``scale`` then cropped from column ``x0`` to ``size``."""
    return replace(
        camera,
        f=camera.f * scale,
        c_x=scale * (camera.c_x + 0.5) - 0.5 - x0,
        c_y=scale * (camera.c_y + 0.5) - 0.5,
        image_width=size[0],
        image_height=size[1],
    )


def crop_boxes(boxes: BoxTable, scale: float, x0: int, size: tuple[int, int]) -> BoxTable:
    """Boxes of the scaled and cropped frames (clipped; boxes left with < 8 px dropped)."""
    b = scale * (boxes.boxes + 0.5) - 0.5 - np.array([x0, 0, x0, 0])
    b[:, [0, 2]] = np.clip(b[:, [0, 2]], 0, size[0] - 1)
    return replace(boxes, boxes=b).select(b[:, 2] - b[:, 0] >= 8)


def hd_scale_crop(width: int, height: int) -> tuple[float, int]:
    """Scale (to 1080 rows) and first column of the 1920-wide centre crop."""
    scale = HD[1] / height
    return scale, (round(width * scale) - HD[0]) // 2


def hd_frame(image: NDArray[np.uint8], scale: float, x0: int) -> NDArray[np.uint8]:
    width, height = image.shape[1], image.shape[0]
    big = cv2.resize(
        image, (round(width * scale), round(height * scale)), interpolation=cv2.INTER_LINEAR
    )
    return np.ascontiguousarray(big[: HD[1], x0 : x0 + HD[0]])


def write_h264(images: Iterator[NDArray[np.uint8]], path: Path, fps: int = 10) -> None:
    """BGR frames to an H.264 MP4 (PyAV, libx264, yuv420p, CRF 18)."""
    import av

    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264", rate=fps)
        stream.width, stream.height = HD
        stream.pix_fmt = "yuv420p"
        stream.options = {"crf": "18"}
        for image in images:
            for packet in stream.encode(av.VideoFrame.from_ndarray(image, format="bgr24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def make_run_inputs(data: Path, out: Path) -> list[RunInput]:
    """The ``kitti`` and ``1080p`` inputs (the video and box files made once under ``out``)."""
    drive = KittiRawDrive.open(data / "kitti_raw_lead")
    camera = drive.calib.camera().with_image_size(*KITTI_SIZE)
    boxes = drive.lidar_boxes(KITTI_SIZE)
    kitti_boxes = write_box_csv(boxes, out / "kitti_boxes.csv", ())
    scale, x0 = hd_scale_crop(*KITTI_SIZE)
    video = out / "kitti_raw_lead_1080p.mp4"
    if not video.is_file():
        frames = (f.image for f in open_frames(drive.image_dir) if f.image is not None)
        write_h264((hd_frame(image, scale, x0) for image in frames), video)
    hd_boxes = write_box_csv(crop_boxes(boxes, scale, x0, HD), out / "hd_boxes.csv", ())
    return [
        RunInput("kitti", drive.image_dir, camera, kitti_boxes),
        RunInput("1080p", video, crop_camera(camera, scale, x0, HD), hd_boxes),
    ]


# ----------------------------------------------------------------------------- part 1: run
class StageClock:
    """Wall and thread-processor seconds per stage (each stage timed in the thread it runs)."""

    def __init__(self) -> None:
        self.wall: defaultdict[str, float] = defaultdict(float)
        self.cpu: defaultdict[str, float] = defaultdict(float)

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        w0, c0 = time.perf_counter(), time.thread_time()
        try:
            yield
        finally:
            self.wall[name] += time.perf_counter() - w0
            self.cpu[name] += time.thread_time() - c0

    def timed(self, name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            with self.stage(name):
                return fn(*args, **kwargs)

        return wrapper


class TimedSource:
    """A frame source whose decoding (each ``next``) is timed as ``decode``."""

    def __init__(self, source: FrameSource, clock: StageClock) -> None:
        self.source, self.clock, self.path = source, clock, source.path

    def expected_frames(self) -> int | None:
        return self.source.expected_frames()

    def frame_size(self) -> tuple[int, int]:
        return self.source.frame_size()

    def __iter__(self) -> Iterator[Frame]:
        frames = iter(self.source)
        while True:
            with self.clock.stage("decode"):
                frame = next(frames, None)
            if frame is None:
                return
            yield frame


def instrumented(clock: StageClock, stack: ExitStack) -> None:
    """Time the run's stages by wrapping what ``slopedist.streaming.loop`` calls."""
    step = FrameStep.step
    stack.enter_context(mock.patch.object(FrameStep, "step", clock.timed("estimation", step)))
    draw = clock.timed("overlay draw", runner.draw_fig3_overlay)
    stack.enter_context(mock.patch.object(runner, "draw_fig3_overlay", draw))
    for name in ("write", "close"):
        method = clock.timed("overlay encode", getattr(runner.OverlayWriter, name))
        stack.enter_context(mock.patch.object(runner.OverlayWriter, name, method))
    for name in ("write_row", "write_rows"):
        method = clock.timed("writing", getattr(CsvStreamWriter, name))
        stack.enter_context(mock.patch.object(CsvStreamWriter, name, method))


def worker(args: argparse.Namespace) -> int:
    """One run of one configuration; prints its per-frame figures as JSON."""
    os.sched_setaffinity(0, set(sorted(os.sched_getaffinity(0))[: args.cores]))
    cv2.setNumThreads(args.cores)
    spec = json.loads(args.worker)
    camera = Camera(**spec["camera"])
    clock = StageClock()
    odometry = BuiltinVisualOdometry(camera)
    odometry.process = clock.timed("odometry", odometry.process)  # type: ignore[method-assign]
    out = Path(spec["out"])
    config = runner.RunConfig(
        out,
        overlay=out / "overlay.mp4" if spec["overlay"] else None,
        progress=False,
        decode_ahead=args.ahead,
    )
    boxes = read_box_file(spec["boxes"])
    source = TimedSource(open_frames(spec["frames"]), clock)
    estimator = make_estimator("ours", camera)
    with ExitStack() as stack:
        instrumented(clock, stack)
        w0, c0 = time.perf_counter(), time.process_time()
        result = runner.run_frames(source, boxes, odometry, estimator, config)
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    n = result.frames
    # in threads of their own: decoding, and the overlay's drawing and encoding
    behind = ("decode", "overlay draw", "overlay encode") if args.ahead else ()
    main_thread = sum(v for k, v in clock.wall.items() if k not in behind)
    figures = {f"{k} wall": v / n * 1e3 for k, v in clock.wall.items()}
    figures |= {f"{k} cpu": v / n * 1e3 for k, v in clock.cpu.items()}
    figures |= {"other wall": (wall - main_thread) / n * 1e3}
    figures |= {"total wall": wall / n * 1e3, "total cpu": cpu / n * 1e3, "frames": n}
    print(json.dumps(figures))
    return 0


def run_configurations(
    inputs: list[RunInput], out: Path, repeats: int
) -> dict[tuple[str, int, int, bool], list[dict[str, float]]]:
    """Every configuration ``repeats`` times, alternating, each in a fresh process."""
    runs: dict[tuple[str, int, int, bool], list[dict[str, float]]] = defaultdict(list)
    configs = [
        (inp, cores, ahead, ov)
        for inp in inputs
        for cores, ahead in ((1, 0), (1, 4), (2, 4))
        for ov in (False, True)
    ]
    for _ in range(repeats):
        for inp, cores, ahead, overlay in configs:
            spec = {
                "camera": {
                    k: getattr(inp.camera, k)
                    for k in ("f", "c_x", "c_y", "height_m", "image_width", "image_height")
                },
                "frames": str(inp.frames),
                "boxes": str(inp.boxes),
                "overlay": overlay,
                "out": str(out / f"run_{inp.name}_{cores}_{ahead}_{int(overlay)}"),
            }
            command = [sys.executable, __file__, "--worker", json.dumps(spec)]
            done = subprocess.run(
                [*command, "--cores", str(cores), "--ahead", str(ahead)],
                capture_output=True,
                text=True,
                check=True,
            )
            runs[(inp.name, cores, ahead, overlay)].append(json.loads(done.stdout.splitlines()[-1]))
    return runs


def print_run_table(runs: dict[tuple[str, int, int, bool], list[dict[str, float]]]) -> None:
    columns = [*STAGES, "other", "total"]
    print("\nPart 1: slopedist run, method ours, built-in odometry; ms per frame, min / median")
    print(
        f"{'input':6s} {'cores':>5s} {'ahead':>5s} {'overlay':>7s} {'clock':>5s} "
        + " ".join(f"{c:>14s}" for c in columns)
    )
    for (name, cores, ahead, overlay), figures in runs.items():
        for clock in ("wall", "cpu"):
            cells = []
            for c in columns:
                values = [f.get(f"{c} {clock}", math.nan) for f in figures]
                if all(math.isnan(v) for v in values):
                    cells.append(f"{'-':>14s}")
                    continue
                cells.append(f"{min(values):6.2f} / {statistics.median(values):6.2f}")
            print(
                f"{name:6s} {cores:5d} {ahead:5d} {'yes' if overlay else 'no':>7s} {clock:>5s} "
                + " ".join(f"{c:>14s}" for c in cells)
            )
    print(
        "(stage cpu = processor time of the thread running the stage; total cpu = all threads; "
        "other = loop wall time outside the stages)"
    )


# ----------------------------------------------------------------------------- part 2
class NaiveOdometry:
    """Reference: corners on every frame, Lucas–Kanade into the next, essential matrix by
    RANSAC, ``recoverPose``; frame-to-frame rotations chained."""

    def __init__(self, camera: Camera) -> None:
        self.K = camera.K
        self.prev: Gray | None = None
        self.R = np.eye(3)
        self.clock = StageClock()

    def reset(self) -> None:
        self.prev, self.R = None, np.eye(3)

    def process(
        self, image_gray: Gray, timestamp_s: float, mask_boxes: NDArray[np.float64] | None = None
    ) -> OdometryResult:
        prev, self.prev = self.prev, image_gray
        if prev is None:
            return OdometryResult(self.R.copy(), OdometryState.OK)
        with self.clock.stage("corners"):
            p0 = cv2.goodFeaturesToTrack(prev, NAIVE_POINTS, 0.01, 10)
        if p0 is None or len(p0) < 8:
            return OdometryResult(None, OdometryState.LOST)
        with self.clock.stage("LK"):
            p1, status, _ = cv2.calcOpticalFlowPyrLK(prev, image_gray, p0, np.empty_like(p0))
        good = status.ravel() == 1
        a, b = p0[good].reshape(-1, 2), p1[good].reshape(-1, 2)
        if len(a) < 8:
            return OdometryResult(None, OdometryState.LOST)
        with self.clock.stage("essential"):
            E, mask = cv2.findEssentialMat(a, b, self.K, cv2.RANSAC, 0.999, 1.0)
            if E is None or E.shape != (3, 3):
                return OdometryResult(None, OdometryState.LOST)
            _, R_rel, _, _ = cv2.recoverPose(E, a, b, self.K, mask=mask)
        self.R = self.R @ np.asarray(R_rel).T  # X_cur = R_rel X_prev
        return OdometryResult(self.R.copy(), OdometryState.OK, int(np.sum(mask)))


@dataclass(frozen=True)
class OdometryInput:
    """Decoded grey frames with their camera and, where known, ground-truth rotations."""

    name: str
    camera: Camera
    frames: list[tuple[float, Gray]]
    truth: Any = None


def odometry_inputs(data: Path, run_inputs: list[RunInput]) -> list[OdometryInput]:
    """The two excerpts at their size and scaled to 1920 wide; ``kitti`` and ``1080p``."""
    found = []
    for folder in sorted((data / "kitti_odometry").iterdir()):
        seq = read_kitti_odometry(folder)
        frames = [(t, img) for _, t, img in seq.frames()]
        found.append(OdometryInput(folder.name[:7], seq.camera, frames, seq.ground_truth))
        width, height = frames[0][1].shape[1], frames[0][1].shape[0]
        s = HD[0] / width
        size = (HD[0], round(height * s))
        big = [
            (t, np.asarray(cv2.resize(img, size, interpolation=cv2.INTER_LINEAR), np.uint8))
            for t, img in frames
        ]
        cam = crop_camera(seq.camera, s, 0, size)
        found.append(OdometryInput(f"{folder.name[:7]}×{s:.2f}", cam, big, seq.ground_truth))
    for inp in run_inputs:
        frames = [
            (f.timestamp_s, np.asarray(cv2.cvtColor(f.image, cv2.COLOR_BGR2GRAY)))
            for f in open_frames(inp.frames)
            if f.image is not None
        ]
        found.append(OdometryInput(inp.name, inp.camera, frames))
    return found


def backends(camera: Camera) -> dict[str, RotationOdometry]:
    full = VisualOdometryConfig(max_width_px=None)
    return {
        "built-in": BuiltinVisualOdometry(camera),
        "built-in full": BuiltinVisualOdometry(camera, full),
        "naive": NaiveOdometry(camera),
    }


def one_run(odometry: RotationOdometry, frames: list[tuple[float, Gray]]) -> OdometryRun:
    from slopedist.odometry.accuracy import run_odometry

    return run_odometry(odometry, frames)


def one_core() -> None:
    """This process on its first allowed core, OpenCV with one thread."""
    cv2.setNumThreads(1)
    os.sched_setaffinity(0, set(sorted(os.sched_getaffinity(0))[:1]))


def accuracy(run: OdometryRun, truth: Any, full: OdometryRun) -> tuple[float, float, float]:
    """θ RMS and median one-second rotation error against ``truth`` (NaN without it), and θ
    RMS against the run ``full``, degrees."""
    theta = rel = math.nan
    if truth is not None:
        ev = OdometryEvaluation.from_run(run, truth)
        theta, rel = math.degrees(ev.theta_rms_rad), math.degrees(ev.rel_rot_median_rad)
    err = rotation_errors(run, full.track).theta_err_rad
    return theta, rel, math.degrees(float(np.sqrt(np.nanmean(err**2))))


def odometry_table(inputs: list[OdometryInput], repeats: int) -> None:
    one_core()
    print("\nPart 2: odometry alone, 1 core; ms per frame min / median; θ and rel in degrees")
    print(
        f"{'input':14s} {'size':>9s} {'backend':13s} {'ok':>6s} {'wall ms':>15s} "
        f"{'cpu ms':>15s} {'θ RMS':>7s} {'rel med':>7s} {'θ vs full':>9s} {'÷ naive':>15s}"
    )
    for inp in inputs:
        runs: dict[str, list[OdometryRun]] = defaultdict(list)
        naive_steps: list[StageClock] = []
        builtin_lk: list[StageClock] = []
        for _ in range(repeats):
            for name, backend in backends(inp.camera).items():
                if name == "built-in":
                    builtin_lk.append(StageClock())
                    flow = builtin_lk[-1].timed("LK", cv2.calcOpticalFlowPyrLK)
                    with mock.patch.object(cv2, "calcOpticalFlowPyrLK", flow):
                        runs[name].append(one_run(backend, inp.frames))
                else:
                    runs[name].append(one_run(backend, inp.frames))
                if isinstance(backend, NaiveOdometry):
                    naive_steps.append(backend.clock)
        full = runs["built-in full"][0]
        naive_wall = statistics.median(r.seconds for r in runs["naive"])
        naive_cpu = statistics.median(r.cpu_seconds for r in runs["naive"])
        for name, rs in runs.items():
            walls = [r.seconds / len(r) * 1e3 for r in rs]
            cpus = [r.cpu_seconds / len(r) * 1e3 for r in rs]
            theta, rel, vs_full = accuracy(rs[0], inp.truth, full)
            h, w = inp.frames[0][1].shape
            print(
                f"{inp.name:14s} {f'{w}×{h}':>9s} {name:13s} "
                f"{int(rs[0].valid.sum()):3d}/{len(rs[0]):<3d}"
                f"{min(walls):7.2f}/{statistics.median(walls):7.2f} "
                f"{min(cpus):7.2f}/{statistics.median(cpus):7.2f} "
                f"{theta:7.4f} {rel:7.4f} {vs_full:9.4f} "
                f"{statistics.median(r.seconds for r in rs) / naive_wall:7.3f}/"
                f"{statistics.median(r.cpu_seconds for r in rs) / naive_cpu:.3f}",
                flush=True,
            )
        print_lk_floor(naive_steps, builtin_lk, len(inp.frames), naive_cpu / len(inp.frames))


def print_lk_floor(
    naive: list[StageClock], builtin: list[StageClock], n_frames: int, naive_cpu_s: float
) -> None:
    """The naive reference's steps and the built-in's optical flow (median CPU ms per frame)
    against 1/8 of the naive reference: an odometry that tracks its points with pyramidal
    Lucas–Kanade cannot cost less than that one call."""

    def ms(clocks: list[StageClock], name: str) -> float:
        return statistics.median(c.cpu[name] for c in clocks) / n_frames * 1e3

    print(
        f"{'':24s} naive steps, cpu ms: "
        + ", ".join(f"{k} {ms(naive, k):.2f}" for k in ("corners", "LK", "essential"))
        + f"; built-in LK {ms(builtin, 'LK'):.2f}"
        + f"; 1/8 of the naive reference {naive_cpu_s * 1e3 / 8:.2f}",
        flush=True,
    )


Command = tuple[list[str], str]
"""A command line and the source tree it runs (``PYTHONPATH``)."""


def time_commands(commands: dict[str, Command], repeats: int, warm_up: bool) -> None:
    """Wall and processor time (the child's, all threads and processes) of each command, the
    commands alternating; with ``warm_up`` a first round (writing the bytecode cache under
    ``PYTHONPYCACHEPREFIX``) is not counted. Prints min / median in seconds."""
    import resource

    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPYCACHEPREFIX"] = "/tmp/pyc_realtime_bench"
    times: dict[str, list[tuple[float, float]]] = defaultdict(list)
    for k in range(repeats + int(warm_up)):
        for name, (command, tree) in commands.items():
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            w0 = time.perf_counter()
            subprocess.run(command, env=env | {"PYTHONPATH": tree}, check=True, capture_output=True)
            wall = time.perf_counter() - w0
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
            if k or not warm_up:
                times[name].append((wall, cpu))
    for name, values in times.items():
        walls, cpus = [v[0] for v in values], [v[1] for v in values]
        print(
            f"  {name:22s} wall {min(walls):7.3f} / {statistics.median(walls):7.3f}   "
            f"cpu {min(cpus):7.3f} / {statistics.median(cpus):7.3f}",
            flush=True,
        )


def startup_times(repeats: int, compare_src: Path | None) -> None:
    """``python -m slopedist --help`` with a warm bytecode cache, against a bare interpreter
    (and the source tree ``compare_src``)."""
    here = str(REPO / "src")
    commands: dict[str, Command] = {"bare python": ([sys.executable, "-c", "pass"], here)}
    trees = {"this tree": here} | ({"compare": str(compare_src)} if compare_src else {})
    for name, tree in trees.items():
        commands[name] = ([sys.executable, "-m", "slopedist", "--help"], tree)
    print("\nStart-up: `python -m slopedist --help`, seconds, min / median")
    time_commands(commands, repeats, warm_up=True)


def demo_times(repeats: int, out: Path, compare_src: Path | None) -> None:
    """``slopedist demo`` (the whole suite, quiet) with the default jobs and with ``--jobs 1``
    (and from the source tree ``compare_src``)."""
    here = str(REPO / "src")
    demo = [sys.executable, "-m", "slopedist", "demo", "--quiet", "--out"]
    commands: dict[str, Command] = {
        "demo (jobs: cores)": ([*demo, str(out / "demo_jobs")], here),
        "demo --jobs 1": ([*demo, str(out / "demo_1"), "--jobs", "1"], here),
    }
    if compare_src is not None:
        commands["demo (compare)"] = ([*demo, str(out / "demo_compare")], str(compare_src))
    print("\nslopedist demo, seconds, min / median")
    time_commands(commands, repeats, warm_up=False)


SWEEP_WIDTHS = (960, 1280, 1600, None)


def width_sweep(inputs: list[OdometryInput]) -> None:
    """Accuracy and processor time of the built-in odometry per working width (``max_width_px``)
    on the inputs wider than 1280 px."""
    one_core()
    print("\nWorking width of the built-in odometry (1 core; θ, rel in degrees; one run)")
    print(
        f"{'input':14s} {'size':>9s} {'max width':>9s} {'ok':>6s} {'cpu ms':>7s} "
        f"{'θ RMS':>7s} {'rel med':>7s} {'θ vs full':>9s}"
    )
    for inp in inputs:
        h, w = inp.frames[0][1].shape
        if w <= 1280:
            continue
        full: OdometryRun | None = None
        for width in reversed(SWEEP_WIDTHS):  # None (full resolution) first
            config = VisualOdometryConfig(max_width_px=width)
            run = one_run(BuiltinVisualOdometry(inp.camera, config), inp.frames)
            full = full or run
            theta, rel, vs_full = accuracy(run, inp.truth, full)
            print(
                f"{inp.name:14s} {f'{w}×{h}':>9s} {width!s:>9s} "
                f"{int(run.valid.sum()):3d}/{len(run):<3d}"
                f"{run.cpu_seconds / len(run) * 1e3:7.2f} {theta:7.4f} {rel:7.4f} "
                f"{vs_full:9.4f}",
                flush=True,
            )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--out", type=Path, default=REPO / "bench_out" / "realtime")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--part",
        choices=("run", "odometry", "widths", "startup", "demo", "all"),
        default="all",
    )
    parser.add_argument(
        "--compare-src", type=Path, help="another source tree for the start-up comparison"
    )
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--cores", type=int, default=1, help=argparse.SUPPRESS)
    parser.add_argument("--ahead", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        return worker(args)
    if args.part in ("startup", "all"):
        startup_times(max(args.repeats, 5), args.compare_src)
    if args.part in ("demo", "all"):
        demo_times(args.repeats, args.out, args.compare_src)
    if args.part in ("startup", "demo"):
        return 0
    if not (args.data / "kitti_raw_lead").is_dir():
        print(f"shared data not found under {args.data}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    inputs = make_run_inputs(args.data, args.out)
    print(
        f"OpenCV {cv2.__version__}, {os.cpu_count()} cores; load average "
        f"{', '.join(f'{v:.1f}' for v in os.getloadavg())}"
    )
    if args.part in ("run", "all"):
        print_run_table(run_configurations(inputs, args.out, args.repeats))
    if args.part in ("odometry", "widths", "all"):
        odometry = odometry_inputs(args.data, inputs)
        if args.part != "widths":
            odometry_table(odometry, args.repeats)
        if args.part != "odometry":
            width_sweep(odometry)
    print(f"load average after: {', '.join(f'{v:.1f}' for v in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
