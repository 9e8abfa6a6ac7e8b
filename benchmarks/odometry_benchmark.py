"""Accuracy, speed and memory of the built-in visual odometry on the KITTI odometry excerpts.

Prints, for each sequence folder under ``--data`` (``image_l/``, ``poses.txt``, ``calib.txt``):

- ``θ RMS``: RMS error of the ego gradient θ (eq. 2–4, θ0 = 0, look-back 1 s = 10 frames) from the
  estimated rotations against θ from the ground-truth rotations of the same frame pairs, over
  every frame (frames younger than 1 s look back to frame 0, as in the pipeline) and over full
  windows only (k ≥ 10);
- ``rel med``: median angle of the rotation error over the 10-frame windows;
- ``ms/frame``: time inside ``process`` per frame after decoding (frames are decoded beforehand),
  OpenCV limited to one thread (``cv2.setNumThreads(1)``); wall clock, best of ``--repeats``
  runs (the machine is shared), and processor time;

then a long run of ``--long`` frames (default 10 000) on the 1241×376 sequence, the frames played
forward and backward in a loop (0…50, 49…1, 0…50, …: continuous motion, timestamps increasing),
with the resident memory at 1k/2k/5k/10k frames, the frame states, θ and relative-rotation errors
against the ground truth of the frames shown, and the time per frame.

Usage::

    python benchmarks/odometry_benchmark.py [--data ../shared/data/kitti_odometry]
        [--repeats 3] [--long 10000]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from memory import peak_rss_mb, rss_mb  # benchmarks/memory.py, beside this script
from numpy.typing import NDArray

from slopedist.io.kitti.odometry import KittiOdometrySequence, read_kitti_odometry
from slopedist.odometry.accuracy import (
    OdometryEvaluation,
    OdometryRun,
    rotation_errors,
    run_odometry,
)
from slopedist.odometry.base import OdometryState, RotationTrack
from slopedist.odometry.visual import BuiltinVisualOdometry

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "kitti_odometry"
TARGETS = {"seq06_000-050": 0.05, "unknown_000-050": 0.12}
REL_TARGET_DEG = 0.15
MS_TARGET = 10.0


def load(seq: KittiOdometrySequence) -> list[tuple[float, NDArray[np.uint8]]]:
    return [(t, image) for _, t, image in seq.frames()]


def accuracy_row(seq: KittiOdometrySequence, runs: list[OdometryRun]) -> str:
    assert seq.ground_truth is not None
    run = runs[0]
    figures = OdometryEvaluation.from_run(run, seq.ground_truth)
    errors = rotation_errors(run, seq.ground_truth)
    full = np.isfinite(errors.rel_err_rad)
    theta_full = math.degrees(float(np.sqrt(np.mean(errors.theta_err_rad[full] ** 2))))
    wall = min(r.seconds for r in runs) / len(run) * 1e3
    cpu = min(r.cpu_seconds for r in runs) / len(run) * 1e3
    theta = math.degrees(figures.theta_rms_rad)
    rel = math.degrees(figures.rel_rot_median_rad)
    target = TARGETS.get(seq.root.name)
    verdict = [
        f"θ {'ok' if target is not None and theta <= target else 'MISS'} (≤ {target})"
        if target is not None
        else "",
        f"rel {'ok' if rel <= REL_TARGET_DEG else 'MISS'} (≤ {REL_TARGET_DEG})",
        f"time {'ok' if wall <= MS_TARGET else 'MISS'} (≤ {MS_TARGET:.0f} ms)",
    ]
    size = f"{seq.camera.image_width}×{seq.camera.image_height}"
    return (
        f"{seq.root.name:16s} {size:9s} {figures.frames_ok:3d}/{figures.frames:<3d} "
        f"{theta:8.4f} {theta_full:9.4f} {rel:8.4f} {wall:9.2f} {cpu:8.2f}   "
        + ", ".join(v for v in verdict if v)
    )


def ping_pong(n_frames: int, n: int) -> list[int]:
    """Frame indices 0…n−1, n−2…1, 0…: ``n_frames`` of them."""
    cycle = list(range(n)) + list(range(n - 2, 0, -1))
    return [cycle[k % len(cycle)] for k in range(n_frames)]


def long_run(
    seq: KittiOdometrySequence, frames: list[tuple[float, NDArray[np.uint8]]], n_frames: int
) -> None:
    assert seq.ground_truth is not None
    order = ping_pong(n_frames, len(frames))
    vo = BuiltinVisualOdometry(seq.camera)
    checkpoints = {1000, 2000, 5000, 10000, n_frames}
    rotations = np.empty((n_frames, 3, 3))
    valid = np.zeros(n_frames, dtype=bool)
    segment = np.zeros(n_frames, dtype=np.int64)
    states = {s: 0 for s in OdometryState}
    seconds = cpu = 0.0
    print(
        f"\nlong run: {n_frames} frames of {seq.root.name} played forward and backward "
        f"({seq.camera.image_width}×{seq.camera.image_height})"
    )
    print(
        f"  {'frames':>6s} {'RSS MB':>7s} {'peak MB':>8s} {'history':>8s} {'tracks':>7s} "
        f"{'ms/frame':>9s} {'CPU ms':>7s}   (times: mean so far)"
    )
    for k, idx in enumerate(order):
        image = frames[idx][1]
        t0, c0 = time.perf_counter(), time.process_time()
        result = vo.process(image, k * 0.1)
        seconds += time.perf_counter() - t0
        cpu += time.process_time() - c0
        states[result.state] += 1
        valid[k] = result.state is OdometryState.OK
        rotations[k] = result.R_world_cam if result.R_world_cam is not None else np.eye(3)
        segment[k] = result.segment
        if k + 1 in checkpoints:
            print(
                f"  {k + 1:6d} {rss_mb():7.1f} {peak_rss_mb():8.1f} {vo.history_frames:8d} "
                f"{len(vo.tracks):7d} {seconds / (k + 1) * 1e3:9.2f} {cpu / (k + 1) * 1e3:7.2f}",
                flush=True,
            )
    truth = RotationTrack.from_arrays(
        np.arange(n_frames) * 0.1, seq.ground_truth.R_world_cam[order]
    )
    run = OdometryRun(np.arange(n_frames) * 0.1, rotations, valid, segment, seconds, cpu)
    figures = OdometryEvaluation.from_run(run, truth)
    print(
        "  states: "
        + ", ".join(f"{s.value} {n}" for s, n in states.items())
        + f"; segments: {int(segment.max()) + 1}"
    )
    print(
        f"  θ RMS {math.degrees(figures.theta_rms_rad):.4f}°, rel-rot median "
        f"{math.degrees(figures.rel_rot_median_rad):.4f}°, "
        f"{seconds / n_frames * 1e3:.2f} ms/frame wall, {cpu / n_frames * 1e3:.2f} ms/frame CPU"
    )


def sequence_folders(data: Path) -> list[Path]:
    """KITTI odometry sequence folders (with ``poses.txt``) under ``data``, sorted; prints a
    message to stderr when there is none."""
    folders = (
        sorted(p for p in data.iterdir() if (p / "poses.txt").is_file()) if data.is_dir() else []
    )
    if not folders:
        print(f"no KITTI odometry sequences under {data}", file=sys.stderr)
    return folders


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument(
        "--repeats", type=int, default=3, help="timing runs per sequence (the best is reported)"
    )
    parser.add_argument(
        "--long", type=int, default=10000, help="frames of the memory run (0: skip)"
    )
    args = parser.parse_args(argv)
    folders = sequence_folders(args.data)
    if not folders:
        return 2
    cv2.setNumThreads(1)
    print(
        f"built-in visual odometry, OpenCV {cv2.__version__} with 1 thread "
        f"(cv2.getNumThreads() = {cv2.getNumThreads()})"
    )
    print(
        f"{'sequence':16s} {'size':9s} {'ok':>7s} {'θ RMS °':>8s} {'θ k≥10 °':>9s} "
        f"{'rel med°':>8s} {'ms/frame':>9s} {'CPU ms':>8s}"
    )
    sequences = []
    for folder in folders:
        seq = read_kitti_odometry(folder)
        frames = load(seq)
        runs = [
            run_odometry(BuiltinVisualOdometry(seq.camera), frames)
            for _ in range(max(args.repeats, 1))
        ]
        print(accuracy_row(seq, runs), flush=True)
        sequences.append((seq, frames))
    if args.long > 0:
        seq, frames = max(sequences, key=lambda s: s[0].camera.image_width or 0)
        long_run(seq, frames, args.long)
    return 0


if __name__ == "__main__":
    sys.exit(main())
