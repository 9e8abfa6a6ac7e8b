"""The command line: eval and estimate, and user mistakes ending in exit code 2."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from slopedist.cli import main

P2 = "721.5 0 609.6 44.9 0 721.5 172.9 0.2 0 0 1 0.003"


@pytest.fixture
def small_sequence(tmp_path: Path) -> dict[str, Path]:
    calib = tmp_path / "calib.txt"
    calib.write_text(f"P2: {P2}\n")
    poses = tmp_path / "poses.txt"
    poses.write_text("".join(f"1 0 0 0 0 1 0 0 0 0 1 {k:.1f}\n" for k in range(5)))
    boxes = tmp_path / "boxes.csv"
    boxes.write_text(
        "frame,left,top,right,bottom,track_id\n0,500,150,600,250,7\n"
        "3,500,40,600,90,7\n4,10,20,5,30,8\n"
    )
    return {"calib": calib, "poses": poses, "boxes": boxes}


def test_estimate_writes_records(small_sequence: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "out" / "records.csv"
    code = main(
        [
            "estimate",
            "--calib",
            str(small_sequence["calib"]),
            "--poses",
            str(small_sequence["poses"]),
            "--boxes",
            str(small_sequence["boxes"]),
            "--method",
            "paper",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    rows = list(csv.DictReader(out.open()))
    assert [r["frame"] for r in rows] == ["0", "3", "4"]
    assert float(rows[0]["distance_m"]) == pytest.approx(721.5 * 1.65 / (250 - 172.9), rel=1e-5)
    assert rows[0]["track_id"] == "7" and rows[0]["status"] == "ok"
    assert rows[1]["status"] == "missing" and rows[1]["reason"] == "below_horizon"
    assert rows[2]["reason"] == "inverted_box"


def test_estimate_to_stdout(small_sequence: dict[str, Path], capsys: pytest.CaptureFixture) -> None:
    assert (
        main(
            [
                "estimate",
                "--calib",
                str(small_sequence["calib"]),
                "--poses",
                str(small_sequence["poses"]),
                "--boxes",
                str(small_sequence["boxes"]),
            ]
        )
        == 0
    )
    assert capsys.readouterr().out.startswith("frame,timestamp_s")


def test_poses_not_covering_boxes(
    small_sequence: dict[str, Path], capsys: pytest.CaptureFixture
) -> None:
    small_sequence["poses"].write_text("1 0 0 0 0 1 0 0 0 0 1 0\n")
    code = main(
        [
            "estimate",
            "--calib",
            str(small_sequence["calib"]),
            "--poses",
            str(small_sequence["poses"]),
            "--boxes",
            str(small_sequence["boxes"]),
        ]
    )
    assert code == 2
    err = capsys.readouterr().err
    assert "1 poses do not cover" in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("which", "content", "message"),
    [
        ("calib", "P2: 1 2 x 4 5 6 7 8 9 10 11 12\n", "line 1, field 'P2[2]'"),
        ("poses", "1 0 0 0 0 1 0 0 0 0 1\n", "line 1: expected 12 numbers"),
        ("boxes", "frame,left,top,right,bottom\n0,1,2,3\n", "line 2, field 'bottom'"),
    ],
)
def test_malformed_inputs_exit_2(
    small_sequence: dict[str, Path],
    capsys: pytest.CaptureFixture,
    which: str,
    content: str,
    message: str,
) -> None:
    small_sequence[which].write_text(content)
    code = main(
        [
            "estimate",
            "--calib",
            str(small_sequence["calib"]),
            "--poses",
            str(small_sequence["poses"]),
            "--boxes",
            str(small_sequence["boxes"]),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and message in err and str(small_sequence[which]) in err


def test_unknown_method_is_a_usage_error(small_sequence: dict[str, Path]) -> None:
    assert (
        main(
            [
                "estimate",
                "--calib",
                str(small_sequence["calib"]),
                "--poses",
                str(small_sequence["poses"]),
                "--boxes",
                str(small_sequence["boxes"]),
                "--method",
                "magic",
            ]
        )
        == 2
    )


def test_eval_missing_data_dir(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["eval", "kitti-tracking", str(tmp_path / "none")]) == 2
    assert "no KITTI tracking data" in capsys.readouterr().err


def test_eval_json_shape(
    kitti_tracking_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "r.json"
    code = main(
        [
            "eval",
            "kitti-tracking",
            str(kitti_tracking_dir),
            "--sequences",
            "0000,0004",
            "--methods",
            "flat,paper",
            "--json",
            str(out),
        ]
    )
    assert code == 0
    report = json.loads(out.read_text())
    assert set(report) == {"protocol", "methods"}
    seq = report["methods"]["paper"]["sequences"]["0004"]
    for key in ("n", "rmse", "mae", "abs_rel", "delta_1.25"):
        assert key in seq and key in report["methods"]["paper"]["overall"]
    pooled_n = sum(report["methods"]["flat"]["sequences"][s]["n"] for s in ("0000", "0004"))
    assert report["methods"]["flat"]["overall"]["n"] == pooled_n
    printed = capsys.readouterr().out
    assert "overall" in printed and "0004" in printed
    assert np.isfinite(seq["rmse"])


def _estimate_rows(paths: dict[str, Path], out: Path, *options: str) -> list[dict[str, str]]:
    args = ["estimate", "--calib", str(paths["calib"]), "--poses", str(paths["poses"])]
    assert main([*args, "--boxes", str(paths["boxes"]), "--out", str(out), *options]) == 0
    return list(csv.DictReader(out.open()))


def _all_columns(paths: dict[str, Path], out: Path, *options: str) -> list[dict[str, str]]:
    """:func:`_estimate_rows` with every column (``--columns all``)."""
    return _estimate_rows(paths, out, *options, "--columns", "all")


def test_estimate_applies_the_eq7_options_to_every_method_built_on_paper(
    small_sequence: dict[str, Path], tmp_path: Path
) -> None:
    """``--alphas``/``--thresholds`` reach ``imu`` (the paper's method on IMU rotations) as they
    do in ``eval``, not only ``paper``."""
    small_sequence["boxes"].write_text(
        "frame,left,top,right,bottom,track_id\n0,500,120,600,200,1\n1,300,150,420,260,2\n"
    )
    default = _all_columns(small_sequence, tmp_path / "d.csv", "--method", "imu")
    steep = ("--alphas", "20,30,40")
    imu = _all_columns(small_sequence, tmp_path / "i.csv", "--method", "imu", *steep)
    paper = _all_columns(small_sequence, tmp_path / "p.csv", "--method", "paper", *steep)
    # box 0: centre 12.9 px above the vanishing line (θ = 0): α2 applies
    assert float(default[0]["theta_adj_deg"]) == pytest.approx(5.0)
    assert float(imu[0]["theta_adj_deg"]) == pytest.approx(30.0)
    assert imu[0]["distance_m"] != default[0]["distance_m"]
    assert [(r["theta_adj_deg"], r["distance_m"]) for r in imu] == [
        (r["theta_adj_deg"], r["distance_m"]) for r in paper
    ]


def test_estimate_an_offline_method(small_sequence: dict[str, Path], tmp_path: Path) -> None:
    """``ours-offline`` writes its (offline) records once the sequence has ended, in order."""
    args = ["estimate", "--calib", str(small_sequence["calib"]), "--poses"]
    args += [str(small_sequence["poses"]), "--boxes", str(small_sequence["boxes"]), "--out"]
    rows = {}
    for method in ("ours", "ours-offline"):
        out = tmp_path / f"{method}.csv"
        assert main([*args, str(out), "--method", method, "--columns", "all"]) == 0
        rows[method] = list(csv.DictReader(out.open()))
    assert [r["frame"] for r in rows["ours-offline"]] == [r["frame"] for r in rows["ours"]]
    assert {r["method"] for r in rows["ours-offline"]} == {"ours-offline"}
    assert rows["ours-offline"][2]["reason"] == "inverted_box"
    assert rows["ours-offline"][0]["size_scale"] != ""


def test_ours_options_reach_ours_from_the_command_line(
    small_sequence: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """``--ours-option KEY=VALUE`` sets options of ``ours`` (``size_learning=true`` fills
    the size columns, ``use_width=false`` changes the distances); a bad key or value is one
    usage error naming the option, and nothing is written."""
    default = _all_columns(small_sequence, tmp_path / "d.csv", "--method", "ours")
    learned = _all_columns(
        small_sequence,
        tmp_path / "l.csv",
        "--method",
        "ours",
        "--ours-option",
        "size_learning=true",
        "--ours-option",
        "use_width=false",
    )
    assert all(r["size_scale"] == "" for r in default)
    assert any(r["size_scale"] != "" for r in learned)
    assert [r["distance_m"] for r in learned] != [r["distance_m"] for r in default]
    args = ["estimate", "--calib", str(small_sequence["calib"]), "--poses"]
    args += [str(small_sequence["poses"]), "--boxes", str(small_sequence["boxes"])]
    for bad, message in (
        ("bogus=1", "'bogus' is not an ours option"),
        ("min_iou=2", "min_iou must be in [0, 1]"),
        ("use_width=maybe", "'maybe' is not a bool"),
        ("size_learning", "is not KEY=VALUE"),
    ):
        out = tmp_path / "bad.csv"
        assert main([*args, "--out", str(out), "--ours-option", bad]) == 2
        err = capsys.readouterr().err
        assert "--ours-option" in err and message in err and "Traceback" not in err
        assert not out.exists()


def test_estimate_depthmap_without_depth_is_refused(
    small_sequence: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """estimate takes no depth maps: `--method depthmap` wrote every box as missing, no_depth,
    with exit code 0."""
    out = tmp_path / "records.csv"
    args = ["--poses", str(small_sequence["poses"]), "--boxes", str(small_sequence["boxes"])]
    args += ["--method", "depthmap", "--out", str(out)]
    code = main(["estimate", "--calib", str(small_sequence["calib"]), *args])
    err = capsys.readouterr().err
    assert code == 2 and "method 'depthmap' needs depth maps" in err and "--depth-dir" in err
    assert not out.exists()


@pytest.mark.parametrize("method", ["flat", "ego", "paper", "ours", "ours-offline"])
def test_estimate_gives_no_ok_distance_to_a_one_pixel_box(
    small_sequence: dict[str, Path], tmp_path: Path, method: str
) -> None:
    """A 1 px box 4 rows below the horizon (eq. 1: 1190/4 ≈ 300 m; ``ours``' size cue over
    1000 m) is ``missing``, ``beyond_resolution``; a 40 px car beside it keeps its distance."""
    boxes = tmp_path / "tiny.csv"
    boxes.write_text(
        "frame,left,top,right,bottom,track_id\n"
        + "".join(f"{k},300,175.9,301,176.9,1\n{k},500,150,560,190,2\n" for k in range(5))
    )
    out = tmp_path / "records.csv"
    args = ["estimate", "--calib", str(small_sequence["calib"]), "--poses"]
    args += [str(small_sequence["poses"]), "--boxes", str(boxes), "--method", method]
    assert main([*args, "--image-size", "1242x375", "--out", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    tiny = [r for r in rows if r["track_id"] == "1"]
    car = [r for r in rows if r["track_id"] == "2"]
    assert {(r["status"], r["reason"], r["distance_m"]) for r in tiny} == {
        ("missing", "beyond_resolution", "")
    }
    assert all(r["status"] == "ok" and float(r["distance_m"]) < 100 for r in car)


@pytest.mark.parametrize("command", ["estimate", "calibrate"])
def test_a_tum_pose_file_at_another_rate_than_the_frame_period_given_is_refused(
    small_sequence: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture, command: str
) -> None:
    """TUM poses are timed by their own column: at 20 Hz with frames at 10 Hz
    (``--frame-period 0.1`` given) every frame took the pose of half its time, silently."""
    tum = tmp_path / "poses_20hz.tum"
    tum.write_text("".join(f"{100 + 0.05 * k:.2f} 0 0 {k} 0 0 0 1\n" for k in range(10)))
    args = [command, "--calib", str(small_sequence["calib"]), "--poses", str(tum)]
    args += ["--boxes", str(small_sequence["boxes"]), "--image-size", "1242x375"]
    if command == "estimate":
        args += ["--out", str(tmp_path / "records.csv")]
    assert main([*args, "--frame-period", "0.1"]) == 2
    message = capsys.readouterr().err
    assert str(tum) in message and "--frame-period 0.1 s" in message
    assert "frame 1's pose is at 100.050000 s, 0.05 s after frame 0's" in message
    assert not (tmp_path / "records.csv").exists()
    # poses at the frame period given are accepted
    tum.write_text("".join(f"{100 + 0.1 * k:.2f} 0 0 {k} 0 0 0 1\n" for k in range(10)))
    assert main([*args, "--frame-period", "0.1"]) == 0


@pytest.mark.parametrize("command", ["estimate", "calibrate"])
def test_tum_poses_a_little_off_the_frame_period_given_are_accepted_over_a_long_drive(
    small_sequence: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture, command: str
) -> None:
    """A camera at 0.104 s per frame for a nominal ``--frame-period 0.1``: each pose is its
    frame's; compared with ``k × 0.1`` the 4 ms added up to half a period by frame 13 and the
    drive was refused. A missing pose (a step of two periods) still is."""
    tum = tmp_path / "poses.tum"
    times = 100 + 0.104 * np.arange(300)
    tum.write_text("".join(f"{t:.6f} 0 0 {k} 0 0 0 1\n" for k, t in enumerate(times)))
    args = [command, "--calib", str(small_sequence["calib"]), "--poses", str(tum)]
    args += ["--boxes", str(small_sequence["boxes"]), "--image-size", "1242x375"]
    if command == "estimate":
        args += ["--out", str(tmp_path / "records.csv")]
    assert main([*args, "--frame-period", "0.1"]) == 0
    gap = np.delete(times, 5)
    tum.write_text("".join(f"{t:.6f} 0 0 {k} 0 0 0 1\n" for k, t in enumerate(gap)))
    assert main([*args, "--frame-period", "0.1"]) == 2
    assert "frame 5's pose is at 100.624000 s, 0.208 s after frame 4's" in capsys.readouterr().err


@pytest.mark.parametrize("c_y", ["-1", "0", "1e-320"])
@pytest.mark.parametrize("command", ["estimate", "calibrate"])
def test_a_principal_point_that_fits_no_image_is_refused_without_an_image_size(
    small_sequence: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    c_y: str,
    command: str,
) -> None:
    """c_y = −1, 0 or 1e-320 gave every row ``ok`` at 4.07 m where the truth was 9.96 m
    (``run`` and ``--image-size`` refused it): no image has its principal point there."""
    calib = tmp_path / "calib.txt"
    calib.write_text(f"P2: {P2.replace('172.9', c_y)}\n")
    args = [command, "--calib", str(calib), "--poses", str(small_sequence["poses"])]
    args += ["--boxes", str(small_sequence["boxes"])]
    if command == "estimate":
        args += ["--out", str(tmp_path / "r.csv")]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"slopedist: error: {calib}: principal point c_y = ")
    assert "fits only images under a pixel" in err or "top edge of any image" in err
    assert not (tmp_path / "r.csv").exists()


@pytest.mark.parametrize("method", ["flat", "paper", "ours"])
def test_a_box_beyond_every_image_the_calibration_fits_is_outside_the_image(
    small_sequence: dict[str, Path], tmp_path: Path, method: str
) -> None:
    """Without --image-size a box at (5000, 5000, 5100, 5100) was ``ok`` at 0.24 m and one at
    x −900…−800 ``ok`` at 9.36 m: with c_x = 609.6 and c_y = 172.9 px no image is wider than
    1742 px or taller than 692 px, and none has pixels left of 0."""
    boxes = tmp_path / "far.csv"
    boxes.write_text(
        "frame,left,top,right,bottom,track_id\n0,5000,5000,5100,5100,1\n1,-900,170,-800,230,2\n"
        "2,500,150,600,250,3\n3,1650,150,1750,250,4\n"
    )
    out = tmp_path / "records.csv"
    args = ["estimate", "--calib", str(small_sequence["calib"]), "--poses"]
    args += [str(small_sequence["poses"]), "--boxes", str(boxes), "--method", method]
    assert main([*args, "--out", str(out)]) == 0
    rows = {r["track_id"]: r for r in csv.DictReader(out.open())}
    for far in ("1", "2"):
        assert (rows[far]["status"], rows[far]["reason"]) == ("missing", "outside_image")
        assert rows[far]["distance_m"] == ""
    assert rows["3"]["status"] == "ok"  # in the image
    assert rows["4"]["reason"] != "outside_image"  # inside the largest image c_x fits


@pytest.mark.parametrize("layout", ["orbslam3_poses", "oxts_poses"])
def test_estimate_refuses_a_shuffled_pose_file(
    kitti_tracking_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], layout: str
) -> None:
    """Sequence 0000's pose lines shuffled gave all 535 vehicle rows ``ok``, off by up to 226 %
    (ORB-SLAM3, KITTI layout) and 118 % (OXTS)."""
    lines = (kitti_tracking_dir / layout / "0000.txt").read_text().splitlines()
    order = np.r_[0, np.random.default_rng(3).permutation(len(lines) - 1) + 1]
    poses = tmp_path / "poses.txt"
    poses.write_text("".join(lines[k] + "\n" for k in order))
    args = ["estimate", "--calib", str(kitti_tracking_dir / "calib" / "0000.txt")]
    args += ["--poses", str(poses), "--boxes", str(kitti_tracking_dir / "label_02" / "0000.txt")]
    if layout == "oxts_poses":
        args += ["--pose-format", "oxts"]
    assert main([*args, "--out", str(tmp_path / "r.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"slopedist: error: {poses}, line ") and "out of order" in err
    assert not (tmp_path / "r.csv").exists()
