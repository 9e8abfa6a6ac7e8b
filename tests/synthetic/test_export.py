"""``slopedist simulate``: the output folder is read back by the other commands."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from slopedist.cli import main
from slopedist.core.camera import Camera
from slopedist.io.depth.files import read_kitti_depth_png
from slopedist.io.detections.readers import read_box_csv
from slopedist.odometry.posefiles import read_kitti_poses
from slopedist.synthetic.export import SIMULATION_NAMES

FRAMES = 4


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("sim") / "run"
    assert main(["simulate", "ego_crest", "--out", str(out), "--frames", str(FRAMES)]) == 0
    return out


def test_layout_and_readers(sim: Path) -> None:
    names = {p.name for p in sim.iterdir()}
    assert {
        "scenario.toml",
        "calib.txt",
        "info.json",
        "poses.txt",
        "times.txt",
        "boxes.csv",
        "boxes_exact.csv",
        "truth.csv",
        "frames.csv",
        "image_02",
        "depth",
    } <= names
    cam = Camera.from_kitti_calib(sim / "calib.txt")
    assert (cam.f, cam.c_x, cam.c_y) == pytest.approx((721.5377, 609.5593, 172.854))
    track = read_kitti_poses(sim / "poses.txt")
    assert len(track) == FRAMES
    np.testing.assert_allclose(track.R_world_cam[0], np.eye(3), atol=1e-9)
    boxes = read_box_csv(sim / "boxes.csv")
    assert set(boxes.track_id.tolist()) <= {1, 2} and len(boxes) >= FRAMES
    info = json.loads((sim / "info.json").read_text())
    assert info["frames"] == FRAMES and info["camera_height_m"] == 1.65
    assert len(list((sim / "image_02").glob("*.png"))) == FRAMES


def test_every_csv_has_lf_line_ends(sim: Path) -> None:
    csvs = sorted(sim.glob("*.csv"))
    assert [p.name for p in csvs] == ["boxes.csv", "boxes_exact.csv", "frames.csv", "truth.csv"]
    for path in csvs:
        data = path.read_bytes()
        assert b"\r" not in data and data.endswith(b"\n"), path.name


def test_truth_matches_boxes_and_depth(sim: Path) -> None:
    rows = list(csv.DictReader((sim / "truth.csv").open()))
    assert len(rows) == 2 * FRAMES
    exact = read_box_csv(sim / "boxes_exact.csv")
    first = next(r for r in rows if r["frame"] == "0" and r["track_id"] == "1")
    row0 = np.flatnonzero((exact.frame == 0) & (exact.track_id == 1))[0]
    np.testing.assert_allclose(
        exact.boxes[row0], [float(first[k]) for k in ("left", "top", "right", "bottom")], rtol=1e-5
    )
    # the true depth at the box's bottom-centre pixel is the rear face's distance
    depth = read_kitti_depth_png(sim / "depth" / "000000.png")
    b = exact.boxes[row0]
    d = depth[int(b[3]) - 2, int(0.5 * (b[0] + b[2]))]
    assert d == pytest.approx(float(first["z_rear_m"]), abs=0.05)


def test_estimate_runs_on_the_output(sim: Path, tmp_path: Path) -> None:
    out = tmp_path / "est.csv"
    code = main(
        [
            "estimate",
            "--calib",
            str(sim / "calib.txt"),
            "--poses",
            str(sim / "poses.txt"),
            "--boxes",
            str(sim / "boxes.csv"),
            "--method",
            "paper",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    rows = list(csv.DictReader(out.open()))
    assert rows and all(r["status"] == "ok" for r in rows)


def test_user_mistakes_end_with_exit_code_2(
    tmp_path: Path, sim: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[ego]\nspeed_kmh = -3\n[[target]]\nstart_m = 1\nspeed_kmh = 1\n")
    assert main(["simulate", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "bad.toml, line 2, field 'ego.speed_kmh'" in err
    assert main(["simulate", "nope", "--out", str(tmp_path / "o")]) == 2
    assert "built-in" in capsys.readouterr().err
    assert main(["simulate", "ego_crest", "--out", str(sim)]) == 2  # would overwrite
    assert "--force" in capsys.readouterr().err


def test_list(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--list"]) == 0
    out = capsys.readouterr().out
    assert "target_steep_uphill" in out and "ego_sag" in out


def test_a_drive_folder_with_files_of_the_same_names_is_not_overwritten(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A folder of a real drive (its calib.txt, boxes.csv, frames) but no poses.txt: refused,
    naming what would be overwritten; written with --force."""
    drive = tmp_path / "drive"
    (drive / "image_02").mkdir(parents=True)
    (drive / "calib.txt").write_text("P2: 721 0 609 0 0 721 172 0 0 0 1 0\n")
    (drive / "boxes.csv").write_text("frame,left,top,right,bottom\n")
    args = ["simulate", "ego_crest", "--out", str(drive), "--frames", "1", "--depth", "none"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "already holds calib.txt, boxes.csv, image_02" in err and "--force" in err
    assert (drive / "calib.txt").read_text().startswith("P2: 721 ")
    assert not list((drive / "image_02").iterdir())
    assert main([*args, "--force"]) == 0
    assert (drive / "poses.txt").is_file()


def test_a_road_without_targets_writes_every_file_with_no_box(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    empty = tmp_path / "empty_road.toml"
    empty.write_text("duration_s = 0.3\n[ego]\nspeed_kmh = 30.0\n")
    out = tmp_path / "o"
    assert main(["simulate", str(empty), "--out", str(out)]) == 0
    assert "boxes.csv holds no box (the scenario has no [[target]])" in capsys.readouterr().out
    assert {p.name for p in out.iterdir()} == set(SIMULATION_NAMES)
    assert len(list((out / "image_02").iterdir())) == len(list((out / "depth").iterdir())) == 3
    for name in ("boxes.csv", "boxes_exact.csv", "truth.csv"):
        assert len(list(csv.DictReader((out / name).open()))) == 0, name
    assert len(list(csv.DictReader((out / "frames.csv").open()))) == 3
    assert len(read_box_csv(out / "boxes.csv")) == 0
    info = json.loads((out / "info.json").read_text())
    assert info["targets"] == [] and info["detections"] == 0 and info["frames"] == 3


def test_force_never_mixes_old_and_new_frames(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--force over a longer simulation (or another depth format) is refused: the old frames
    would stay next to the new ones; nothing is deleted."""
    out = tmp_path / "o"
    assert main(["simulate", "same_flat", "--out", str(out), "--frames", "3"]) == 0
    before = sorted(p.name for p in (out / "image_02").iterdir())
    assert main(["simulate", "same_flat", "--out", str(out), "--frames", "1", "--force"]) == 2
    err = capsys.readouterr().err
    assert f"{out / 'image_02'} holds 2 file(s)" in err and "000001.png, 000002.png" in err
    assert sorted(p.name for p in (out / "image_02").iterdir()) == before
    assert len((out / "poses.txt").read_text().splitlines()) == 3  # nothing was rewritten
    args = ["simulate", "same_flat", "--out", str(out), "--frames", "3", "--force"]
    assert main([*args, "--depth", "npy"]) == 2
    assert f"{out / 'depth'} holds 3 file(s)" in capsys.readouterr().err
    assert main(args) == 0  # the same frames again: every file replaced
