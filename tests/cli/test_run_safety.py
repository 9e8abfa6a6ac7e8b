"""``slopedist run`` and ``estimate`` under kills, full disks, outputs that would overwrite
their inputs and closed pipes: what stays on disk is valid and says how far it got."""

from __future__ import annotations

import csv
import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

import slopedist
from slopedist.cli import main
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.writers import write_box_csv

W, H = 320, 200
CALIB = "P2: 500 0 160 0 0 500 100 0 0 0 1 0\n"
SRC = str(Path(slopedist.__file__).resolve().parents[1])


def make_inputs(tmp_path: Path, n: int) -> list[str]:
    """``n`` noisy frames (so the odometry has work to do), one box per frame."""
    frames = tmp_path / "frames"
    frames.mkdir()
    rng = np.random.default_rng(0)
    base = rng.integers(0, 255, (H + 40, W + 40, 3), dtype=np.uint8)
    for k in range(n):
        cv2.imwrite(str(frames / f"{k:06d}.png"), base[k % 40 : k % 40 + H, :W])
    (tmp_path / "calib.txt").write_text(CALIB)
    boxes = BoxTable.build(np.arange(n), np.tile((100.0, 110.0, 150.0, 150.0), (n, 1)))
    write_box_csv(boxes, tmp_path / "boxes.csv")
    return [str(frames), "--calib", str(tmp_path / "calib.txt"), "--boxes",
            str(tmp_path / "boxes.csv"), "--quiet", "--method", "ego",
            "--columns", "all"]  # fmt: skip


def read_rows(path: Path) -> list[dict[str, str]]:
    text = path.read_text(encoding="utf-8")
    assert text.endswith("\n"), f"{path} ends mid-row"
    rows = list(csv.DictReader(text.splitlines()))
    header = text.splitlines()[0].split(",")
    assert all(len(r) == len(header) and None not in r.values() for r in rows)
    return rows


def start_run(args: list[str]) -> subprocess.Popen[bytes]:
    env = {**os.environ, "PYTHONPATH": SRC}
    return subprocess.Popen(
        [sys.executable, "-m", "slopedist", "run", *args],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )


def wait_for_rows(path: Path, n: int, proc: subprocess.Popen[bytes], limit_s: float = 60) -> None:
    t0 = time.monotonic()
    while time.monotonic() - t0 < limit_s:
        if path.exists() and path.read_text(encoding="utf-8").count("\n") > n:
            return
        if proc.poll() is not None:
            pytest.fail(f"run ended before {n} rows: {proc.stderr.read().decode()}")  # type: ignore[union-attr]
        time.sleep(0.01)
    proc.kill()
    pytest.fail("run too slow")


def test_sigterm_part_way_writes_run_json_and_exits_143(tmp_path: Path) -> None:
    args = make_inputs(tmp_path, 400)
    out = tmp_path / "out"
    proc = start_run([*args, "--out", str(out)])
    wait_for_rows(out / "records.partial.csv", 10, proc)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, err.decode()
    assert "stopped by SIGTERM" in err.decode()
    summary = json.loads((out / "run.json").read_text())
    rows = read_rows(out / "records.csv")
    frames = read_rows(out / "frames.csv")
    assert summary["complete"] is False and "SIGTERM" in summary["error"]
    last = summary["last_complete_frame"]
    assert 9 <= last < 399  # rows of frames 0..9 were seen before the signal
    assert summary["frames"] == len(frames) == last + 1
    assert [int(r["frame"]) for r in rows] == list(range(last + 1))  # whole frames only
    assert not list(out.glob("*.partial*"))


def test_sigkill_leaves_the_previous_run_whole_and_marks_the_new_one_partial(
    tmp_path: Path,
) -> None:
    args = make_inputs(tmp_path, 400)
    out = tmp_path / "out"
    first = tmp_path / "first"
    assert main(["run", *args, "--out", str(out), "--odometry", "none", "--method", "flat"]) == 0
    shutil.copytree(out, first)
    proc = start_run([*args, "--out", str(out)])
    wait_for_rows(out / "records.partial.csv", 10, proc)
    proc.kill()
    proc.wait(timeout=30)
    for name in ("records.csv", "frames.csv", "run.json"):  # the previous run, untouched
        assert (out / name).read_bytes() == (first / name).read_bytes()
    assert json.loads((out / "run.json").read_text())["complete"] is True
    partial = read_rows(out / "records.partial.csv")  # the new one: marked, whole rows
    assert len(partial) >= 10 and {r["method"] for r in partial} == {"ego"}


