"""ORB-SLAM3 (optional backend) beside the built-in visual odometry on KITTI odometry excerpts.

For each sequence folder (``image_l/``, ``poses.txt``, ``calib.txt``) and each backend, every frame
is fed in order (timestamps k × 0.1 s) and compared with the ground-truth poses:

- ``theta_rms_deg``: RMS error of the ego gradient θ (eq. 4, θ0 = 0) between frame k and k − 10,
  over the k where the backend has both rotations;
- ``rel_rot_median_deg``: median angle of the rotation error over the same 10-frame windows;
- ``windows``: how many of the sequence's 10-frame windows the backend covers;
- ``ms_per_frame``: the backend's own time per frame after decoding (for ORB-SLAM3 the track
  call, without its real-time pacing; its mapping thread runs beside it).

ORB-SLAM3 needs ``pyorbslam3`` and a vocabulary: ``--vocab PATH`` or ``$PYORBSLAM3_VOCAB``, or
``--train-vocab`` to train one (DBoW2 text, k = 10, 6 levels) from the benchmark's own frames
(about 40 s) into ``--out``.

Usage::

    python benchmarks/orbslam3_vs_builtin.py [--data ../shared/data/kitti_odometry]
        [--vocab voc.txt | --train-vocab] [--out bench_out/orbslam3]
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from slopedist.core import geometry as geo
from slopedist.core.camera import Camera
from slopedist.core.errors import SlopedistError
from slopedist.odometry.orb_vocabulary import images_in, train_from_images
from slopedist.odometry.posefiles import read_kitti_poses
from slopedist.streaming.pipeline import build_odometry

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "kitti_odometry"
WINDOW = 10
PERIOD_S = 0.1


@contextlib.contextmanager
def c_stdout_to_stderr() -> Iterator[None]:
    """Send what C++ code prints on standard output (ORB-SLAM3's log) to standard error."""
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def evaluate(seq: Path, backend: str, vocab: Path | None) -> dict[str, float]:
    camera = Camera.from_kitti_calib(seq / "calib.txt")
    gt = read_kitti_poses(seq / "poses.txt").R_world_cam
    odo = build_odometry(backend, camera, vocab)
    files = sorted((seq / "image_l").glob("*.png"))
    R: list[np.ndarray | None] = []
    times = []
    for k, path in enumerate(files):
        image = np.asarray(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), np.uint8)
        t0 = time.perf_counter()
        res = odo.process(image, k * PERIOD_S)
        times.append(getattr(odo, "last_track_ms", (time.perf_counter() - t0) * 1e3))
        R.append(res.R_world_cam)
    if hasattr(odo, "close"):
        odo.close()
    pairs = [(k - WINDOW, k) for k in range(WINDOW, len(files))]
    ok = [(a, b) for a, b in pairs if R[a] is not None and R[b] is not None]
    theta_err, rel_err = [], []
    for a, b in ok:
        Ra, Rb = R[a], R[b]
        assert Ra is not None and Rb is not None
        theta_err.append(float(geo.ego_road_gradient(Ra, Rb) - geo.ego_road_gradient(gt[a], gt[b])))
        err = (Ra.T @ Rb).T @ (gt[a].T @ gt[b])
        rel_err.append(float(geo.rotation_angle_rad(err)))
    return {
        "frames": len(files),
        "windows": len(ok),
        "windows_total": len(pairs),
        "theta_rms_deg": math.degrees(math.sqrt(np.mean(np.square(theta_err))))
        if theta_err
        else math.nan,
        "rel_rot_median_deg": math.degrees(float(np.median(rel_err))) if rel_err else math.nan,
        "ms_per_frame": float(np.mean(times)),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--vocab", type=Path, default=None)
    parser.add_argument("--train-vocab", action="store_true")
    parser.add_argument("--out", type=Path, default=REPO / "bench_out" / "orbslam3")
    parser.add_argument(
        "--runs",
        type=int,
        default=1,
        help="ORB-SLAM3 runs per sequence (it is multi-threaded and not deterministic)",
    )
    args = parser.parse_args(argv)
    seqs = (
        sorted(p for p in args.data.iterdir() if (p / "poses.txt").is_file())
        if args.data.is_dir()
        else []
    )
    if not seqs:
        print(f"no KITTI odometry sequences under {args.data}", file=sys.stderr)
        return 2
    vocab = args.vocab
    if args.train_vocab:
        t0 = time.perf_counter()
        folders = [s / "image_l" for s in seqs]
        raw = args.data.parent / "kitti_raw_lead" / "image_02"
        if raw.is_dir():
            folders.append(raw)
        vocab = train_from_images(images_in(folders), args.out / "orb_vocabulary.txt", 10, 6)
        print(
            f"trained {vocab} from {len(folders)} folders in {time.perf_counter() - t0:.0f} s",
            file=sys.stderr,
        )
    backends = ["builtin", "orbslam3"]
    print(
        f"{'sequence':18s} {'backend':9s} {'run':>3s} {'windows':>8s} {'θ RMS °':>8s} "
        f"{'rel med °':>9s} {'ms/frame':>9s}"
    )
    for seq in seqs:
        for backend in backends:
            for run in range(args.runs if backend == "orbslam3" else 1):
                try:
                    with c_stdout_to_stderr():
                        r = evaluate(seq, backend, vocab if backend == "orbslam3" else None)
                except SlopedistError as exc:
                    print(f"{seq.name:18s} {backend:9s} unavailable: {exc}")
                    break
                print(
                    f"{seq.name:18s} {backend:9s} {run + 1:3d} "
                    f"{r['windows']:4d}/{r['windows_total']:<3d} {r['theta_rms_deg']:8.3f} "
                    f"{r['rel_rot_median_deg']:9.3f} {r['ms_per_frame']:9.1f}",
                    flush=True,
                )
    if vocab is None and not os.environ.get("PYORBSLAM3_VOCAB"):
        print("(ORB-SLAM3 rows need --vocab, $PYORBSLAM3_VOCAB or --train-vocab)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
