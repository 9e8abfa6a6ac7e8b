"""One drive of a batch, in process: same records as ``slopedist run``, atomic outputs,
stamps that see changed inputs, a corrupt drive that fails alone."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from slopedist.batch.drive import completed_stamp, process_drive, publish
from slopedist.batch.manifest import DriveSpec, spec_summary
from slopedist.batch.settings import SETTING_COLUMNS, RunSettings
from slopedist.batch.stamp import SETTINGS_KEY, STAMP_KEY, input_stamp
from slopedist.batch.status import DriveStatus
from slopedist.cli import main

from .conftest import run_alone, simulate


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    pytest.importorskip("slopedist.odometry.visual")
    return simulate("ego_crest", tmp_path_factory.mktemp("sim") / "ego_crest")


def spec_of(sim: Path, name: str = "crest", method: str = "paper", **kw: object) -> DriveSpec:
    return DriveSpec(
        name,
        sim / "image_02",
        kw.pop("calib", sim / "calib.txt"),  # type: ignore[arg-type]
        sim / "boxes.csv",
        method=method,
        timestamps=sim / "times.txt",
        **kw,  # type: ignore[arg-type]
    )


def test_a_drive_gives_the_records_of_run_alone(sim: Path, tmp_path: Path) -> None:
    spec = spec_of(sim)
    out = tmp_path / "batch"
    out.mkdir()
    outcome = process_drive(spec, out, input_stamp(spec))
    assert outcome.status is DriveStatus.DONE and outcome.attempts == 1
    assert outcome.frames == 5 and outcome.records > 0
    assert 10 < outcome.worker_peak_rss_mb < 10_000  # MB (ru_maxrss is kB on Linux)
    alone = run_alone(
        sim / "image_02",
        sim / "calib.txt",
        sim / "boxes.csv",
        "paper",
        tmp_path / "alone",
        "--timestamps",
        str(sim / "times.txt"),
    )
    assert (out / "crest" / "records.csv").read_bytes() == alone.read_bytes()
    summary = json.loads((out / "crest" / "run.json").read_text())
    assert summary["sequence"] == "crest" and summary[STAMP_KEY] == input_stamp(spec)
    assert completed_stamp(out / "crest") == input_stamp(spec)
    assert not [p for p in out.iterdir() if p.name.startswith(".tmp-")]


def test_a_distorted_calibration_gives_the_records_of_run_alone(sim: Path, tmp_path: Path) -> None:
    calib = tmp_path / "k.txt"  # the simulated camera's K with some barrel distortion
    calib.write_text("721.5377 0 609.5593\n0 721.5377 172.854\n0 0 1\n-0.05 0.01 0 0\n")
    spec = spec_of(sim, method="ego", calib=calib)
    out = tmp_path / "batch"
    out.mkdir()
    assert process_drive(spec, out, input_stamp(spec)).status is DriveStatus.DONE
    times = ["--timestamps", str(sim / "times.txt")]
    alone = run_alone(sim / "image_02", calib, sim / "boxes.csv", "ego", tmp_path / "a", *times)
    assert (out / "crest" / "records.csv").read_bytes() == alone.read_bytes()


def test_a_corrupt_drive_fails_alone_and_leaves_no_folder(sim: Path, tmp_path: Path) -> None:
    calib = tmp_path / "calib.txt"
    calib.write_text("P2: 1 2 3\n")
    out = tmp_path / "batch"
    out.mkdir()
    (out / "crest").mkdir()  # outputs of older inputs: stale once the drive fails
    spec = spec_of(sim, calib=calib)
    outcome = process_drive(spec, out, input_stamp(spec))
    assert outcome.status is DriveStatus.FAILED
    assert str(calib) in outcome.error and "\n" not in outcome.error
    assert sorted(p.name for p in out.iterdir()) == [".attempts-crest"]


def test_stamps_see_content_and_options_not_touches(sim: Path, tmp_path: Path) -> None:
    local = tmp_path / "sim"
    shutil.copytree(sim, local)
    spec = spec_of(local)
    before = input_stamp(spec)
    os.utime(local / "calib.txt", (1, 1))  # touched, same content
    assert input_stamp(spec) == before
    assert input_stamp(spec_of(local, method="flat")) != before
    assert input_stamp(spec_of(local, height_m=1.5)) != before
    for topic in ("image_topic", "rotation_topic", "speed_topic"):  # a log's topics count too
        with_topic = input_stamp(spec_of(local, **{topic: "/a"}))
        assert with_topic != before
        assert input_stamp(spec_of(local, **{topic: "/b"})) != with_topic
    no_calib = input_stamp(spec_of(local, calib=None))  # a log's camera_info instead
    assert no_calib != before and "calib" not in no_calib["inputs"]
    (local / "boxes.csv").write_text((local / "boxes.csv").read_text().replace(",1,", ",2,", 1))
    assert input_stamp(spec)["inputs"]["boxes"] != before["inputs"]["boxes"]
    sorted((local / "image_02").iterdir())[-1].unlink()
    assert input_stamp(spec)["inputs"]["frames"]["files"] == before["inputs"]["frames"]["files"] - 1


def test_publish_replaces_an_older_folder(tmp_path: Path) -> None:
    final, tmp = tmp_path / "d", tmp_path / ".tmp-d"
    final.mkdir()
    (final / "old.txt").write_text("old")
    tmp.mkdir()
    (tmp / "new.txt").write_text("new")
    publish(tmp, final)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d"]
    assert [p.name for p in final.iterdir()] == ["new.txt"]


def test_an_unfinished_run_is_not_complete(tmp_path: Path) -> None:
    folder = tmp_path / "d"
    folder.mkdir()
    assert completed_stamp(folder) is None
    (folder / "run.json").write_text('{"error": "boom", "batch_inputs": {}}')
    assert completed_stamp(folder) is None
    (folder / "run.json").write_text('{"error": null, "batch_inputs": {"a": 1}}')
    assert completed_stamp(folder) == {"a": 1}
    (folder / "run.json").write_text("{trunc")
    assert completed_stamp(folder) is None


def test_a_drive_with_a_detector_gives_the_records_of_run_alone(
    tmp_path: Path, constant_model: Callable[..., Path]
) -> None:
    pytest.importorskip("onnxruntime", reason="onnxruntime (extra 'onnx') runs the detector")
    out = np.zeros((12, 20))  # YOLOv8 [1, 4 + 8, 20] of a 320x320 input: one car
    out[:4, 0], out[4 + 2, 0] = (130, 200, 60, 40), 0.9
    model = constant_model(tmp_path / "yolo.onnx", {"output0": out[None]})
    frames = tmp_path / "frames"
    frames.mkdir()
    for i in range(3):
        cv2.imwrite(str(frames / f"{i:06d}.png"), np.full((360, 640, 3), 80 + 20 * i, np.uint8))
    calib = tmp_path / "calib.txt"
    calib.write_text("P2: 500 0 320 0 0 500 180 0 0 0 1 0\n")
    spec = DriveSpec("det", frames, calib, None, method="flat", odometry="none", detector=model)
    batch = tmp_path / "batch"
    batch.mkdir()
    outcome = process_drive(spec, batch, input_stamp(spec))
    assert outcome.status is DriveStatus.DONE, outcome.error
    alone = tmp_path / "alone"
    args = ["run", str(frames), "--calib", str(calib), "--detector", str(model), "--quiet"]
    assert main([*args, "--method", "flat", "--odometry", "none", "--out", str(alone)]) == 0
    records = (batch / "det" / "records.csv").read_bytes()
    assert records == (alone / "records.csv").read_bytes() and records.count(b"\n") == 4


def test_a_drive_with_run_settings_gives_the_outputs_of_run_alone(
    sim: Path, tmp_path: Path
) -> None:
    """Reference point, ours options, vehicle classes, offline mode, a PNG overlay, the TUM
    export and every column of a drive's settings give what ``slopedist run`` gives with the
    same options; ``run.json`` records them, with the paths of the published folder."""
    settings = RunSettings(
        reference="nearest_face",
        ours_options=(("odd_object_weight", 0.0), ("size_learning", True)),
        vehicle_classes=("Car", "Van"),
        offline=True,
        overlay=True,
        overlay_format="png",
        export=("tum",),
        columns="all",
    )
    spec = spec_of(sim, method="ours", settings=settings)
    out = tmp_path / "batch"
    out.mkdir()
    outcome = process_drive(spec, out, input_stamp(spec))
    assert outcome.status is DriveStatus.DONE, outcome.error
    options = ["--timestamps", str(sim / "times.txt"), "--reference", "nearest_face", "--offline"]
    options += ["--ours-option", "size_learning=true", "--ours-option", "odd_object_weight=0"]
    options += ["--vehicle-classes", "Car,Van", "--overlay", "--overlay-format", "png"]
    options += ["--columns", "all"]
    alone = run_alone(
        sim / "image_02",
        sim / "calib.txt",
        sim / "boxes.csv",
        "ours",
        tmp_path / "alone",
        *options,
        "--export",
        "tum",
    ).parent
    drive = out / "crest"
    for name in ("records.csv", "tracks.csv", "trajectory.tum"):
        assert (drive / name).read_bytes() == (alone / name).read_bytes(), name
    records = (drive / "records.csv").read_text().splitlines()
    header = records[0].split(",")
    rows = [dict(zip(header, line.split(","))) for line in records[1:]]
    assert {r["method"] for r in rows} == {"ours-offline"}
    ok = [r for r in rows if r["status"] == "ok"]
    assert ok and {r["reference"] for r in ok} == {"nearest_face"}
    assert all(r["distance_m"] == r["distance_nearest_face_m"] for r in ok)
    pngs = sorted(p.name for p in (drive / "overlay").iterdir())
    assert pngs == sorted(p.name for p in (alone / "overlay").iterdir()) and len(pngs) == 5
    summary = json.loads((drive / "run.json").read_text())
    assert summary[SETTINGS_KEY] == spec_summary(spec)
    assert summary[SETTINGS_KEY]["ours_options"] == {
        "odd_object_weight": 0.0,
        "size_learning": True,
    }
    assert summary[SETTINGS_KEY]["reference"] == "nearest_face"
    assert summary["out_dir"] == str(drive) and summary["overlay"] == str(drive / "overlay")
    assert summary["exports"] == [str(drive / "trajectory.tum")]


def test_stamps_see_changed_settings(sim: Path) -> None:
    """Every run setting changes the stamp; the default settings leave it as before they
    existed (a drive completed by an older batch is not run again)."""
    spec = spec_of(sim, method="ours")
    before = input_stamp(spec)
    old_form = {k: v for k, v in spec_summary(spec).items() if k not in SETTING_COLUMNS}
    digest = hashlib.sha256(json.dumps(old_form, sort_keys=True).encode()).hexdigest()
    assert before["options_sha256"] == digest
    changes = [
        RunSettings(reference="contact"),
        RunSettings(ours_options=(("use_width", False),)),
        RunSettings(ours_options=(("use_width", True),)),
        RunSettings(vehicle_classes=("Car",)),
        RunSettings(offline=True),
        RunSettings(overlay=True),
        RunSettings(overlay=True, overlay_format="png"),
        RunSettings(export=("mcap",)),
    ]
    stamps = [input_stamp(replace(spec, settings=s))["options_sha256"] for s in changes]
    assert len({before["options_sha256"], *stamps}) == len(changes) + 1
    same = replace(
        spec, settings=RunSettings(ours_options=(("use_width", False), ("gate_sigma", 4.0)))
    )
    swapped = replace(
        spec, settings=RunSettings(ours_options=(("gate_sigma", 4.0), ("use_width", False)))
    )
    assert input_stamp(same) == input_stamp(swapped)  # the options' order does not count


def test_the_rows_a_box_reader_drops_are_a_warning_of_the_batch(
    sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A drive runs in a Ray worker whose log goes nowhere: the reader's warning comes back in
    the drive's outcome, and the batch prints it with the drive's name."""
    from slopedist.batch.engine import BatchResult
    from slopedist.cli.batch_cmd import batch_summary_text
    from slopedist.io.detections.boxes import BoxTable, concat_boxes
    from slopedist.io.detections.convert import read_boxes
    from slopedist.io.detections.format_writers import write_coco

    boxes = read_boxes(sim / "boxes.csv")
    n = len(boxes)
    people = BoxTable.build(boxes.frame, boxes.boxes, boxes.track_id, classes=["Pedestrian"] * n)
    coco = tmp_path / "boxes.json"
    write_coco(concat_boxes([boxes, people]), coco, {3: "Car", 1: "Pedestrian"})
    spec = replace(spec_of(sim), boxes=coco)
    out = tmp_path / "batch"
    out.mkdir()
    outcome = process_drive(spec, out, input_stamp(spec))
    assert outcome.status is DriveStatus.DONE
    assert len(outcome.warnings) == 1 and f"dropped {n} of {2 * n} box rows" in outcome.warnings[0]
    text = batch_summary_text(BatchResult(out, [outcome], 1.0))
    assert f"warning: drive crest: {coco}: dropped {n} of {2 * n} box rows" in text
    status = (out / "crest" / "run.json").read_text()
    assert '"dropped_boxes"' in status


def test_a_failed_drive_keeps_the_warnings_its_run_logged(
    sim: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The rows a reader left out may be why a drive failed: its outcome keeps them (they were
    kept only for a drive that finished)."""
    import logging

    from slopedist.batch import drive
    from slopedist.core.errors import InputFileError

    def warn_then_fail(*args: object) -> None:
        logging.getLogger("slopedist.io.detections").warning("boxes.json: dropped 9 of 10 box rows")
        raise InputFileError("boxes.json", "no box left")

    monkeypatch.setattr(drive, "run_single_drive", warn_then_fail)
    out = tmp_path / "batch"
    out.mkdir()
    spec = spec_of(sim)
    outcome = process_drive(spec, out, input_stamp(spec))
    assert outcome.status is DriveStatus.FAILED and "no box left" in outcome.error
    assert outcome.warnings == ("boxes.json: dropped 9 of 10 box rows",)
