"""The batch on a local Ray instance with 2 CPUs: records identical to running each drive
alone, a corrupt drive isolated, a killed worker retried, a second run that skips complete
drives and redoes a deleted one or one whose settings changed; drive logs (ROS 1 bag, ROS 2
MCAP) with their camera_info, IMU and speed topics giving the records of ``slopedist run`` on
the log and the headways of the fleet safety table, also found in a folder of drives. Ray
starts once for the session (``ray_instance`` of tests/conftest.py)."""

from __future__ import annotations

import csv
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from slopedist.batch import BatchOptions, BatchResult, DriveStatus, load_drives, run_batch
from slopedist.batch.drive import CRASH_ENV
from slopedist.batch.engine import LOCK_NAME, import_ray, kept_signal_handlers, output_lock
from slopedist.batch.safety import SHORT_HEADWAY_S
from slopedist.cli import main
from slopedist.core.errors import ConfigurationError, OptionalDependencyError

from .conftest import real_drive, run_alone, simulate, simulated_log, write_drive_log

SHARED_LEAD = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "kitti_raw_lead"
SCENARIOS = ("ego_crest", "same_downhill", "target_steep_uphill")
CRASHED = "ego_crest_paper"


@dataclass
class Fleet:
    root: Path
    manifest: Path
    out: Path
    result: BatchResult
    rows: list[list[str]]

    def status(self) -> dict[str, dict[str, str]]:
        with (self.out / "status.csv").open(newline="") as fh:
            return {r["drive"]: r for r in csv.DictReader(fh)}


@pytest.fixture(scope="module")
def fleet(ray_instance: Any, tmp_path_factory: pytest.TempPathFactory) -> Fleet:
    root = tmp_path_factory.mktemp("fleet")
    rows = [["drive", "frames", "calib", "boxes", "method", "timestamps"]]
    for scenario in SCENARIOS:
        simulate(scenario, root / scenario)
        for method in ("paper", "flat"):
            files = [f"{scenario}/{n}" for n in ("image_02", "calib.txt", "boxes.csv")]
            rows.append([f"{scenario}_{method}", *files, method, f"{scenario}/times.txt"])
    ours = [f"{SCENARIOS[0]}/{n}" for n in ("image_02", "calib.txt", "boxes.csv")]
    rows.append([f"{SCENARIOS[0]}_ours", *ours, "ours", f"{SCENARIOS[0]}/times.txt"])  # TTC
    if SHARED_LEAD.is_dir():  # the shared real frames (absent in a fresh clone)
        real_drive(SHARED_LEAD, root / "kitti")
        rows.append(["kitti", "kitti/image_02", "kitti/calib.txt", "kitti/boxes.csv", "ego", ""])
    (root / "broken.csv").write_text("frame,left,top,right,bottom\n0,1,2,3,4\n1,1,oops,3,4\n")
    rows.append(["broken", *rows[1][1:3], "broken.csv", "paper", ""])
    manifest = root / "drives.csv"
    with manifest.open("w", newline="") as fh:
        csv.writer(fh).writerows(rows)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(CRASH_ENV, f"{CRASHED}:2")  # first attempt dies after 2 frames
        result = run_batch(load_drives(manifest), root / "out", BatchOptions(progress=False))
    return Fleet(root, manifest, root / "out", result, rows)


def test_a_batch_gives_the_records_of_each_drive_run_alone(fleet: Fleet, tmp_path: Path) -> None:
    done = [r for r in fleet.rows[1:] if r[0] != "broken"]
    assert len(done) >= 6
    for name, frames, calib, boxes, method, times in done:
        extra = ["--timestamps", str(fleet.root / times)] if times else []
        at = fleet.root
        alone = run_alone(
            at / frames, at / calib, at / boxes, method, tmp_path / name, *extra
        ).read_bytes()
        assert (fleet.out / name / "records.csv").read_bytes() == alone, name
    status = fleet.status()
    assert all(status[r[0]]["status"] == "done" for r in done)
    assert fleet.result.frames_run == sum(int(status[r[0]]["frames"]) for r in done)


