"""The batch on a local Ray instance with 2 CPUs: records identical to running each drive
alone, a corrupt drive isolated, a killed worker retried, a second run that skips complete
drives and redoes a deleted one. Ray starts once for the session (``ray_instance`` of
tests/conftest.py)."""

from __future__ import annotations

import csv
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from slopedist.batch import BatchOptions, BatchResult, DriveStatus, load_drives, run_batch
from slopedist.batch.drive import CRASH_ENV
from slopedist.batch.engine import import_ray, kept_signal_handlers
from slopedist.cli import main
from slopedist.errors import OptionalDependencyError

from .conftest import real_drive, run_alone, simulate

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
    assert not [p for p in fleet.out.iterdir() if p.name.startswith(".")]


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
    from slopedist.report import ReportOptions, SourceKind, report_data, write_report

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
