"""``slopedist run`` options: depth maps from files and from an ONNX model, the look-back of the
built-in odometry, the sequence name, no odometry."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from slopedist.cli import main
from slopedist.core.camera import Camera
from slopedist.io.depth import write_kitti_depth_png
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.writers import write_box_csv
from slopedist.streaming import pipeline as pipeline_module
from slopedist.streaming.step import DEFAULT_RECORD_FIELDS, METHOD_TRACK_COLUMN

W, H = 320, 200
CALIB = "P2: 500 0 160 0 0 500 100 0 0 0 1 0\n"
BOX = (100.0, 110.0, 150.0, 150.0)


def setup(tmp_path: Path, n: int = 4, truth: bool = False) -> list[str]:
    """Frames of uniform grey ``40 + 10k``, one box per frame; the common arguments."""
    frames = tmp_path / "frames"
    frames.mkdir()
    for k in range(n):
        cv2.imwrite(str(frames / f"{k:06d}.png"), np.full((H, W, 3), 40 + 10 * k, np.uint8))
    (tmp_path / "calib.txt").write_text(CALIB)
    extra = {"gt_distance_m": np.full(n, 20.0)} if truth else {}
    boxes = BoxTable.build(np.arange(n), np.tile(BOX, (n, 1)), np.zeros(n), **extra)
    write_box_csv(boxes, tmp_path / "boxes.csv")
    return [
        str(frames),
        "--calib",
        str(tmp_path / "calib.txt"),
        "--boxes",
        str(tmp_path / "boxes.csv"),
        "--out",
        str(tmp_path / "out"),
        "--quiet",
    ]


def records(tmp_path: Path) -> list[dict[str, str]]:
    with (tmp_path / "out" / "records.csv").open() as fh:
        return list(csv.DictReader(fh))


def frame_log(tmp_path: Path) -> list[dict[str, str]]:
    with (tmp_path / "out" / "frames.csv").open() as fh:
        return list(csv.DictReader(fh))


def test_depth_folder_of_kitti_pngs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = setup(tmp_path, truth=True)
    for k in (0, 1, 3):  # no map for frame 2
        write_kitti_depth_png(
            tmp_path / "depth" / f"{k:010d}.png", np.full((H, W), 12.5 + k, np.float32)
        )
    code = main(
        [
            "run",
            *args,
            "--method",
            "depthmap",
            "--odometry",
            "none",
            "--depth-dir",
            str(tmp_path / "depth"),
            "--depth-sample",
            "window",
            "--sequence",
            "s1",
        ]
    )
    assert code == 0, capsys.readouterr().err
    err = capsys.readouterr().err
    assert "1 frames with boxes had no depth map" in err and "ground truth" in err
    rows = records(tmp_path)
    assert [r["distance_m"] for r in rows] == ["12.5", "13.5", "", "15.5"]
    assert rows[2]["reason"] == "no_depth" and rows[0]["gt_distance_m"] == "20"
    assert all(r["depth_ms"] != "" for r in frame_log(tmp_path))
    summary = json.loads((tmp_path / "out" / "run.json").read_text())
    assert summary["sequence"] == "s1" and summary["depth_source"].startswith("file read")
    # the truth column also serves the oracle median scaling: scale = 20 / depth
    code = main(
        [
            "run",
            *args,
            "--method",
            "depthmap",
            "--depth-dir",
            str(tmp_path / "depth"),
            "--depth-scaling",
            "truth",
            "--odometry",
            "none",
        ]
    )
    assert code == 0
    assert [r["distance_m"] for r in records(tmp_path)] == ["20", "20", "", "20"]


def test_onnx_depth_model(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("onnx", reason="the 'onnx' package (test extra) builds the model")
    pytest.importorskip("onnxruntime", reason="onnxruntime (extra 'onnx') runs the model")
    from tests.io.depth.test_onnx_model import BIAS, WEIGHTS_RGB, build_model

    model = build_model(tmp_path / "tiny.onnx")
    args = setup(tmp_path)
    code = main(
        [
            "run",
            *args,
            "--method",
            "depthmap",
            "--odometry",
            "none",
            "--depth-model",
            str(model),
            "--depth-input-size",
            "24x16",
            "--depth-mean",
            "0.1,0.1,0.1",
            "--depth-std",
            "0.5,0.5,0.5",
            "--depth-scale",
            "4",
            "--depth-output",
            "inverse",
        ]
    )
    assert code == 0, capsys.readouterr().err
    for k, row in enumerate(records(tmp_path)):
        x = ((40 + 10 * k) / 255 - 0.1) / 0.5  # every channel, normalised
        expected = 4.0 / (sum(WEIGHTS_RGB) * x + BIAS)
        assert float(row["distance_m"]) == pytest.approx(expected, rel=1e-4)
    assert all(float(r["depth_ms"]) > 0 for r in frame_log(tmp_path))
    assert (
        "onnx inference" in json.loads((tmp_path / "out" / "run.json").read_text())["depth_source"]
    )


def test_onnx_without_onnxruntime_is_a_clear_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    args = setup(tmp_path)
    (tmp_path / "m.onnx").write_bytes(b"not read")
    monkeypatch.setitem(sys.modules, "onnxruntime", None)
    code = main(
        [
            "run",
            *args,
            "--method",
            "depthmap",
            "--depth-model",
            str(tmp_path / "m.onnx"),
            "--depth-input-size",
            "24x16",
        ]
    )
    assert code == 2
    err = capsys.readouterr().err
    assert "onnxruntime" in err and "slopedist[onnx]" in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--method", "depthmap"], "needs depth maps: give a folder"),
        (["--method", "paper", "--depth-dir", "DEPTH"], "does not use depth"),
        (
            ["--method", "depthmap", "--depth-dir", "DEPTH", "--depth-model", "m.onnx"],
            "either --depth-dir or --depth-model",
        ),
        (
            ["--method", "depthmap", "--depth-dir", "DEPTH", "--depth-mean", "0,0,0"],
            "--depth-mean configure an ONNX depth model",
        ),
        (["--method", "depthmap", "--depth-model", "m.onnx"], "--depth-input-size WIDTHxHEIGHT"),
        (
            ["--method", "depthmap", "--depth-model", "m.onnx", "--depth-input-size", "24by16"],
            "--depth-input-size WIDTHxHEIGHT in pixels",
        ),
        (
            [
                "--method",
                "depthmap",
                "--depth-model",
                "missing.onnx",
                "--depth-input-size",
                "24x16",
            ],
            "not found",
        ),
        (
            ["--method", "depthmap", "--depth-dir", "DEPTH", "--depth-scaling", "truth"],
            "needs the ground-truth distance column 'gt_distance_m'",
        ),
        (["--method", "depthmap", "--depth-dir", "nowhere"], "depth folder not found"),
        (["--method", "ego", "--vocab", "v.txt"], "--vocab is only used"),
    ],
)
def test_bad_depth_options_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    if "missing.onnx" in extra:  # the model file is looked for once onnxruntime is there
        pytest.importorskip("onnxruntime")
    args = setup(tmp_path)
    write_kitti_depth_png(tmp_path / "depth" / "000000.png", np.full((H, W), 5.0))
    extra = [str(tmp_path / "depth") if e == "DEPTH" else e for e in extra]
    extra = [str(tmp_path / e) if e.endswith(".onnx") else e for e in extra]
    (tmp_path / "m.onnx").write_bytes(b"")
    assert main(["run", *args, *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_lookback_reaches_the_builtin_odometry(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("slopedist.odometry.visual")
    cam = Camera(500.0, 160.0, 100.0, height_m=1.5)
    vo = pipeline_module.build_odometry("builtin", cam, None, 0.5)
    assert vo.config.lookback_s == 0.5  # type: ignore[attr-defined]
    seen: dict[str, Any] = {}
    real = pipeline_module.make_odometry

    def spy(name: str, camera: Camera, **options: Any) -> Any:
        seen.update(name=name, **options)
        return real(name, camera, **options)

    monkeypatch.setattr(pipeline_module, "make_odometry", spy)
    assert main(["run", *setup(tmp_path), "--method", "ego", "--lookback", "0.3"]) == 0
    assert seen == {"name": "builtin", "lookback_s": 0.3}


def test_a_run_without_odometry_says_so_in_its_summary(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", *setup(tmp_path), "--method", "flat", "--odometry", "none"]) == 0
    out = capsys.readouterr()
    text = out.out + out.err
    assert "no odometry, estimation" in text and "nan" not in text


def test_intrinsics_flags_instead_of_a_calibration_file(tmp_path: Path) -> None:
    args = setup(tmp_path)
    assert main(["run", *args, "--method", "flat", "--odometry", "none"]) == 0
    with_file = records(tmp_path)
    i = args.index("--calib")
    flags = ["--fx", "500", "--fy", "500", "--cx", "160", "--cy", "100"]
    args[i : i + 2] = flags
    assert main(["run", *args, "--method", "flat", "--odometry", "none"]) == 0
    assert records(tmp_path) == with_file and with_file


def test_a_distorted_calibration_maps_the_odometry_points(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("slopedist.odometry.visual")
    args = setup(tmp_path)
    calib = tmp_path / "k.txt"
    calib.write_text("500 0 160\n0 500 100\n0 0 1\n-0.3 0.1 0 0\n")
    args[args.index("--calib") + 1] = str(calib)
    seen: dict[str, Any] = {}
    real = pipeline_module.make_odometry

    def spy(name: str, camera: Camera, **options: Any) -> Any:
        seen.update(options)
        return real(name, camera, **options)

    monkeypatch.setattr(pipeline_module, "make_odometry", spy)
    assert main(["run", *args, "--method", "ego"]) == 0
    point = np.array([[300.0, 180.0]])
    assert seen["point_map"](point)[0, 0] > 300.0  # barrel distortion undone: moved outwards


def test_offline_run_writes_the_offline_records_at_the_end(tmp_path: Path) -> None:
    args = setup(tmp_path, n=6)
    assert main(["run", *args, "--method", "ours", "--odometry", "none"]) == 0
    causal = records(tmp_path)
    assert main(["run", *args, "--offline", "--odometry", "none", "--columns", "all"]) == 0
    offline = records(tmp_path)
    assert [r["method"] for r in offline] == ["ours-offline"] * 6
    assert [r["frame"] for r in offline] == [r["frame"] for r in causal]
    assert all(r["size_scale"] != "" for r in offline)
    assert [r["estimated"] for r in frame_log(tmp_path)] == ["1"] * 6


def test_offline_tracks_summarise_the_offline_records(tmp_path: Path) -> None:
    """``tracks.csv`` of an offline run is the summary of its records (the offline pass), not
    of the causal pass the frames were shown with."""
    args = setup(tmp_path, n=6)
    assert main(["run", *args, "--offline", "--odometry", "none"]) == 0
    rows = [r for r in records(tmp_path) if r["status"] == "ok"]
    with (tmp_path / "out" / "tracks.csv").open() as fh:
        (track,) = list(csv.DictReader(fh))
    assert int(track["frames"]) == len(rows)
    assert float(track["min_distance_m"]) == min(float(r["distance_m"]) for r in rows)
    ttcs = [float(r["ttc_s"]) for r in rows if r["ttc_s"] and float(r["ttc_s"]) > 0]
    assert (float(track["min_ttc_s"]) if track["min_ttc_s"] else None) == min(ttcs, default=None)


def test_offline_needs_a_method_with_an_offline_mode(tmp_path: Path) -> None:
    assert main(["run", *setup(tmp_path), "--method", "paper", "--offline"]) != 0


def test_image_size_completes_the_intrinsics_flags(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--image-size`` goes with ``--fx --fy --cx --cy`` as an OpenCV file's own size: it must
    agree with the frames (a clear error otherwise) and with a file that states one; a
    malformed size names the option."""
    args = setup(tmp_path)
    i = args.index("--calib")
    args[i : i + 2] = ["--fx", "500", "--fy", "500", "--cx", "160", "--cy", "100"]
    run = ["run", *args, "--method", "flat", "--odometry", "none"]
    assert main([*run, "--image-size", f"{W}x{H}"]) == 0
    assert records(tmp_path)
    assert main([*run, "--image-size", f"{W + 2}x{H}"]) == 2
    err = capsys.readouterr().err
    assert f"images are {W}×{H} px but the calibration is for {W + 2}×{H} px" in err
    assert main([*run, "--image-size", "wide"]) == 2
    assert "--image-size WIDTHxHEIGHT" in capsys.readouterr().err
    yaml = tmp_path / "cam.yaml"
    yaml.write_text(
        "%YAML:1.0\n---\nimage_width: 320\nimage_height: 200\ncamera_matrix: !!opencv-matrix\n"
        "   rows: 3\n   cols: 3\n   dt: d\n"
        "   data: [ 500., 0., 160., 0., 500., 100., 0., 0., 1. ]\n"
    )
    args[i : i + 8] = ["--calib", str(yaml)]
    assert (
        main(["run", *args, "--method", "flat", "--odometry", "none", "--image-size", "640x400"])
        == 2
    )
    assert "the calibration is for 320×200 px images, not 640×400 px as given" in (
        capsys.readouterr().err
    )


