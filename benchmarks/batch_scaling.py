"""Throughput of ``slopedist batch`` on Ray against the same drives run one after another.

Drives: ``--drives`` short synthetic scenarios (``slopedist simulate``, ``--frames`` frames
each, built-in visual odometry, method ``paper``), rendered once into ``--out``. Timed, each on
the same drives with the outputs written as a batch writes them:

1. sequential: :func:`slopedist.batch.drive.process_drive` on every drive in this process, one
   after another (no Ray);
2. Ray with 1 and with 2 CPUs (an embedded instance; its start-up is timed apart):
   :func:`~slopedist.batch.engine.run_batch` with ``force`` (every drive runs) twice, the first
   with cold workers (each new worker process imports slopedist), the second timed;
3. with ``--two-node``: a two-node Ray cluster on this machine over loopback (``ray start
   --head --num-cpus 1`` and a second ``ray start --address 127.0.0.1:PORT --num-cpus 1``,
   both started here with ``--block`` and stopped by killing their process groups), the same
   batch through ``address`` (one run, cold workers).

Prints frames per second (wall clock of the whole batch), the speed-up over sequential, the CPU
time per frame (user + system, this process for sequential, the workers' for Ray: the cost that
does not depend on how busy a shared machine is), Ray's per-drive overhead (the warm 1-CPU batch
wall time minus the time spent inside the drives' tasks, per drive), the extra time of cold
workers and the round trip of an empty task. Usage::

    python benchmarks/batch_scaling.py [--drives 6] [--frames 40] [--two-node]
        [--out bench_out/batch_scaling]
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from slopedist.batch import BatchOptions, load_drives, run_batch
from slopedist.batch.drive import process_drive
from slopedist.batch.manifest import DriveSpec
from slopedist.batch.stamp import input_stamp
from slopedist.cli import main as slopedist_main

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = ("ego_crest", "ego_sag", "same_downhill", "same_flat", "curve_flat", "bumps_and_curves")
HEAD_PORT = 6391


def make_drives(root: Path, n: int, frames: int) -> list[DriveSpec]:
    """``n`` simulated drives of ``frames`` frames and their manifest (reused when present)."""
    rows = [["drive", "frames", "calib", "boxes", "method", "timestamps"]]
    for i in range(n):
        scenario = SCENARIOS[i % len(SCENARIOS)]
        name = f"{scenario}_{i}"
        sim = root / "drives" / name
        if not (sim / "times.txt").is_file():
            shutil.rmtree(sim, ignore_errors=True)
            args = ["simulate", scenario, "--out", str(sim), "--frames", str(frames)]
            assert slopedist_main([*args, "--depth", "none"]) == 0
        files = [f"drives/{name}/{f}" for f in ("image_02", "calib.txt", "boxes.csv")]
        rows.append([name, *files, "paper", f"drives/{name}/times.txt"])
    manifest = root / "drives.csv"
    with manifest.open("w", newline="") as fh:
        csv.writer(fh).writerows(rows)
    return load_drives(manifest)


def sequential(drives: list[DriveSpec], out: Path) -> dict[str, float]:
    """Wall time (s), CPU time (s) and frames of the drives run one after another here."""
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    start, cpu, frames = time.perf_counter(), time.process_time(), 0
    for spec in drives:
        outcome = process_drive(spec, out, input_stamp(spec))
        assert outcome.error == "", outcome.error
        frames += outcome.frames
    seconds = time.perf_counter() - start
    return {"seconds": seconds, "cpu_s": time.process_time() - cpu, "frames": frames}


def batch_time(drives: list[DriveSpec], out: Path, address: str | None = None) -> dict[str, float]:
    """Wall time (s), the drives' CPU time in the workers (s) and frames of one forced batch
    on the running (or given) Ray."""
    start = time.perf_counter()
    options = BatchOptions(address=address, force=True, progress=False, parquet=False)
    result = run_batch(drives, out, options)
    assert all(o.error == "" for o in result.outcomes), result.outcomes
    seconds = time.perf_counter() - start
    cpu = sum(o.cpu_seconds for o in result.outcomes)
    inside = sum(o.seconds for o in result.outcomes)
    return {"seconds": seconds, "cpu_s": cpu, "inside_s": inside, "frames": result.frames_run}


def empty_task_s(ray: Any, n: int = 200) -> float:
    """Mean round trip of an empty task (submitted in bulk), seconds."""

    @ray.remote(num_cpus=1)
    def nothing() -> None:
        return None

    ray.get(nothing.remote())  # a warm worker
    start = time.perf_counter()
    ray.get([nothing.remote() for _ in range(n)])
    return (time.perf_counter() - start) / n


def on_embedded_ray(cpus: int, drives: list[DriveSpec], out: Path) -> dict[str, float]:
    import ray

    start = time.perf_counter()
    ray.init(address="local", num_cpus=cpus, include_dashboard=False, log_to_driver=False)
    startup = time.perf_counter() - start
    try:
        cold = batch_time(drives, out)["seconds"]  # new worker processes import slopedist first
        timed = batch_time(drives, out)
        task = empty_task_s(ray)
    finally:
        ray.shutdown()
    return {"startup_s": startup, "cold_s": cold, "task_s": task, **timed}


def two_node(drives: list[DriveSpec], out: Path) -> dict[str, float]:
    """The batch on a head + worker cluster over loopback, 1 CPU each."""
    ray_bin = str(Path(sys.executable).with_name("ray"))
    common = ["--num-cpus", "1", "--block", "--disable-usage-stats"]
    head_cmd = [ray_bin, "start", "--head", "--port", str(HEAD_PORT), "--node-ip-address"]
    head = subprocess.Popen(
        [*head_cmd, "127.0.0.1", "--include-dashboard", "false", *common],
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    worker = None
    address = f"127.0.0.1:{HEAD_PORT}"
    try:
        time.sleep(8)
        worker = subprocess.Popen(
            [ray_bin, "start", "--address", address, "--node-ip-address", "127.0.0.1", *common],
            start_new_session=True,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        time.sleep(8)
        timed = batch_time(drives, out, address)
    finally:
        for proc in (worker, head):
            if proc is not None:
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait(timeout=60)
        current = Path(tempfile.gettempdir()) / "ray" / "ray_current_cluster"
        if current.is_file() and current.read_text().strip().endswith(f":{HEAD_PORT}"):
            current.unlink()  # the address `ray stop` would have removed
    return timed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drives", type=int, default=6)
    parser.add_argument("--frames", type=int, default=40, help="frames per drive")
    parser.add_argument("--two-node", action="store_true", help="also a 2-node loopback cluster")
    parser.add_argument("--out", type=Path, default=REPO / "bench_out" / "batch_scaling")
    args = parser.parse_args(argv)
    drives = make_drives(args.out, args.drives, args.frames)
    print(f"{len(drives)} drives x {args.frames} frames (method paper, built-in odometry)")
    print(f"load average before: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    seq = sequential(drives, args.out / "out_seq")
    rows = [("sequential, 1 process", seq, "")]
    ray_runs = {cpus: on_embedded_ray(cpus, drives, args.out / f"out_ray{cpus}") for cpus in (1, 2)}
    for cpus, r in ray_runs.items():
        note = f"start {r['startup_s']:.1f} s, cold batch {r['cold_s']:.1f} s"
        rows.append((f"Ray, {cpus} CPU{'s' if cpus > 1 else ''}", r, note))
    if args.two_node:
        rows.append(("Ray, 2 nodes x 1 CPU (loopback)", two_node(drives, args.out / "two"), ""))
    print(f"{'run':32s} {'wall s':>7s} {'frames/s':>9s} {'speed-up':>9s} {'CPU ms/frame':>13s}")
    for name, r, note in rows:
        print(
            f"{name:32s} {r['seconds']:7.1f} {r['frames'] / r['seconds']:9.2f} "
            f"{seq['seconds'] / r['seconds']:8.2f}x {1e3 * r['cpu_s'] / r['frames']:13.1f}  {note}"
        )
    one = ray_runs[1]
    overhead = (one["seconds"] - one["inside_s"]) / len(drives)
    cold = (one["cold_s"] - one["seconds"]) / len(drives)
    print(
        f"Ray per-drive overhead: {overhead:.3f} s (1-CPU batch wall time minus the time inside "
        f"the drives' tasks, per drive); cold workers added {cold:.2f} s per drive to the first "
        f"batch; an empty task's round trip: {one['task_s'] * 1e3:.2f} ms"
    )
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
