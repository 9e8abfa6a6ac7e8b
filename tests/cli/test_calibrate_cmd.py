"""``slopedist calibrate`` and ``estimate --method ours`` on a simulated sequence."""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from slopedist.cli import main
from slopedist.cli.calibrate_cmd import advice_text
from slopedist.core.camera import KITTI_CAMERA_HEIGHT_M, Camera
from slopedist.estimators.ours import EXTRA_COLUMNS
from slopedist.estimators.ours.selfcal import Calibration, uncalibrated_warning
from slopedist.streaming.mount_calibration import judge_mount
from slopedist.streaming.step import METHOD_TRACK_COLUMN
from slopedist.synthetic.traffic import simulate_traffic

F, CX, CY = 721.5, 609.6, 172.9


@pytest.fixture
def simulated(tmp_path: Path) -> dict[str, Path]:
    """150 frames of 10 cars seen by a camera at rest, 1.65 m high, θ0 = 0."""
    sim = simulate_traffic(Camera(F, CX, CY, 1.65, 0.0), 10, 150, seed=3)
    calib = tmp_path / "calib.txt"
    calib.write_text(f"P2: {F} 0 {CX} 0 0 {F} {CY} 0 0 0 1 0\n")
    poses = tmp_path / "poses.txt"
    poses.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n" * len(sim.timestamps_s))
    boxes = tmp_path / "boxes.csv"
    with boxes.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["frame", "left", "top", "right", "bottom", "track_id", "score", "class"])
        for k, b, tid in zip(sim.boxes.frame, sim.boxes.boxes, sim.boxes.track_id):
            w.writerow([k, *(f"{v:.3f}" for v in b), tid, "", "Car"])
    return {"calib": calib, "poses": poses, "boxes": boxes}


def _args(paths: dict[str, Path]) -> list[str]:
    return [
        "--calib",
        str(paths["calib"]),
        "--poses",
        str(paths["poses"]),
        "--boxes",
        str(paths["boxes"]),
    ]