def test_a_snapshot_of_a_frame_not_read_is_a_warning(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`--snapshot N` beyond the last frame (or of a frame that does not decode) used to write
    nothing and say nothing."""
    args = setup(tmp_path, n=3)
    (Path(args[0]) / "000001.png").write_bytes(b"not a png")
    argv = ["run", *args, "--method", "flat", "--odometry", "none"]
    assert main([*argv, "--snapshot", "0", "--snapshot", "1", "--snapshot", "7"]) == 0
    err = capsys.readouterr().err
    assert (tmp_path / "out" / "snapshot_000000.jpg").exists()
    assert "warning: no snapshot of frame 1, 7:" in err
    assert main([*argv, "--snapshot", "2"]) == 0
    assert "no snapshot" not in capsys.readouterr().err


def test_a_tum_export_without_rotations_is_refused_before_anything_is_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--export tum --odometry none`` wrote a trajectory.tum with a header and no pose, and
    said nothing."""
    run = ["run", *setup(tmp_path), "--method", "flat", "--odometry", "none"]
    assert main([*run, "--export", "tum"]) == 2
    assert "--export tum writes the rotations" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
    assert main([*run, "--export", "mcap"]) == 0  # the MCAP export has frames to show
    assert (tmp_path / "out" / "run.mcap").is_file()


def test_summary_warns_when_most_frames_are_missing() -> None:
    # a folder named by milliseconds (00000000.png, 00000067.png, ...): 66 "missing" frames
    # between two images, and the summary only counted them
    from slopedist.cli.run_cmd import summary_text
    from slopedist.streaming.config import RunResult

    result = RunResult("out", "ours", frames=12, frame_status={"ok": 2, "missing": 10})
    assert "warning: 10 of the 12 frames are missing" in summary_text(result, Path("out"))
    result = RunResult("out", "ours", frames=12, frame_status={"ok": 7, "missing": 5})
    assert "frames are missing" not in summary_text(result, Path("out"))


def test_selfcal_without_rotations(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    """ours-selfcal calibrates from frames with a measured θ only: --odometry none is refused
    up front, and a run whose odometry never gave a rotation (featureless frames) says at the
    end that it did not calibrate (the calib_* columns were silently the configured values)."""
    args = setup(tmp_path)
    assert main(["run", *args, "--method", "ours-selfcal", "--odometry", "none"]) == 2
    err = capsys.readouterr().err
    assert "--odometry none gives none" in err and "Traceback" not in err
    assert main(["run", *args, "--method", "ours-selfcal"]) == 0
    assert "ours-selfcal did not self-calibrate: no frame had a measured rotation" in caplog.text
    caplog.clear()
    assert main(["run", *args, "--method", "ours"]) == 0
    assert "self-calibrate" not in caplog.text


def test_frames_further_apart_than_the_lookback(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A timelapse (frames 3 s apart) looks back one frame step, not the 1 s look-back: the run
    says so once; frames 0.1 s apart, or no rotations at all (--odometry none), say nothing."""
    args = setup(tmp_path)
    stamps = tmp_path / "stamps.txt"
    stamps.write_text("".join(f"{3.0 * k}\n" for k in range(4)))
    assert main(["run", *args, "--method", "ours", "--timestamps", str(stamps)]) == 0
    assert "a median 3 s apart, longer than the 1 s look-back" in caplog.text
    assert caplog.text.count("look-back of the ego gradient") == 1
    caplog.clear()
    assert (
        main(["run", *args, "--method", "ours", "--timestamps", str(stamps), "--lookback", "4"])
        == 0
    )
    assert "look-back of the ego gradient" not in caplog.text
    opts = ["--timestamps", str(stamps), "--odometry", "none"]
    assert main(["run", *args, "--method", "flat", *opts]) == 0
    assert main(["run", *args, "--method", "ours"]) == 0
    assert "look-back of the ego gradient" not in caplog.text


@pytest.mark.parametrize(
    ("calib", "frame_px", "said"),
    [
        ("P2: 500 0 160 0 0 500 300 0 0 0 1 0\n", (W, H), "c_y = 300.0 px lies outside the"),
        (CALIB, (1, 1), "c_x = 160.0 px lies outside the 1×1 px images"),
    ],
)
def test_a_calibration_that_does_not_fit_the_frames_names_its_file_and_the_frames(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    calib: str,
    frame_px: tuple[int, int],
    said: str,
) -> None:
    """A principal point off the image ("camera principal point c_y = 300 px is outside 0..200
    px") and 1×1 px frames blamed on the calibration named neither the file nor the frames."""
    args = setup(tmp_path)
    (tmp_path / "calib.txt").write_text(calib)
    for k in range(4):
        cv2.imwrite(str(tmp_path / "frames" / f"{k:06d}.png"), np.zeros((*frame_px[::-1], 3)))
    assert main(["run", *args]) == 2
    err = capsys.readouterr().err.strip()
    where = f"{tmp_path / 'calib.txt'} and the frames of {tmp_path / 'frames'}"
    assert err.startswith(f"slopedist: error: {where}: ") and said in err
    assert "the calibration is probably for another resolution (about" in err


def test_run_reports_the_gap_by_default_and_is_scored_as_at_the_centre(tmp_path: Path) -> None:
    """``run`` gives the distance to the nearest face (``reference`` says so, as ``run.json``);
    ``--reference centre`` the centre; scored against a truth (KITTI's z, the centre) both
    runs get the same figures: each method is scored at its own point."""
    common = setup(tmp_path, n=6, truth=True)
    assert main(["run", *common, "--odometry", "none", "--columns", "all"]) == 0
    face = records(tmp_path)
    summary = json.loads((tmp_path / "out" / "run.json").read_text())
    assert summary["reference"] == "nearest_face"
    centre_out = tmp_path / "centre"
    args = ["run", *common[:-3], "--out", str(centre_out), "--quiet", "--odometry", "none"]
    assert main([*args, "--reference", "centre", "--columns", "all"]) == 0
    with (centre_out / "records.csv").open() as fh:
        centre = list(csv.DictReader(fh))
    ok = [(f, c) for f, c in zip(face, centre) if f["status"] == "ok"]
    assert ok and {f["reference"] for f, _ in ok} == {"nearest_face"}
    assert {c["reference"] for _, c in ok} == {"centre"}
    for f, c in ok:
        assert float(f["distance_m"]) == pytest.approx(float(c["distance_nearest_face_m"]))
        assert float(f["distance_m"]) < float(c["distance_m"])
    tables = []
    for folder in (tmp_path / "out", centre_out):
        report = tmp_path / f"report_{folder.name}"
        assert main(["report", str(folder), "--out", str(report), "--no-parquet"]) == 0
        tables.append((report / "table1_rmse.csv").read_text())
    assert tables[0] == tables[1]


def _sparse_track(tmp_path: Path, track_ids: bool) -> list[str]:
    """Ten frames; one car in frames 0, 1, 5 and 9 only (user's track id 1 when
    ``track_ids``), the common arguments of ``ours`` without odometry."""
    args = setup(tmp_path, n=10)
    seen = np.array([0, 1, 5, 9])
    ids = np.ones(len(seen)) if track_ids else None
    boxes = BoxTable.build(seen, np.tile(BOX, (len(seen), 1)), ids)
    write_box_csv(boxes, tmp_path / "boxes.csv")
    return [*args, "--method", "ours", "--odometry", "none"]


def test_default_records_have_the_columns_a_user_acts_on_and_the_users_track(
    tmp_path: Path,
) -> None:
    """The default ``records.csv`` has at most 16 columns, the user's own track id on every row
    of a sparse track and no diagnostics; ``--columns all`` has every column, the method's own
    track number under a name that says what it is; ``tracks.csv`` follows the same id."""
    args = _sparse_track(tmp_path, track_ids=True)
    assert main(["run", *args]) == 0
    rows = records(tmp_path)
    assert list(rows[0]) == list(DEFAULT_RECORD_FIELDS) and len(rows[0]) <= 16
    assert [r["track_id"] for r in rows] == ["1"] * 4
    with (tmp_path / "out" / "tracks.csv").open() as fh:
        assert [t["track_id"] for t in csv.DictReader(fh)] == ["1"]
    assert main(["run", *args, "--columns", "all"]) == 0
    full = records(tmp_path)
    assert {"method", "cut", "cue_gap_sigma", METHOD_TRACK_COLUMN} <= set(full[0])
    assert "track_uid" not in full[0] and [r["track_id"] for r in full] == ["1"] * 4
    assert [r["distance_m"] for r in full] == [r["distance_m"] for r in rows]
    summary = json.loads((tmp_path / "out" / "run.json").read_text())
    assert (summary["method"], summary["columns"]) == ("ours", "all")


def test_boxes_without_track_ids_follow_the_trackers_id(tmp_path: Path) -> None:
    """Boxes without a track id: ``track_id`` is the tracker's, in the records and in
    ``tracks.csv``; a run with truth adds ``gt_distance_m`` and stays within 16 columns."""
    assert main(["run", *_sparse_track(tmp_path, track_ids=False)]) == 0
    rows = records(tmp_path)
    assert all(int(r["track_id"]) >= 0 for r in rows)
    with (tmp_path / "out" / "tracks.csv").open() as fh:
        tracked = {t["track_id"] for t in csv.DictReader(fh)}
    assert tracked and tracked == {r["track_id"] for r in rows if r["status"] == "ok"}
    truth = tmp_path / "truth"
    truth.mkdir()
    assert main(["run", *setup(truth, n=3, truth=True), "--method", "flat"]) == 0
    header = next(csv.reader((truth / "out" / "records.csv").open()))
    assert header == [*DEFAULT_RECORD_FIELDS, "gt_distance_m"] and len(header) <= 16


K_1080P = "1000 0 960\n0 1000 540\n0 0 1\n"
"""A 3×3 K calibrated on 1920×1080 px frames."""
ANOTHER_RESOLUTION = (
    "the calibration's principal point c_x = 960.0 px lies outside the 320×200 px images; "
    "the calibration is probably for another resolution (about "
    "1920×1080 px = 2·c_x × 2·c_y); give the calibration for these frames, or resize the "
    "frames to it"
)


def test_a_calibration_for_another_resolution_names_the_file_and_the_cause(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A K of 1920×1080 px frames on 320×200 px frames, in ``run`` and in ``estimate
    --image-size``: one line naming the file and the resolution it is probably for."""
    args = setup(tmp_path)
    calib = tmp_path / "k1080.txt"
    calib.write_text(K_1080P)
    args[args.index("--calib") + 1] = str(calib)
    assert main(["run", *args]) == 2
    err = capsys.readouterr().err.strip()
    where = f"{calib} and the frames of {tmp_path / 'frames'}"
    assert err == f"slopedist: error: {where}: {ANOTHER_RESOLUTION}"
    (tmp_path / "poses.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n" * 4)
    estimate = ["estimate", "--calib", str(calib), "--poses", str(tmp_path / "poses.txt")]
    estimate += ["--boxes", str(tmp_path / "boxes.csv"), "--image-size", f"{W}x{H}"]
    assert main(estimate) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"slopedist: error: {calib} with --image-size {W}x{H}: {ANOTHER_RESOLUTION}"


def test_a_run_without_boxes_points_to_the_detector_guide(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Neither --boxes nor --detector: one line that names both and docs/detectors.md, which
    starts with the shortest way to a detector (the commands it names exist)."""
    args = setup(tmp_path)
    at = args.index("--boxes")
    assert main(["run", *args[:at], *args[at + 2 :]]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [
        "slopedist: error: no boxes: give a box file (--boxes FILE) or an ONNX detector "
        "(--detector MODEL.onnx; export one yourself in two commands: docs/detectors.md)"
    ]
    guide = (Path(__file__).parents[2] / "docs" / "detectors.md").read_text(encoding="utf-8")
    first = guide.split("\n## ")[1]
    assert first.startswith("The shortest way") and "yolo export model=yolov8n.pt" in first
    assert "slopedist run drive.mp4 --calib calib.txt --detector yolov8n.onnx" in first
    assert main(["run", *args, "--detector", str(tmp_path / "m.onnx")]) == 2
    assert "not both" in capsys.readouterr().err


def test_a_report_of_default_records_with_truth_says_how_ours_was_moved(tmp_path: Path) -> None:
    """Default records lack ``ours``'s own depth extent: the report scores them all the same,
    at the truth's centre with the class's length, and says so."""
    assert main(["run", *setup(tmp_path, n=6, truth=True), "--odometry", "none"]) == 0
    report = tmp_path / "report"
    assert main(["report", str(tmp_path / "out"), "--out", str(report), "--no-parquet"]) == 0
    assert (report / "table1_rmse.csv").read_text().count("\n") >= 2
    text = (report / "report.md").read_text(encoding="utf-8")
    assert "ours: moved to the truth's point with half the class's length" in text
    assert "--columns all" in text