def test_a_corrupt_drive_fails_alone(fleet: Fleet) -> None:
    row = fleet.status()["broken"]
    assert row["status"] == "failed"
    assert "broken.csv, line 3" in row["error"]
    assert not (fleet.out / "broken").exists()
    assert not fleet.result.all_failed
    assert [p.name for p in fleet.out.iterdir() if p.name.startswith(".")] == [LOCK_NAME]


def test_a_worker_killed_mid_drive_is_retried(fleet: Fleet) -> None:
    row = fleet.status()[CRASHED]
    assert (row["status"], row["attempts"]) == ("done", "2")
    assert int(row["frames"]) == 5


def test_fleet_dataset_and_summary(fleet: Fleet) -> None:
    import pyarrow.dataset as ds

    table = ds.dataset(fleet.out / "records.parquet", partitioning="hive").to_table()
    drives = table.column("drive").to_pylist()
    status = fleet.status()
    done = sorted(d for d, r in status.items() if r["status"] == "done")
    assert sorted(set(drives)) == done
    assert all(drives.count(d) == int(status[d]["records"]) for d in done)
    with (fleet.out / "fleet" / "pooled.csv").open(newline="") as fh:
        pooled = {r["method"]: r for r in csv.DictReader(fh)}
    with (fleet.out / "fleet" / "drives.csv").open(newline="") as fh:
        per_drive = list(csv.DictReader(fh))
    for method, row in pooled.items():
        mine = [r for r in per_drive if r["method"] == method]
        assert int(row["drives"]) == len(mine)
        assert int(row["n"]) == sum(int(r["n"]) for r in mine) > 0


def test_fleet_report_of_the_batch(fleet: Fleet, tmp_path: Path) -> None:
    from slopedist.evaluation.report import ReportOptions, SourceKind, report_data, write_report

    data = report_data(fleet.out, ReportOptions())
    assert data.kind is SourceKind.FLEET
    status = fleet.status()
    assert sorted(data.sequences) == sorted(d for d, r in status.items() if r["status"] == "done")
    tables = {t.key: t for t in write_report(data, tmp_path / "rep", parquet=False).tables}
    assert data.fleet is not None
    per_drive = {(r["drive"], r["method"]): r["rmse"] for r in data.fleet.drives}
    table1 = tables["table1_rmse"]
    assert len(per_drive) >= 6
    compared = 0
    for row in table1.rows[: len(data.sequences)]:  # Table 1 per drive = the fleet table
        for method, value in zip(table1.headers[2:], row[2:]):
            if (row[0], method) in per_drive:
                assert value == pytest.approx(per_drive[(row[0], method)]), (row[0], method)
                compared += 1
    assert compared == len(per_drive)
    tracks = list(csv.DictReader((fleet.out / f"{SCENARIOS[0]}_ours" / "tracks.csv").open()))
    safety = {r[0]: r for r in tables["fleet_safety_pooled"].rows}
    assert safety["ours"][3] == len(tracks) > 0
    assert safety["ours"][5] == pytest.approx(min(float(t["min_ttc_s"]) for t in tracks))
    assert tables["fleet_failed"].rows == [["broken", status["broken"]["error"]]]