def test_calibrate_recovers_a_wrong_calibration(
    simulated: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "cal.json"
    code = main(
        [
            "calibrate",
            *_args(simulated),
            "--height",
            "1.815",
            "--mount-angle",
            "1",
            "--json",
            str(out),
        ]
    )
    assert code == 0
    text = capsys.readouterr().out
    # 15 s of 10 cars: the estimate finds the truth, but not 5σ from the configured mount
    # (ADVISE_Z), so the advice is to keep it, with the reason
    assert "within 5σ" in text and "no advice: keep the configured mount" in text
    final = json.loads(out.read_text())["final"]
    assert final["mount_angle_deg"] == pytest.approx(0.0, abs=0.3)
    assert final["height_m"] == pytest.approx(1.65, rel=0.05)
    assert 0.07 <= final["height_sigma_m"] < 0.15 and final["n_tracks"] >= 5  # total 1σ ≥ floor


def test_json_final_holds_the_1_sigma_the_text_gives(
    simulated: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """``final`` in ``--json`` is the estimate with the total 1σ the text prints (fit, spread,
    vehicles and floor), not the fit's alone (0.03 m against ± 0.10 m on kitti_raw_lead)."""
    out = tmp_path / "cal.json"
    assert main(["calibrate", *_args(simulated), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    data = json.loads(out.read_text())
    final, total = data["final"], data["advice"]["sigma"]["total"]
    assert final["mount_angle_sigma_deg"] == total["mount_angle_deg"]
    assert final["height_sigma_m"] == total["height_m"]
    assert f"± {final['mount_angle_sigma_deg']:.2f}°" in text
    assert f"h = {final['height_m']:.3f} m ± {final['height_sigma_m']:.3f} m" in text


def test_calibrate_without_boxes_is_a_user_error(
    simulated: dict[str, Path], capsys: pytest.CaptureFixture
) -> None:
    simulated["boxes"].write_text("frame,left,top,right,bottom\n")
    assert main(["calibrate", *_args(simulated)]) == 2
    err = capsys.readouterr().err
    assert "no boxes" in err and "Traceback" not in err


@pytest.mark.parametrize("name", ["calib", "poses", "boxes"])
def test_json_that_is_an_input_is_refused(
    simulated: dict[str, Path], capsys: pytest.CaptureFixture, name: str
) -> None:
    """`--json calib.txt` replaced the calibration (any input file) with the estimate."""
    before = simulated[name].read_text()
    assert main(["calibrate", *_args(simulated), "--json", str(simulated[name])]) == 2
    assert "would be overwritten" in capsys.readouterr().err
    assert simulated[name].read_text() == before


def test_estimate_with_ours_writes_the_gap_by_default_and_centre_on_request(
    simulated: dict[str, Path], tmp_path: Path
) -> None:
    out = tmp_path / "records.csv"
    args = ["estimate", *_args(simulated), "--method", "ours"]
    assert main([*args, "--reference", "centre", "--out", str(out), "--columns", "all"]) == 0
    rows = list(csv.DictReader(out.open()))
    named = {METHOD_TRACK_COLUMN if c == "track_uid" else c for c in EXTRA_COLUMNS}
    assert rows and named <= set(rows[0])
    assert {r["reference"] for r in rows} == {"centre"}
    assert all(r["status"] == "ok" for r in rows)
    late = [r for r in rows if int(r["frame"]) > 20]
    assert sum(1 for r in late if r["speed_mps"] != "") > 0.9 * len(late)
    assert all(math.isfinite(float(r["distance_nearest_face_m"])) for r in rows)
    face = tmp_path / "face.csv"
    assert main([*args, "--out", str(face), "--columns", "all"]) == 0  # the gap by default
    face_rows = list(csv.DictReader(face.open()))
    assert {r["reference"] for r in face_rows} == {"nearest_face"}
    for r, f in zip(rows, face_rows):
        assert float(f["distance_m"]) == pytest.approx(float(r["distance_nearest_face_m"]))
        assert float(f["distance_centre_m"]) == pytest.approx(float(r["distance_m"]))


def test_calibrate_with_intrinsics_flags_equals_the_calibration_file(
    simulated: dict[str, Path], tmp_path: Path
) -> None:
    outs = []
    for form in (
        ["--calib", str(simulated["calib"])],
        ["--fx", str(F), "--fy", str(F), "--cx", str(CX), "--cy", str(CY)],
    ):
        out = tmp_path / f"cal{len(outs)}.json"
        args = ["--poses", str(simulated["poses"]), "--boxes", str(simulated["boxes"])]
        assert main(["calibrate", *form, *args, "--json", str(out)]) == 0
        outs.append(json.loads(out.read_text())["final"])
    assert outs[0] == outs[1]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--fx", "700"], "not both"),
        (["--cy", "200"], "not both"),
    ],
)
def test_calib_and_intrinsics_flags_are_exclusive(
    simulated: dict[str, Path], extra: list[str], message: str, capsys: pytest.CaptureFixture
) -> None:
    assert main(["calibrate", *_args(simulated), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        ([], "give the camera calibration"),
        (["--fx", "700", "--fy", "700", "--cx", "300"], "missing --cy"),
        (["--fx", "-700", "--fy", "700", "--cx", "300", "--cy", "200"], "focal lengths"),
        (["--fx", "700", "--fy", "nan", "--cx", "300", "--cy", "200"], "finite"),
    ],
)
def test_intrinsics_flags_errors_name_the_options(
    simulated: dict[str, Path], flags: list[str], message: str, capsys: pytest.CaptureFixture
) -> None:
    args = ["--poses", str(simulated["poses"]), "--boxes", str(simulated["boxes"])]
    assert main(["calibrate", *flags, *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_calibrate_needs_frames_or_poses(
    simulated: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    calib = ["--calib", str(simulated["calib"])]
    assert main(["calibrate", *calib, "--boxes", str(simulated["boxes"])]) == 2
    assert "give FRAMES" in capsys.readouterr().err
    frames = tmp_path / "frames"
    frames.mkdir()
    assert main(["calibrate", str(frames), *_args(simulated)]) == 2
    assert "leave out --poses" in capsys.readouterr().err


@pytest.mark.parametrize(("height", "mount_deg"), [(1.65, 0.0), (1.45, 1.0)])
def test_calibrate_from_real_frames_alone(
    kitti_raw_lead_dir: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
    height: float,
    mount_deg: float,
) -> None:
    """``calibrate FRAMES`` on the 78 KITTI raw frames with LiDAR-cluster boxes: the built-in
    odometry gives the rotations (no pose file). Those boxes are clusters of everything on the
    road (trucks, the lead car's roof over another car, hedges) called ``Car``: 12 % of them
    have a shape no car gives, and their size cue puts the camera at about 1.2 m (truth ≈
    1.65 m). Configured right or wrong, the advice must never be a height outside the truth ±
    its own σ: here it declines, saying why."""
    from slopedist.io.detections.writers import write_box_csv
    from slopedist.io.kitti.raw import KittiRawDrive

    drive = KittiRawDrive.open(kitti_raw_lead_dir)
    boxes = write_box_csv(drive.lidar_boxes((1242, 375)), tmp_path / "lidar_boxes.csv")
    out = tmp_path / "cal.json"
    args = ["--calib", str(drive.calib_path), "--boxes", str(boxes), "--json", str(out)]
    args += ["--height", str(height), "--mount-angle", str(mount_deg)]
    assert main(["calibrate", str(drive.image_dir), *args]) == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    assert "1σ parts: fit" in text and "do not fit their classes" in text
    advice = json.loads(out.read_text())["advice"]
    assert advice["estimate"]["n_tracks"] >= 8 and len(advice["segments"]) == 3
    sigma = advice["sigma"]
    assert sigma["total"]["height_m"] >= max(sigma["fit"]["height_m"], sigma["floor"]["height_m"])
    assert advice["shape_outlier_share"] > 0.06
    used_h = advice["use"]["height_m"]
    if advice["advise"]["height"] or advice["advise"]["mount_angle"]:
        assert abs(used_h - KITTI_CAMERA_HEIGHT_M) <= sigma["total"]["height_m"]
    else:
        assert used_h == height and "no advice: keep the configured mount" in text
    history = json.loads(out.read_text())["history"]
    assert history[-1]["t_s"] == pytest.approx(7.7)


def test_calibrate_frames_with_a_detector(
    kitti_raw_lead_dir: Path,
    tmp_path: Path,
    constant_model: Callable[..., Path],
    capsys: pytest.CaptureFixture,
) -> None:
    """``calibrate FRAMES --detector``: a test-built YOLOv8-layout model that sees one car in
    every frame; one vehicle cannot calibrate a mount, so the command runs and declines."""
    output = np.zeros((1, 84, 100), np.float32)
    output[0, :4, 0] = (160.0, 170.0, 40.0, 30.0)  # centre x, y, width, height (input pixels)
    output[0, 4 + 2, 0] = 0.9  # COCO class 2: car
    model = constant_model(tmp_path / "yolo.onnx", {"output0": output})
    calib = str(kitti_raw_lead_dir / "calib.txt")
    frames = str(kitti_raw_lead_dir / "image_02")
    assert main(["calibrate", frames, "--calib", calib, "--detector", str(model)]) == 0
    text = capsys.readouterr().out
    assert "too little data" in text and "no advice: keep the configured mount" in text


def test_calibrate_frames_checks_the_calibrations_image_size_against_the_frames(
    kitti_raw_lead_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """``calibrate FRAMES`` takes the frames' size as ``run`` does: a calibration made for
    1280×720 images used on the 1242×375 frames is one error naming both sizes."""
    calib = tmp_path / "camera_info.yaml"
    calib.write_text(
        "image_width: 1280\nimage_height: 720\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
        "  data: [721.5, 0.0, 609.6, 0.0, 721.5, 172.9, 0.0, 0.0, 1.0]\n"
    )
    boxes = tmp_path / "boxes.csv"
    boxes.write_text("frame,left,top,right,bottom\n0,600,180,660,220\n")
    frames = str(kitti_raw_lead_dir / "image_02")
    assert main(["calibrate", frames, "--calib", str(calib), "--boxes", str(boxes)]) == 2
    err = capsys.readouterr().err
    assert "1280" in err and "1242" in err and "Traceback" not in err


def test_advice_text_says_which_sigma_parts_were_not_measured() -> None:
    # one frame of two vehicles: one stretch saw targets and the jackknife needs three
    # vehicles; their zeros are no evidence of a small error and are not printed as 0.00°
    def cal(n_obs: int, n_tracks: int) -> Calibration:
        return Calibration(0.01, 0.005, 1.6, 0.1, 0.0, n_obs, n_tracks)

    empty = cal(0, 0)
    advice = judge_mount(cal(6, 2), [cal(6, 2), empty, empty], cal(0, 0))
    parts = next(line for line in advice_text(advice).splitlines() if "1σ parts" in line)
    assert "spread of 3 stretches not measured (targets in 1 of them)" in parts
    assert "leave-one-vehicle-out not measured (2 vehicles)" in parts
    assert "fit 0.29°, 0.100 m" in parts and "0.00°" not in parts
    whole = judge_mount(cal(600, 20), [cal(200, 8), cal(200, 8), cal(200, 8)], cal(0, 0))
    assert "not measured" not in advice_text(whole)


def test_estimate_is_quiet_when_selfcal_calibrated(
    simulated: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`estimate --method ours-selfcal` warns only when it never calibrated."""
    out = tmp_path / "records.csv"
    assert main(["estimate", *_args(simulated), "--method", "ours-selfcal", "--out", str(out)]) == 0
    assert "did not self-calibrate" not in capsys.readouterr().err


def test_uncalibrated_warning_names_the_cause() -> None:
    """No frame with θ, or frames with θ but no usable target: the calib_* columns are the
    configured values, and the warning says which."""
    cal = Calibration(0.0, 0.02, 1.65, 0.2, 0.0, 0, 0)
    assert "no frame had a measured rotation" in str(uncalibrated_warning("ours-selfcal", cal))
    seen = uncalibrated_warning("ours-selfcal", replace(cal, n_frames=7))
    assert "none of the 7 frames with a measured rotation had a usable target" in str(seen)
    assert uncalibrated_warning("ours-selfcal", replace(cal, n_observations=3)) is None


def test_estimate_warns_of_frames_further_apart_than_the_lookback(
    simulated: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`--frame-period 3`: every θ looks back one 3 s step, not the 1 s look-back; said once."""
    out = tmp_path / "records.csv"
    args = ["estimate", *_args(simulated), "--method", "paper", "--out", str(out)]
    assert main([*args, "--frame-period", "3"]) == 0
    err = capsys.readouterr().err
    assert "a median 3 s apart, longer than the 1 s look-back" in err and "--lookback" in err
    assert main(args) == 0
    assert "look-back" not in capsys.readouterr().err