def test_a_rerun_replaces_every_file_of_the_previous_run(tmp_path: Path) -> None:
    args = make_inputs(tmp_path, 6)
    out = tmp_path / "out"
    assert main(["run", *args, "--out", str(out), "--odometry", "none", "--method", "flat"]) == 0
    assert main(["run", *args, "--out", str(out), "--odometry", "none", "--method", "flat",
                 "--sequence", "second"]) == 0  # fmt: skip
    assert json.loads((out / "run.json").read_text())["sequence"] == "second"
    assert len(read_rows(out / "records.csv")) == 6
    assert sorted(p.name for p in out.iterdir()) == [
        "frames.csv",
        "records.csv",
        "run.json",
        "tracks.csv",
    ]


def test_a_rerun_removes_the_overlay_exports_and_snapshots_it_does_not_write(
    tmp_path: Path,
) -> None:
    """An earlier run's overlay, exports and snapshots would no longer match the records: a
    rerun into the same folder without them removes them, but never an input of its own."""
    args = make_inputs(tmp_path, 4)
    out = tmp_path / "out"
    first = ["--overlay", "--overlay-format", "png", "--export", "tum", "--export", "mcap"]
    assert (
        main(["run", *args, "--out", str(out), *first, "--snapshot", "1", "--snapshot", "2"]) == 0
    )
    assert {"overlay", "trajectory.tum", "run.mcap", "snapshot_000001.jpg"} <= {
        p.name for p in out.iterdir()
    }
    assert main(["run", *args, "--out", str(out), "--method", "flat", "--snapshot", "2"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "frames.csv",
        "records.csv",
        "run.json",
        "snapshot_000002.jpg",
        "tracks.csv",
    ]
    shutil.copy(tmp_path / "calib.txt", out / "trajectory.tum")  # an input named like an export
    calib = ["--calib", str(out / "trajectory.tum")]
    assert main(["run", *args, *calib, "--out", str(out), "--method", "flat"]) == 0
    assert (out / "trajectory.tum").read_text() == CALIB
    assert not (out / "snapshot_000002.jpg").exists()
    (out / "overlay").mkdir()  # a folder named like the PNG overlay that holds an input
    shutil.copy(tmp_path / "calib.txt", out / "overlay" / "calib.txt")
    calib = ["--calib", str(out / "overlay" / "calib.txt")]
    assert main(["run", *args, *calib, "--out", str(out), "--method", "flat"]) == 0
    assert (out / "overlay" / "calib.txt").read_text() == CALIB


def test_outputs_that_would_overwrite_an_input_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = make_inputs(tmp_path, 3)
    before = (tmp_path / "boxes.csv").read_bytes()
    assert main(["run", *args, "--out", args[0], "--odometry", "none"]) == 2
    assert "would be overwritten" in capsys.readouterr().err
    (tmp_path / "o").mkdir()
    shutil.copy(tmp_path / "boxes.csv", tmp_path / "o" / "records.csv")
    args[4] = str(tmp_path / "o" / "records.csv")
    assert main(["run", *args, "--out", str(tmp_path / "o"), "--odometry", "none"]) == 2
    assert "would be overwritten" in capsys.readouterr().err
    assert (tmp_path / "o" / "records.csv").read_bytes() == before
    assert not (tmp_path / "o" / "run.json").exists()


def _estimate_args(tmp_path: Path) -> list[str]:
    (tmp_path / "calib.txt").write_text("P2: 721 0 609 0 0 721 172 0 0 0 1 0\n")
    (tmp_path / "poses.txt").write_text(
        "".join(f"1 0 0 0 0 1 0 0 0 0 1 {k:.1f}\n" for k in range(50))
    )
    rows = "".join(f"{k},500,180,600,250,7\n{k},700,180,760,240,8\n" for k in range(50))
    (tmp_path / "b.csv").write_text("frame,left,top,right,bottom,track_id\n" + rows)
    return [
        "estimate",
        "--calib",
        str(tmp_path / "calib.txt"),
        "--poses",
        str(tmp_path / "poses.txt"),
        "--boxes",
        str(tmp_path / "b.csv"),
        "--method",
        "flat",
    ]


def test_estimate_refuses_to_overwrite_its_boxes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = _estimate_args(tmp_path)
    before = (tmp_path / "b.csv").read_bytes()
    assert main([*args, "--out", str(tmp_path / "b.csv")]) == 2
    assert "would be overwritten" in capsys.readouterr().err
    assert (tmp_path / "b.csv").read_bytes() == before


def test_estimate_into_a_closed_pipe_exits_quietly(tmp_path: Path) -> None:
    args = _estimate_args(tmp_path)
    env = {**os.environ, "PYTHONPATH": SRC}
    cmd = " ".join([sys.executable, "-m", "slopedist", *args, "| head -1"])
    res = subprocess.run(
        ["bash", "-o", "pipefail", "-c", cmd], env=env, capture_output=True, timeout=120
    )
    assert res.stdout.decode().startswith("frame,timestamp_s")
    assert res.stderr.decode() == "" and res.returncode == 0


def make_wide_inputs(tmp_path: Path, n: int, per_frame: int) -> list[str]:
    """``n`` frames with ``per_frame`` boxes each, every box its own track (so that
    ``tracks.csv`` grows with the records)."""
    args = make_inputs(tmp_path, n)
    frames = np.repeat(np.arange(n), per_frame)
    shift = np.tile(np.arange(per_frame) * 0.5, n)
    boxes = np.stack([100 + shift, np.full_like(shift, 110), 150 + shift, np.full_like(shift, 150)])
    table = BoxTable.build(frames, boxes.T, track_id=np.arange(n * per_frame))
    write_box_csv(table, tmp_path / "boxes.csv")
    return args


def check_whole_or_absent(out: Path, per_frame: int) -> dict[str, object]:
    """records.csv, frames.csv, tracks.csv and run.json of a run stopped by a full disk: each
    absent, or whole (no NUL byte, whole rows, whole frames); returns ``run.json``."""
    for name in ("records.csv", "frames.csv", "tracks.csv", "run.json"):
        if (out / name).exists():
            assert b"\0" not in (out / name).read_bytes(), f"{name} holds NUL bytes"
    summary = json.loads((out / "run.json").read_text())
    assert summary["complete"] is False and "No space left" in summary["error"]
    last = summary["last_complete_frame"]
    frames = [int(r["frame"]) for r in read_rows(out / "frames.csv")]
    assert frames == list(range(last + 1))
    per = Counter(int(r["frame"]) for r in read_rows(out / "records.csv"))
    assert sorted(per) == list(range(len(per))) and len(per) in (last + 1, last + 2)
    assert set(per.values()) == {per_frame}  # no frame cut short
    assert summary["records"] == sum(per.values())
    if (out / "tracks.csv").exists():  # written at the end: whole, or not at all
        assert len(read_rows(out / "tracks.csv")) == sum(per.values())
    return summary


def small_disk_run(tmp_path: Path, args: list[str], size: str) -> tuple[int, str, Path]:
    """``slopedist run ARGS`` with ``--out`` on a file system of ``size`` (a tmpfs mounted in
    a user and mount namespace of its own: no root needed); its exit code and stderr, and a
    copy of the output folder. Skips where namespaces or tmpfs are not available."""
    unshare = shutil.which("unshare")
    probe = [unshare or "unshare", "--user", "--map-root-user", "--mount", "true"]
    if unshare is None or subprocess.run(probe, capture_output=True).returncode != 0:
        pytest.skip("needs `unshare --user --map-root-user --mount` for a small real disk")
    disk, copy = tmp_path / "disk", tmp_path / "copy"
    disk.mkdir()
    script = (  # $0 the disk, $1 its size, $2 where the output is copied, then the command
        'mount -t tmpfs -o size="$1" tmpfs "$0" || exit 99; copy="$2"; shift 2; '
        '"$@" --out "$0/out" 2>"$0.err"; code=$?; cp -a "$0/out" "$copy"; exit $code'
    )
    cmd = [unshare, "--user", "--map-root-user", "--mount", "sh", "-c", script]
    cmd += [str(disk), size, str(copy), sys.executable, "-m", "slopedist", "run", *args]
    res = subprocess.run(cmd, capture_output=True, env={**os.environ, "PYTHONPATH": SRC})
    if res.returncode == 99:
        pytest.skip(f"cannot mount a tmpfs in a user namespace: {res.stderr.decode()}")
    err_file = disk.with_name("disk.err")
    err = err_file.read_text() if err_file.exists() else res.stderr.decode()
    return res.returncode, err, copy


def test_a_full_disk_leaves_each_output_whole_or_absent_and_the_report_reads_it(
    tmp_path: Path,
) -> None:
    """A real 1 MB file system filling up: records.csv held NUL bytes and a torn frame after
    its last whole row (cut back while a buffer still held data, which close() then wrote at
    the old offset), and tracks.csv was left empty, so that `slopedist report` refused the
    folder. Now each file is whole up to a frame, or absent."""
    per_frame = 300
    args = make_wide_inputs(tmp_path, 60, per_frame)
    code, err, out = small_disk_run(
        tmp_path, [*args, "--odometry", "none", "--method", "flat"], "1m"
    )
    assert code == 2, err
    assert "No space left" in err and "run stopped at frame" in err
    summary = check_whole_or_absent(out, per_frame)
    assert 10 < summary["last_complete_frame"] < 59
    assert main(["report", str(out), "--out", str(tmp_path / "report")]) == 0


def test_a_full_disk_at_the_lowest_write_leaves_whole_outputs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The same with the disk simulated at ``os.write`` (no namespaces needed): a file system
    with 60 kB free under the output folder, which writes what fits and then refuses."""
    per_frame = 30
    args = make_wide_inputs(tmp_path, 40, per_frame)
    out = tmp_path / "out"
    SmallDisk(out, 60_000).install(monkeypatch)
    assert main(["run", *args, "--out", str(out), "--odometry", "none", "--method", "flat"]) == 2
    err = capsys.readouterr().err
    assert "No space left" in err and "run stopped at frame" in err
    summary = check_whole_or_absent(out, per_frame)
    assert 5 < summary["last_complete_frame"] < 39
    assert not list(out.glob("*.partial*"))
    monkeypatch.undo()
    assert main(["report", str(out), "--out", str(tmp_path / "report")]) == 0


class SmallDisk:
    """A file system with ``free`` bytes left under ``root``: ``os.write`` to a file opened
    there with ``os.open`` writes what fits (a short write), then fails with ENOSPC; bytes
    written over a file's existing ones take no space, as on a real disk."""

    def __init__(self, root: Path, free: int) -> None:
        self.root, self.free = root.resolve(), free
        self.fds: set[int] = set()
        self.real_open, self.real_write, self.real_close = os.open, os.write, os.close

    def install(self, monkeypatch: pytest.MonkeyPatch) -> None:
        monkeypatch.setattr(os, "open", self.open)
        monkeypatch.setattr(os, "write", self.write)
        monkeypatch.setattr(os, "close", self.close)

    def open(self, path: Any, flags: int, mode: int = 0o777, **kw: Any) -> int:
        fd = self.real_open(path, flags, mode, **kw)
        if Path(os.fsdecode(path)).resolve().is_relative_to(self.root):
            self.fds.add(fd)
        return fd

    def close(self, fd: int) -> None:
        self.fds.discard(fd)
        self.real_close(fd)

    def write(self, fd: int, data: Any) -> int:
        if fd not in self.fds:
            return self.real_write(fd, data)
        data = bytes(data)
        end = os.lseek(fd, 0, os.SEEK_CUR) + len(data)
        growth = max(0, end - os.fstat(fd).st_size)
        fits = len(data) - max(0, growth - self.free)
        if fits <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        written = self.real_write(fd, data[:fits])
        self.free -= max(0, growth - (len(data) - written))
        return written


def test_run_knows_the_image_size_and_estimate_takes_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A box reaching the bottom row of the frames is an upper bound in ``run``; ``estimate``
    does the same with ``--image-size`` and tests nothing without it."""
    args = make_inputs(tmp_path, 3)
    boxes = BoxTable.build(
        [0, 0, 1, 2],
        [[100, 120, 150, H - 1.0], [100, 110, 150, 150], [400, 10, 450, 50], [0, 120, 50, 180]],
        classes=["Car", "Car", "Car", "Pedestrian"],
    )
    write_box_csv(boxes, tmp_path / "boxes.csv")
    out = tmp_path / "out"
    assert main(["run", *args, "--out", str(out), "--odometry", "none", "--method", "flat"]) == 0
    rows = read_rows(out / "records.csv")
    assert [(r["status"], r["reason"], r["cut"]) for r in rows] == [
        ("upper_bound", "cut_bottom", "bottom"),
        ("ok", "", ""),
        ("missing", "outside_image", ""),
        ("missing", "not_a_vehicle", "left"),
    ]
    assert float(rows[0]["distance_m"]) == pytest.approx(500 * 1.65 / (H - 1 - 100))
    summary = json.loads((out / "run.json").read_text())
    assert (summary["estimated"], summary["upper_bounds"], summary["not_vehicles"]) == (1, 1, 1)
    assert summary["not_vehicle_classes"] == {"Pedestrian": 1}
    printed = capsys.readouterr()
    assert "not of a vehicle class ('Pedestrian' (1); " in printed.out + printed.err
    # no box of a vehicle class (a detector's class names): a warning naming the classes
    flat = ["--out", str(out), "--odometry", "none", "--method", "flat"]
    assert main(["run", *args, *flat, "--vehicle-classes", "Van"]) == 0
    printed = capsys.readouterr()
    text = printed.out + printed.err
    assert "warning: no box got a distance; 3 of 4 are of a class that is not a vehicle: " in text
    assert "'Car' (2), 'Pedestrian' (1) (missing" in text

    est = _estimate_args(tmp_path)
    (tmp_path / "b.csv").write_text("frame,left,top,right,bottom\n0,500,180,600,374\n")
    assert main([*est, "--image-size", "1242x375"]) == 0
    row = next(csv.DictReader(capsys.readouterr().out.splitlines()))
    assert (row["status"], row["reason"]) == ("upper_bound", "cut_bottom")
    assert main(est) == 0
    row = next(csv.DictReader(capsys.readouterr().out.splitlines()))
    assert (row["status"], row["reason"]) == ("ok", "")
    assert main([*est, "--image-size", "1242"]) == 2
    assert "WIDTHxHEIGHT" in capsys.readouterr().err


def test_an_offline_runs_export_says_it_shows_the_causal_pass(tmp_path: Path) -> None:
    """`run --offline --export mcap`: the MCAP shows the frames as they came (the causal pass),
    while records.csv holds ours-offline; its frames said 'ours-offline' all the same."""
    pytest.importorskip("mcap")
    from slopedist.streaming.mcap_export import FRAME_TOPIC, read_mcap_export

    args = make_inputs(tmp_path, 4)
    args[args.index("--method") + 1] = "ours"
    out = tmp_path / "out"
    assert main(["run", *args, "--offline", "--export", "mcap", "--out", str(out)]) == 0
    frames = read_mcap_export(out / "run.mcap")[FRAME_TOPIC]
    assert {f["method"] for _, f in frames} == {"ours-offline (causal pass)"}
    assert {r["method"] for r in read_rows(out / "records.csv")} == {"ours-offline"}


def test_an_offline_runs_overlay_says_it_shows_the_causal_pass(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`run --offline --snapshot N`: the overlay's header named 'ours-offline' over the causal
    pass's distances (records.csv holds other numbers under that name); it says so, as the
    MCAP export does."""
    import slopedist.streaming.loop as runner

    methods: list[object] = []
    draw = runner.draw_fig3_overlay

    def spy(*args: object, **kwargs: object) -> np.ndarray:
        methods.append(args[6] if len(args) > 6 else kwargs.get("method"))
        return draw(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(runner, "draw_fig3_overlay", spy)
    args = make_inputs(tmp_path, 3)
    args[args.index("--method") + 1] = "ours"
    out = tmp_path / "out"
    assert main(["run", *args, "--offline", "--snapshot", "1", "--out", str(out)]) == 0
    assert (out / "snapshot_000001.jpg").is_file()
    assert methods == ["ours-offline (causal pass)"]


def test_run_counts_the_box_rows_its_reader_left_out(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A COCO file whose person and crowd annotations were dropped without a word: run.json
    counts them by reason and one warning line names the file."""
    args = make_inputs(tmp_path, 3)
    items = [
        {"image_id": 0, "category_id": 3, "bbox": [100, 110, 50, 40]},
        {"image_id": 1, "category_id": 1, "bbox": [100, 110, 50, 40]},
        {"image_id": 2, "category_id": 1, "bbox": [100, 110, 50, 40]},
        {"image_id": 2, "category_id": 3, "bbox": [0, 100, 300, 80], "iscrowd": 1},
    ]
    coco = tmp_path / "boxes.json"
    coco.write_text(json.dumps(items))
    args[args.index("--boxes") + 1] = str(coco)
    out = tmp_path / "out"
    with caplog.at_level("WARNING", logger="slopedist.io.detections.dropped"):
        assert main(["run", *args, "--out", str(out), "--odometry", "none"]) == 0
    summary = json.loads((out / "run.json").read_text())
    assert summary["dropped_boxes"] == {
        "category_id 1 (not in the class map)": 2,
        "crowd annotations (iscrowd 1)": 1,
    }
    assert summary["records"] == 1
    assert [r.getMessage() for r in caplog.records] == [
        f"warning: {coco}: dropped 3 of 4 box rows (75 %): 2 category_id 1 (not in the class "
        "map), 1 crowd annotations (iscrowd 1)"
    ]


def test_a_second_run_into_a_folder_in_use_is_refused_and_the_first_stays_whole(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two runs into one --out mixed their rows (frames out of order, a torn row) and both
    exited 0. Now the second is refused at once, naming the folder and the first's pid."""
    n = 200
    args = make_inputs(tmp_path, n)
    out = tmp_path / "out"
    first = start_run([*args, "--out", str(out)])
    wait_for_rows(out / "records.partial.csv", 10, first)
    second = ["run", *args, "--out", str(out), "--odometry", "none", "--method", "flat"]
    assert main(second) == 2
    err = capsys.readouterr().err
    assert (
        f"slopedist: error: {out} is in use by another slopedist command (pid {first.pid} on "
        in err
    )
    _, first_err = first.communicate(timeout=300)
    assert first.returncode == 0, first_err.decode()
    rows = read_rows(out / "records.csv")
    assert [int(r["frame"]) for r in rows] == list(range(n)) and {r["method"] for r in rows} == {
        "ego"
    }
    summary = json.loads((out / "run.json").read_text())
    assert summary["complete"] is True and summary["records"] == n
    assert sorted(p.name for p in out.iterdir()) == [
        "frames.csv",
        "records.csv",
        "run.json",
        "tracks.csv",
    ]  # no .partial file, no lock file


def test_a_run_takes_over_the_lock_a_killed_run_left_with_a_note(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    args = make_inputs(tmp_path, 300)
    out = tmp_path / "out"
    killed = start_run([*args, "--out", str(out)])
    wait_for_rows(out / "records.partial.csv", 5, killed)
    killed.kill()
    killed.wait(timeout=60)
    assert (out / ".slopedist.lock").read_text().startswith(f"pid {killed.pid} on ")
    flat = ["--odometry", "none", "--method", "flat"]
    (tmp_path / "b").mkdir()
    with caplog.at_level("WARNING", logger="slopedist.io.outputs"):
        assert main(["run", *make_inputs(tmp_path / "b", 3), "--out", str(out), *flat]) == 0
    assert [r.getMessage().split(" on ")[0] for r in caplog.records] == [
        f"note: took over the lock of {out} left by pid {killed.pid}"
    ]
    assert not (out / ".slopedist.lock").exists()


def test_an_interrupted_rerun_keeps_the_complete_run_and_its_partial_output_beside_it(
    tmp_path: Path,
) -> None:
    """SIGTERM to a rerun into a folder holding a complete run replaced that run with the
    partial one. Now the complete run stays as it was, and the stopped rerun's files keep
    their temporary names beside it, with its summary as run.partial.json."""
    args = make_inputs(tmp_path, 400)
    out = tmp_path / "out"
    flat = ["--odometry", "none", "--method", "flat"]
    assert main(["run", *args, "--out", str(out), *flat, "--snapshot", "3"]) == 0
    first = {p.name: p.read_bytes() for p in out.iterdir()}
    assert sorted(first) == [
        "frames.csv",
        "records.csv",
        "run.json",
        "snapshot_000003.jpg",
        "tracks.csv",
    ]
    rerun = start_run([*args, "--out", str(out), "--snapshot", "3"])
    wait_for_rows(out / "records.partial.csv", 10, rerun)
    rerun.send_signal(signal.SIGTERM)
    _, err = rerun.communicate(timeout=120)
    assert rerun.returncode == 128 + signal.SIGTERM, err.decode()
    assert {n: (out / n).read_bytes() for n in first} == first  # the complete run, whole
    assert "the complete earlier run in" in err.decode() and "records.partial.csv" in err.decode()
    partial = json.loads((out / "run.partial.json").read_text())
    assert partial["complete"] is False and "SIGTERM" in partial["error"]
    rows = read_rows(out / "records.partial.csv")
    last = partial["last_complete_frame"]
    assert [int(r["frame"]) for r in rows] == list(range(last + 1))
    assert {r["method"] for r in rows} == {"ego"}
    assert len(read_rows(out / "frames.partial.csv")) == last + 1
    assert (out / "snapshot_000003.partial.jpg").is_file()
    assert not (out / ".slopedist.lock").exists()
    # the next complete run replaces the complete one and the stopped one's leftovers
    assert main(["run", *args, "--out", str(out), *flat]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "frames.csv",
        "records.csv",
        "run.json",
        "tracks.csv",
    ]


def test_estimate_writes_its_out_file_whole_or_leaves_the_previous_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """`estimate --out` wrote over the previous file as it went: a full disk left it cut.
    Now the file is replaced only when every record is written."""
    args = _estimate_args(tmp_path)
    out = tmp_path / "est" / "records.csv"
    assert main([*args, "--out", str(out)]) == 0
    before = out.read_bytes()
    SmallDisk(out.parent, 2000).install(monkeypatch)
    assert main([*args, "--out", str(out), "--method", "paper"]) == 2
    err = capsys.readouterr().err
    assert "No space left" in err and "records.partial.csv" in err
    assert out.read_bytes() == before
    partial = (tmp_path / "est" / "records.partial.csv").read_bytes()
    assert partial.endswith(b"\n") and b"\0" not in partial
    monkeypatch.undo()
    assert sorted(p.name for p in out.parent.iterdir()) == ["records.csv", "records.partial.csv"]


def test_paths_of_any_bytes_work_in_run_and_report(tmp_path: Path) -> None:
    """A folder name with a byte that is not UTF-8: `report` failed with "internal error:
    UnicodeEncodeError", and OpenCV, given such a name, crashed the interpreter. Now every
    file is read and written, and the name is printed and written with the byte as \\xff."""
    root = os.fsencode(tmp_path) + b"/bad\xffname"
    try:
        os.mkdir(root)
    except OSError as exc:
        pytest.skip(f"the file system refuses a name that is not UTF-8: {exc}")
    folder = Path(os.fsdecode(root))
    (tmp_path / "in").mkdir()
    args = make_inputs(tmp_path / "in", 4)  # (the test's own OpenCV calls take UTF-8 names)
    os.rename(tmp_path / "in", folder / "in")
    args = [a.replace(str(tmp_path / "in"), str(folder / "in")) for a in args]
    for png in sorted((folder / "in" / "frames").iterdir()):  # JPEG frames: read by OpenCV
        image = cv2.imdecode(np.frombuffer(png.read_bytes(), np.uint8), cv2.IMREAD_COLOR)
        png.with_suffix(".jpg").write_bytes(cv2.imencode(".jpg", image)[1].tobytes())
        png.unlink()
    out = folder / "out"
    env = {**os.environ, "PYTHONPATH": SRC}
    cmd = [sys.executable, "-m", "slopedist"]
    run = [*cmd, "run", *args, "--out", str(out), "--overlay", "--overlay-format", "png"]
    res = subprocess.run([*run, "--snapshot", "1"], env=env, capture_output=True)
    assert res.returncode == 0, res.stderr.decode(errors="backslashreplace")
    shown = str(tmp_path) + "/bad\\xffname"
    assert f"to {shown}/out/records.csv" in res.stderr.decode()
    assert len(read_rows(out / "records.csv")) == 4
    assert len(list((out / "overlay").glob("*.png"))) == 4
    assert (out / "snapshot_000001.jpg").is_file()
    report = folder / "report"
    res = subprocess.run([*cmd, "report", str(out), "--out", str(report)], env=env,
                         capture_output=True)  # fmt: skip
    assert res.returncode == 0, res.stderr.decode(errors="backslashreplace")
    assert f"wrote {shown}/report/report.html" in res.stderr.decode()
    assert f"{shown}/out" in (report / "report.md").read_text(encoding="utf-8")