def test_a_second_run_skips_complete_drives_and_redoes_a_deleted_one(
    fleet: Fleet, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    shutil.copytree(fleet.out, out)
    shutil.rmtree(out / "same_downhill_flat")
    shutil.rmtree(out / "records.parquet" / "drive=same_downhill_flat")
    changed = fleet.root / "target_steep_uphill" / "boxes.csv"
    text = changed.read_text()
    changed.write_text(text.replace("\n", "\n", 1) + text.splitlines()[-1] + "\n")  # one more box
    second = run_batch(load_drives(fleet.manifest), out, BatchOptions(progress=False))
    changed.write_text(text)
    by_name = {o.drive: o.status for o in second.outcomes}
    redone = {"same_downhill_flat", "target_steep_uphill_paper", "target_steep_uphill_flat"}
    assert {n for n, s in by_name.items() if s is DriveStatus.DONE} == redone
    assert by_name["broken"] is DriveStatus.FAILED
    skipped = set(by_name) - redone - {"broken"}
    assert skipped and all(by_name[n] is DriveStatus.SKIPPED for n in skipped)
    assert (out / "records.parquet" / "drive=same_downhill_flat" / "part-0.parquet").is_file()


def test_cli_exit_code_when_every_drive_failed(
    fleet: Fleet, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    only_broken = tmp_path / "m.csv"
    only_broken.write_text(
        "drive,frames,calib,boxes\n"
        f"broken,{fleet.root / 'ego_crest/image_02'},{fleet.root / 'ego_crest/calib.txt'},"
        f"{fleet.root / 'broken.csv'}\n"
    )
    assert main(["batch", str(only_broken), "--out", str(tmp_path / "o"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "1 drives: 1 failed" in err and "broken.csv, line 3" in err


def test_without_ray_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)
    with pytest.raises(OptionalDependencyError, match=r"pip install 'slopedist\[batch\]'"):
        import_ray()


def test_fail_fast_stops_the_batch(fleet: Fleet, tmp_path: Path) -> None:
    manifest = tmp_path / "m.csv"
    sim = fleet.root / "ego_crest"
    good = f"{sim / 'image_02'},{sim / 'calib.txt'},{sim / 'boxes.csv'}"
    manifest.write_text(
        "drive,frames,calib,boxes,timestamps\n"
        f"broken,{sim / 'image_02'},{sim / 'calib.txt'},{fleet.root / 'broken.csv'},\n"
        + "".join(f"good{i},{good},{sim / 'times.txt'}\n" for i in range(3))
    )
    out = tmp_path / "o"
    assert main(["batch", str(manifest), "--out", str(out), "--fail-fast", "--quiet"]) == 1
    with (out / "status.csv").open(newline="") as fh:
        status = {r["drive"]: r["status"] for r in csv.DictReader(fh)}
    assert status["broken"] == "failed"
    assert "cancelled" in status.values()  # 2 CPUs: at least one good drive was still waiting
    assert all(status[f"good{i}"] in ("cancelled", "done") for i in range(3))


def test_signal_handlers_are_restored() -> None:
    import signal

    before = signal.getsignal(signal.SIGTERM)
    with kept_signal_handlers():
        signal.signal(signal.SIGTERM, lambda *_: None)
    assert signal.getsignal(signal.SIGTERM) is before


LOG_SPEED_MPS = 12.0
"""Ego speed written on the odometry topic of the real frames' log, m/s (the shared frames
come without one)."""


@dataclass
class LogFleet:
    root: Path
    out: Path
    rows: list[dict[str, str]]
    speeds: dict[str, list[float]]
    """Ego speed per frame of each log drive, m/s."""


@pytest.fixture(scope="module")
def log_fleet(ray_instance: Any, tmp_path_factory: pytest.TempPathFactory) -> LogFleet:
    """A batch of drive logs next to an image folder: a ROS 1 bag of a synthetic scenario
    (camera_info as the calibration, visual odometry or its IMU topic, its speed topic) and a
    ROS 2 MCAP log of the shared real frames."""
    pytest.importorskip("rosbags")
    from slopedist.io.rosbag_write import LogFormat, LogTopics

    root = tmp_path_factory.mktemp("logs")
    sim = simulate("ego_crest", root / "sim")
    _, sim_speeds = simulated_log(sim, root / "sim.bag", LogFormat.ROS1)
    topics = LogTopics()
    log = {"calib": "", "timestamps": "", "image_topic": topics.image}
    rows = [
        {**log, "drive": "sim_log", "frames": "sim.bag", "method": "paper"},
        {**log, "drive": "sim_imu", "frames": "sim.bag", "method": "imu"},
        {
            **{k: "" for k in log},
            "drive": "sim_folder",
            "frames": "sim/image_02",
            "calib": "sim/calib.txt",
            "method": "paper",
            "timestamps": "sim/times.txt",
        },
    ]
    rows[0]["speed_topic"] = rows[1]["speed_topic"] = topics.odometry
    rows[1]["rotation_topic"] = topics.imu
    for row in rows:
        row["boxes"] = "sim/boxes.csv"
    speeds = {"sim_log": sim_speeds, "sim_imu": sim_speeds}
    if SHARED_LEAD.is_dir():  # the shared real frames (absent in a fresh clone)
        frames = 8
        kitti = real_drive(SHARED_LEAD, root / "kitti", frames)
        speeds["kitti_log"] = [LOG_SPEED_MPS] * frames
        times = [k / 10 for k in range(frames)]
        write_drive_log(kitti, root / "kitti_log", LogFormat.ROS2_MCAP, times, speeds["kitti_log"])
        rows.append(
            {
                **log,
                "drive": "kitti_log",
                "frames": "kitti_log",
                "boxes": "kitti/boxes.csv",
                "method": "ego",
                "speed_topic": topics.odometry,
            }
        )
    columns = ["drive", "frames", "calib", "boxes", "method", "timestamps"]
    columns += ["image_topic", "rotation_topic", "speed_topic"]
    manifest = root / "drives.csv"
    with manifest.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, columns, restval="")
        writer.writeheader()
        writer.writerows(rows)
    run_batch(load_drives(manifest), root / "out", BatchOptions(progress=False))
    return LogFleet(root, root / "out", rows, speeds)


def read_rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def test_drive_logs_in_a_batch_give_the_records_of_run_alone(
    log_fleet: LogFleet, tmp_path: Path
) -> None:
    status = {r["drive"]: r["status"] for r in read_rows(log_fleet.out / "status.csv")}
    assert status == {r["drive"]: "done" for r in log_fleet.rows}
    logs = [r for r in log_fleet.rows if r.get("image_topic")]
    assert len(logs) >= 2
    for row in logs:
        frames, boxes = log_fleet.root / row["frames"], log_fleet.root / row["boxes"]
        args = ["run", str(frames), "--image-topic", row["image_topic"], "--boxes", str(boxes)]
        for topic in ("rotation_topic", "speed_topic"):  # no --calib: the log's camera_info
            args += [f"--{topic.replace('_', '-')}", row[topic]] if row.get(topic) else []
        alone = tmp_path / row["drive"]
        assert main([*args, "--method", row["method"], "--out", str(alone), "--quiet"]) == 0
        for name in ("records.csv", "tracks.csv"):
            mine = (log_fleet.out / row["drive"] / name).read_bytes()
            assert mine == (alone / name).read_bytes(), (row["drive"], name)
        assert any(r["status"] == "ok" for r in read_rows(alone / "records.csv")), row["drive"]


def test_fleet_safety_has_the_headways_of_the_logs_with_a_speed_topic(log_fleet: LogFleet) -> None:
    safety = {r["drive"]: r for r in read_rows(log_fleet.out / "fleet" / "safety.csv")}
    for drive, speeds in log_fleet.speeds.items():
        records = read_rows(log_fleet.out / drive / "records.csv")
        tracks = read_rows(log_fleet.out / drive / "tracks.csv")
        bound_only = [t for t in tracks if t["frames"] == "0"]  # cut trucks: no distance
        assert all(t["mean_headway_s"] == "" and t["min_distance_bound_m"] for t in bound_only)
        tracks = [t for t in tracks if t["frames"] != "0"]
        for track in tracks:  # headway = distance / ego speed of the frame, over the track
            mine = [
                float(r["distance_m"]) / speeds[int(r["frame"])]
                for r in records
                if r["track_id"] == track["track_id"] and r["reason"] == "" and r["distance_m"]
            ]
            assert float(track["mean_headway_s"]) == pytest.approx(np.mean(mine), rel=1e-5)
        headways = [float(t["mean_headway_s"]) for t in tracks]
        row = safety[drive]
        assert float(row["min_headway_s"]) == pytest.approx(min(headways), rel=1e-6)
        assert int(row["short_headway_tracks"]) == sum(h < SHORT_HEADWAY_S for h in headways)
    assert safety["sim_folder"]["min_headway_s"] == ""  # no ego speed without a log
    assert safety["sim_folder"]["short_headway_tracks"] == "0"


def test_a_second_batch_of_logs_skips_them(log_fleet: LogFleet) -> None:
    result = run_batch(
        load_drives(log_fleet.root / "drives.csv"), log_fleet.out, BatchOptions(progress=False)
    )
    assert {o.status for o in result.outcomes} == {DriveStatus.SKIPPED}


def test_per_drive_settings_reach_the_records_and_a_changed_setting_runs_again(
    ray_instance: Any, tmp_path: Path
) -> None:
    """``slopedist batch`` with per-drive ``reference`` and ``ours_options`` cells and
    batch-wide values (also ``--generic-class``): each drive's records are those of
    ``slopedist run`` with its options, ``fleet/settings.csv`` lists them, and a second batch
    runs again exactly the drive whose setting changed (the others are skipped)."""
    sim = simulate("same_downhill", tmp_path / "sim")
    files = "sim/image_02,sim/calib.txt,sim/boxes.csv,sim/times.txt"
    header = "drive,frames,calib,boxes,timestamps,method,reference,ours_options"
    rows = [
        f"face,{files},ours,nearest_face,odd_object_weight=0;size_learning=true",
        f"batchwide,{files},ours,,",
        f"paper,{files},paper,,",
    ]
    manifest = tmp_path / "drives.csv"
    manifest.write_text("\n".join([header, *rows]) + "\n")
    out = tmp_path / "out"
    batch_args = ["batch", str(manifest), "--out", str(out), "--quiet", "--no-parquet"]
    generic = ["--generic-class", "Car"]
    batch_wide = ["--reference", "contact", "--ours-option", "use_width=false", *generic]
    assert main([*batch_args, *batch_wide]) == 0
    face = ["--reference", "nearest_face", "--ours-option", "odd_object_weight=0", *generic]
    expected = {
        "face": ("ours", *face, "--ours-option", "size_learning=true"),
        "batchwide": ("ours", *batch_wide),
        "paper": ("paper", "--reference", "contact"),
    }
    for drive, (method, *options) in expected.items():
        times = ["--timestamps", str(sim / "times.txt")]
        alone = run_alone(
            sim / "image_02",
            sim / "calib.txt",
            sim / "boxes.csv",
            method,
            tmp_path / "alone" / drive,
            *times,
            *options,
        )
        assert (out / drive / "records.csv").read_bytes() == alone.read_bytes(), drive
    references = {
        drive: {r["reference"] for r in read_rows(out / drive / "records.csv") if r["distance_m"]}
        for drive in expected
    }
    assert references == {"face": {"nearest_face"}, "batchwide": {"contact"}, "paper": {"contact"}}
    settings = {r["drive"]: r for r in read_rows(out / "fleet" / "settings.csv")}
    assert settings["face"]["ours_options"] == "odd_object_weight=0.0;size_learning=true"
    assert (settings["face"]["reference"], settings["batchwide"]["reference"]) == (
        "nearest_face",
        "contact",
    )
    assert (settings["batchwide"]["ours_options"], settings["paper"]["ours_options"]) == (
        "use_width=false",
        "",
    )
    assert settings["paper"]["reference"] == "contact"  # the batch-wide reference: every drive
    assert (settings["batchwide"]["generic_classes"], settings["paper"]["generic_classes"]) == (
        "Car",
        "",
    )

    manifest.write_text(manifest.read_text().replace("nearest_face", "centre"))
    assert main([*batch_args, *batch_wide]) == 0
    status = {r["drive"]: r["status"] for r in read_rows(out / "status.csv")}
    assert status == {"face": "done", "batchwide": "skipped", "paper": "skipped"}
    centre = {r["reference"] for r in read_rows(out / "face" / "records.csv") if r["distance_m"]}
    assert centre == {"centre"}
    again = ["--reference", "nearest_face", "--ours-option", "use_width=false", *generic]
    assert main([*batch_args, *again]) == 0
    status = {r["drive"]: r["status"] for r in read_rows(out / "status.csv")}
    # every method reports at the batch-wide reference: paper's records change with it too
    assert status == {"face": "skipped", "batchwide": "done", "paper": "done"}


def test_a_folder_of_drive_logs_with_a_batch_wide_image_topic(
    log_fleet: LogFleet, tmp_path: Path
) -> None:
    """Folder layout: a drive folder holding a log (and its boxes, no calib.txt) runs as
    ``slopedist run LOG --image-topic`` with the log's camera_info."""
    from slopedist.io.rosbag_write import LogTopics

    folder = tmp_path / "drives" / "monday"
    folder.mkdir(parents=True)
    shutil.copy(log_fleet.root / "sim.bag", folder / "monday.bag")
    shutil.copy(log_fleet.root / "sim" / "boxes.csv", folder / "boxes.csv")
    out, topic = tmp_path / "out", LogTopics().image
    args = ["batch", str(tmp_path / "drives"), "--out", str(out), "--quiet", "--no-parquet"]
    assert main([*args, "--method", "paper"]) == 2  # a log needs its image topic
    assert main([*args, "--method", "paper", "--image-topic", topic]) == 0
    alone = tmp_path / "alone"
    run = ["run", str(folder / "monday.bag"), "--image-topic", topic, "--method", "paper"]
    assert main([*run, "--boxes", str(folder / "boxes.csv"), "--out", str(alone), "--quiet"]) == 0
    records = (out / "monday" / "records.csv").read_bytes()
    assert records == (alone / "records.csv").read_bytes() and records.count(b"\n") > 1


def test_the_embedded_ray_instance_gets_the_usable_cores(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without --workers, the embedded instance has the cores this process may use (a
    container's or taskset's limit), not the machine's count."""
    from slopedist.batch import engine

    calls: list[dict[str, Any]] = []

    class FakeRay:
        def is_initialized(self) -> bool:
            return False

        def init(self, **kwargs: Any) -> None:
            calls.append(kwargs)

        def shutdown(self) -> None:
            pass

    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setattr(engine, "import_ray", lambda purpose="": FakeRay())
    monkeypatch.setattr(engine, "usable_cores", lambda: 3)
    for workers, cpus in ((None, 3), (5, 5)):
        with engine.ray_session(workers, None):
            pass
        assert calls.pop()["num_cpus"] == cpus


def test_an_output_folder_holding_a_drive_input_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--out`` at the folder of the drives would replace each drive's folder (its frames,
    calibration and boxes) by the drive's outputs: refused before anything runs."""
    drives = tmp_path / "drives"
    simulate("ego_crest", drives / "crest", frames=2)
    before = sorted(p.name for p in (drives / "crest").iterdir())
    capsys.readouterr()
    assert main(["batch", str(drives), "--out", str(drives), "--quiet", "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("slopedist: error: the output ") and "of drive 'crest'" in err
    assert len(err.splitlines()) == 1
    assert sorted(p.name for p in (drives / "crest").iterdir()) == before


def test_an_output_folder_inside_a_drive_frame_folder_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--out`` inside a drive's image folder: the batch's files would change that drive's
    input stamp, so it would never be skipped as complete (and the frames folder would fill
    with outputs). Refused before anything is made."""
    drives = tmp_path / "drives"
    simulate("ego_crest", drives / "crest", frames=2)
    frames = drives / "crest" / "image_02"
    before = sorted(p.name for p in frames.iterdir())
    capsys.readouterr()
    out = frames / "out"
    assert main(["batch", str(drives), "--out", str(out), "--quiet", "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("slopedist: error: the output ") and "of drive 'crest'" in err
    assert len(err.splitlines()) == 1
    assert sorted(p.name for p in frames.iterdir()) == before


def test_a_second_batch_into_a_running_batchs_output_is_refused(tmp_path: Path) -> None:
    """Two batches into one OUT: the second would remove the first's running drives as
    leftovers (and a drive failing there deletes its folder); it stops before touching OUT."""
    out = tmp_path / "out"
    running = out / ".tmp-d1-12345678"  # a drive of the first batch, running
    running.mkdir(parents=True)
    held = r"another slopedist batch \(process \d+\)"
    with output_lock(out), pytest.raises(ConfigurationError, match=held):
        run_batch([], out, BatchOptions(progress=False, parquet=False))
    assert running.is_dir()
    run_batch([], out, BatchOptions(progress=False, parquet=False))  # once the first has ended
    assert not running.exists()
