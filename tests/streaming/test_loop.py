"""The streaming run from frames to records: outputs, per-frame states, crashes keep records,
overlay, and the ``slopedist run`` command."""

from __future__ import annotations

import csv
import json
import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np
import pytest

from slopedist.cli import main
from slopedist.core.camera import Camera
from slopedist.core.errors import DataMismatchError, InputFileError
from slopedist.estimators import make_estimator
from slopedist.io import overlay, prefetch
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.writers import write_box_csv
from slopedist.io.frames import Frame, FrameSource, FrameStatus, open_frames
from slopedist.io.intrinsics import Intrinsics
from slopedist.odometry.base import OdometryResult, OdometryState
from slopedist.streaming import loop as runner
from slopedist.streaming import setup as run_setup
from slopedist.streaming.config import SNAPSHOT_QUALITY, RunAbortedError, RunConfig
from slopedist.streaming.loop import run_frames
from slopedist.streaming.step import RecordColumns

W, H = 320, 200
CAM = Camera(500.0, 160.0, 100.0, height_m=1.5)
PITCH_RATE = 0.01  # rad per second of camera pitch: θ over a 1 s look-back = 0.01 rad


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


class ScriptedOdometry:
    """Test double of the odometry protocol: pitch ``PITCH_RATE·t``; not initialised on the first
    frame; optionally fails at one frame."""

    def __init__(self, fail_at: float | None = None, error: Exception | None = None) -> None:
        self.calls: list[tuple[float, np.ndarray | None]] = []
        self.fail_at = fail_at
        self.error = error or RuntimeError("boom")

    def process(
        self, image_gray: np.ndarray, timestamp_s: float, mask_boxes: np.ndarray | None = None
    ) -> OdometryResult:
        assert image_gray.ndim == 2 and image_gray.dtype == np.uint8
        if self.fail_at is not None and timestamp_s >= self.fail_at:
            raise self.error
        self.calls.append((timestamp_s, mask_boxes))
        if len(self.calls) == 1:
            return OdometryResult(None, OdometryState.NOT_INITIALISED, 0)
        return OdometryResult(rot_x(PITCH_RATE * timestamp_s), OdometryState.OK, 123)

    def reset(self) -> None:
        self.calls.clear()


class ThreadCountingOdometry(ScriptedOdometry):
    """:class:`ScriptedOdometry` that notes OpenCV's thread setting at each frame."""

    def __init__(self) -> None:
        super().__init__()
        self.threads: list[int] = []

    def process(
        self, image_gray: np.ndarray, timestamp_s: float, mask_boxes: np.ndarray | None = None
    ) -> OdometryResult:
        self.threads.append(cv2.getNumThreads())
        return super().process(image_gray, timestamp_s, mask_boxes)


def make_frames(root: Path, n: int, skip: tuple[int, ...] = ()) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    for k in range(n):
        if k not in skip:
            cv2.imwrite(str(root / f"{k:06d}.png"), np.full((H, W, 3), 40 + k, np.uint8))
    return root


def boxes_every_frame(n: int) -> BoxTable:
    frames = np.repeat(np.arange(n), 2)
    boxes = np.tile([[100.0, 110.0, 150.0, 150.0], [200.0, 105.0, 230.0, 125.0]], (n, 1))
    return BoxTable.build(frames, boxes, np.tile([0, 1], n))


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def test_records_and_frame_log_match_hand_computed_distances(tmp_path: Path) -> None:
    n = 15
    odo = ScriptedOdometry()
    result = run_frames(
        open_frames(make_frames(tmp_path / "f", n)),
        boxes_every_frame(n),
        odo,
        make_estimator("ego", CAM),
        RunConfig(tmp_path / "out", progress=False),
    )
    assert result.frames == n and result.records == 2 * n and result.estimated == 2 * (n - 1)
    assert result.odometry_states == {"not_initialised": 1, "ok": n - 1}
    # the frame's boxes are masked out of the odometry's features
    assert odo.calls[0][1] is not None and odo.calls[0][1].shape == (2, 4)
    frames = read_csv(tmp_path / "out" / "frames.csv")
    assert [r["frame"] for r in frames] == [str(k) for k in range(n)]
    assert frames[0]["odometry_state"] == "not_initialised" and frames[0]["theta_deg"] == ""
    assert frames[1]["inliers"] == "123" and float(frames[1]["odometry_ms"]) >= 0
    # frame 12 (t = 1.2 s) looks back to frame 2 (t = 0.2 s): θ = 0.01 rad
    assert float(frames[12]["theta_deg"]) == pytest.approx(math.degrees(PITCH_RATE), rel=1e-4)
    rows = [r for r in read_csv(tmp_path / "out" / "records.csv") if r["frame"] == "12"]
    v = CAM.c_y - CAM.f * math.tan(PITCH_RATE)
    assert float(rows[0]["distance_m"]) == pytest.approx(CAM.f * CAM.height_m / (150 - v), rel=1e-5)
    first = [r for r in read_csv(tmp_path / "out" / "records.csv") if r["frame"] == "0"]
    assert [r["reason"] for r in first] == ["no_rotation", "no_rotation"]
    summary = json.loads((tmp_path / "out" / "run.json").read_text())
    assert summary["frames"] == n and summary["error"] is None


def test_missing_frame_is_logged_and_the_run_goes_on(tmp_path: Path) -> None:
    n = 8
    result = run_frames(
        open_frames(make_frames(tmp_path / "f", n, skip=(4,))),
        boxes_every_frame(n),
        ScriptedOdometry(),
        make_estimator("paper", CAM),
        RunConfig(tmp_path / "out", progress=False),
    )
    assert result.frames == n and result.frame_status == {"ok": n - 1, "missing": 1}
    frames = read_csv(tmp_path / "out" / "frames.csv")
    assert frames[4]["frame_status"] == "missing" and frames[4]["odometry_state"] == ""
    assert frames[5]["odometry_state"] == "ok"
    rows = read_csv(tmp_path / "out" / "records.csv")
    assert {r["reason"] for r in rows if r["frame"] == "4"} == {"no_rotation"}
    assert {r["status"] for r in rows if r["frame"] == "5"} == {"ok"}


class RepeatedStampFrames:
    """Frames of ``inner`` where frame ``at`` is what a drive log yields for a repeated header
    stamp: unreadable, at the time of the frame before it."""

    def __init__(self, inner: FrameSource, at: int) -> None:
        self._inner, self._at = inner, at

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)

    def __iter__(self) -> Iterator[Frame]:
        last = 0.0
        for frame in self._inner:
            if frame.index == self._at:
                frame = Frame(
                    frame.index, last, None, FrameStatus.UNREADABLE, frame.source, "repeated"
                )
            last = frame.timestamp_s
            yield frame


class StoppingFrames:
    """A frame source whose stop flag is raised (as by Ctrl-C) once frame ``at`` is given."""

    def __init__(self, inner: FrameSource, config: RunConfig, at: int) -> None:
        self.inner, self.config, self.at = inner, config, at
        self.path = inner.path

    def frame_size(self) -> tuple[int, int]:
        return self.inner.frame_size()

    def expected_frames(self) -> int | None:
        return self.inner.expected_frames()

    def __iter__(self) -> Iterator[Frame]:
        for frame in self.inner:
            if frame.index == self.at:
                self.config.stop.signum = 2
            yield frame


class FailingFrames(StoppingFrames):
    """A frame source whose frame ``at`` cannot be read (an error before it is given)."""

    def __iter__(self) -> Iterator[Frame]:
        for frame in self.inner:
            if frame.index == self.at:
                raise InputFileError(self.path, "cannot be read")
            yield frame


@pytest.mark.parametrize(
    ("source", "at", "last_complete"),
    [(StoppingFrames, 2, 2), (FailingFrames, 0, None)],  # stopped after frame 2; before frame 0
)
def test_a_stopped_run_counts_no_box_of_the_frames_it_never_reached(
    tmp_path: Path, source: type[StoppingFrames], at: int, last_complete: int | None
) -> None:
    n = 8
    config = RunConfig(tmp_path / "out", progress=False, decode_ahead=0)  # stops in step
    frames = source(open_frames(make_frames(tmp_path / "f", n)), config, at)
    with pytest.raises(RunAbortedError):
        run_frames(
            cast(FrameSource, frames),
            boxes_every_frame(n),
            ScriptedOdometry(),
            make_estimator("paper", CAM),
            config,
        )
    summary = json.loads((tmp_path / "out" / "run.json").read_text())
    assert not summary["complete"] and summary["last_complete_frame"] == last_complete
    assert summary["boxes_without_frame"] == 0  # the frames after the last complete one


def test_an_unreadable_frame_out_of_time_order_is_logged_and_the_run_goes_on(
    tmp_path: Path,
) -> None:
    """A log's repeated stamp (or a video's) is an unreadable frame at a time that does not
    follow the frame before: logged, its boxes not used, the frames after it run."""
    n = 8
    frames = RepeatedStampFrames(open_frames(make_frames(tmp_path / "f", n)), 4)
    result = run_frames(
        cast(FrameSource, frames),
        boxes_every_frame(n),
        ScriptedOdometry(),
        make_estimator("paper", CAM),
        RunConfig(tmp_path / "out", progress=False),
    )
    assert result.complete and result.frames == n
    assert result.frame_status == {"ok": n - 1, "unreadable": 1}
    assert result.boxes_without_frame == 2 and result.records == 2 * (n - 1)
    log = read_csv(tmp_path / "out" / "frames.csv")
    assert [r["frame_status"] for r in log][3:6] == ["ok", "unreadable", "ok"]
    assert log[4]["detail"] == "repeated" and log[4]["boxes"] == "0"
    rows = read_csv(tmp_path / "out" / "records.csv")
    assert {r["frame"] for r in rows} == {str(k) for k in range(n) if k != 4}
    assert {r["status"] for r in rows if r["frame"] == "7"} == {"ok"}


def test_crash_halfway_keeps_the_records_written_before(tmp_path: Path) -> None:
    n = 10
    with pytest.raises(RuntimeError, match="boom"):
        run_frames(
            open_frames(make_frames(tmp_path / "f", n)),
            boxes_every_frame(n),
            ScriptedOdometry(fail_at=0.55),
            make_estimator("ego", CAM),
            RunConfig(tmp_path / "out", progress=False),
        )
    rows = read_csv(tmp_path / "out" / "records.csv")
    assert sorted({int(r["frame"]) for r in rows}) == [0, 1, 2, 3, 4, 5]
    assert len(read_csv(tmp_path / "out" / "frames.csv")) == 6
    summary = json.loads((tmp_path / "out" / "run.json").read_text())
    assert summary["failed_frame"] == 6 and "boom" in summary["error"]
    assert summary["frames"] == 6 and summary["frame_status"] == {"ok": 6}  # not the failed one


def test_user_error_halfway_names_the_frame_and_the_kept_records(tmp_path: Path) -> None:
    n = 6
    err = InputFileError("x.png", "bad pixels")
    with pytest.raises(RunAbortedError, match=r"frame 3 \(000003\.png\).*records of the 3 frames"):
        run_frames(
            open_frames(make_frames(tmp_path / "f", n)),
            boxes_every_frame(n),
            ScriptedOdometry(fail_at=0.25, error=err),
            make_estimator("ego", CAM),
            RunConfig(tmp_path / "out", progress=False),
        )
    assert len(read_csv(tmp_path / "out" / "records.csv")) == 6


def test_calibration_mismatch_fails_before_writing(tmp_path: Path) -> None:
    far = Camera(500.0, 700.0, 100.0)
    with pytest.raises(DataMismatchError, match=r"c_x = 700\.0 px lies outside"):
        run_frames(
            open_frames(make_frames(tmp_path / "f", 3)),
            boxes_every_frame(3),
            ScriptedOdometry(),
            make_estimator("ego", far),
            RunConfig(tmp_path / "out", progress=False),
        )
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("target", ["overlay", "overlay.mp4"])
def test_overlay_png_folder_and_mp4(tmp_path: Path, target: str) -> None:
    n = 6
    run_frames(
        open_frames(make_frames(tmp_path / "f", n, skip=(2,))),
        boxes_every_frame(n),
        ScriptedOdometry(),
        make_estimator("ego", CAM),
        RunConfig(tmp_path / "out", overlay=tmp_path / "out" / target, progress=False),
    )
    if target == "overlay":
        pngs = sorted((tmp_path / "out" / "overlay").glob("*.png"))
        assert [p.name for p in pngs] == [f"{k:06d}.png" for k in (0, 1, 3, 4, 5)]
        image = cv2.imread(str(pngs[-1]))
        v = round(CAM.c_y - CAM.f * math.tan(PITCH_RATE * 0.5))  # frame 5 looks back to 0
        assert (image[v] == (0, 255, 0)).all(axis=-1).all()
    else:
        cap = cv2.VideoCapture(str(tmp_path / "out" / target))
        assert cap.get(cv2.CAP_PROP_FRAME_COUNT) == n  # placeholder for the missing frame
        assert fourcc(cap) in {"avc1", "h264"}  # what browsers play
        cap.release()
        summary = json.loads((tmp_path / "out" / "run.json").read_text())
        assert summary["overlay_codec"].startswith("h264")
        assert summary["overlay_warning"] is None


def fourcc(cap: cv2.VideoCapture) -> str:
    """The FourCC of an opened video, as text (``avc1``, ``mp4v``, ...)."""
    code = int(cap.get(cv2.CAP_PROP_FOURCC))
    return "".join(chr((code >> (8 * i)) & 0xFF) for i in range(4)).lower()


def test_an_overlay_without_h264_says_so_in_run_json(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Without an H.264 encoder the MP4 is OpenCV's mp4v, which browsers do not play:
    ``run.json`` says which codec and why."""
    monkeypatch.setattr(overlay, "h264_encoder", lambda: None)
    n = 3
    out = tmp_path / "out"
    run_frames(
        open_frames(make_frames(tmp_path / "f", n)),
        boxes_every_frame(n),
        ScriptedOdometry(),
        make_estimator("ego", CAM),
        RunConfig(out, overlay=out / "overlay.mp4", progress=False),
    )
    cap = cv2.VideoCapture(str(out / "overlay.mp4"))
    assert fourcc(cap) in {"mp4v", "fmp4"}  # MPEG-4 Part 2, as OpenCV reads it back
    cap.release()
    summary = json.loads((out / "run.json").read_text())
    assert summary["overlay_codec"] == "mp4v"
    assert "browsers do not" in summary["overlay_warning"]


def _cli_setup(tmp_path: Path, n: int = 5) -> tuple[Path, Path, Path]:
    frames = make_frames(tmp_path / "f", n)
    calib = tmp_path / "calib.txt"
    calib.write_text("P2: 500 0 160 0 0 500 100 0 0 0 1 0\n")
    boxes = write_box_csv(boxes_every_frame(n), tmp_path / "boxes.csv")
    return frames, calib, boxes


def test_cli_run_writes_outputs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    frames, calib, boxes = _cli_setup(tmp_path)
    monkeypatch.setattr(run_setup, "build_odometry", lambda *a, **k: ScriptedOdometry())
    out = tmp_path / "out"
    code = main(
        [
            "run",
            str(frames),
            "--calib",
            str(calib),
            "--boxes",
            str(boxes),
            "--method",
            "paper",
            "--out",
            str(out),
            "--quiet",
            "--overlay",
            "--overlay-format",
            "png",
        ]
    )
    assert code == 0
    err = capsys.readouterr().err
    assert "wrote 10 records" in err and "frames/s" in err
    assert len(read_csv(out / "records.csv")) == 10
    assert len(list((out / "overlay").glob("*.png"))) == 5


def test_cli_snapshot_is_the_overlay_frame_as_jpeg(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    frames, calib, boxes = _cli_setup(tmp_path)
    monkeypatch.setattr(run_setup, "build_odometry", lambda *a, **k: ScriptedOdometry())
    base = ["run", str(frames), "--calib", str(calib), "--boxes", str(boxes), "--quiet"]
    with_overlay = tmp_path / "a"
    args = ["--overlay", "--overlay-format", "png", "--snapshot", "3"]
    assert main([*base, "--out", str(with_overlay), *args]) == 0
    snapshot = cv2.imread(str(with_overlay / "snapshot_000003.jpg"))
    overlay = cv2.imread(str(with_overlay / "overlay" / "000003.png"))
    _, jpeg = cv2.imencode(".jpg", overlay, [cv2.IMWRITE_JPEG_QUALITY, SNAPSHOT_QUALITY])
    np.testing.assert_array_equal(snapshot, cv2.imdecode(jpeg, cv2.IMREAD_COLOR))
    alone = tmp_path / "b"  # without --overlay: only the snapshots
    assert main([*base, "--out", str(alone), "--snapshot", "1", "--snapshot", "4"]) == 0
    assert sorted(p.name for p in alone.glob("snapshot_*")) == [
        "snapshot_000001.jpg",
        "snapshot_000004.jpg",
    ]
    assert not (alone / "overlay").exists() and not (alone / "overlay.mp4").exists()
    assert f"export: {alone / 'snapshot_000004.jpg'}" in capsys.readouterr().err


def test_cli_bad_inputs_exit_2_with_a_message(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    frames, calib, boxes = _cli_setup(tmp_path)
    monkeypatch.setattr(run_setup, "build_odometry", lambda *a, **k: ScriptedOdometry())
    video = tmp_path / "clip.mp4"
    video.write_text("garbage")
    base = ["--calib", str(calib), "--boxes", str(boxes), "--out", str(tmp_path / "o"), "--quiet"]
    assert main(["run", str(video), *base]) == 2
    assert "cannot be opened as a video" in capsys.readouterr().err
    ts = tmp_path / "t.txt"
    ts.write_text("0\n0.1\n0.1\n0.3\n0.4\n")
    assert main(["run", str(frames), *base, "--timestamps", str(ts)]) == 2
    assert "line 3" in capsys.readouterr().err
    wide = tmp_path / "wide.txt"
    wide.write_text("P2: 500 0 600 0 0 500 100 0 0 0 1 0\n")
    assert main(["run", str(frames), "--calib", str(wide), *base[2:]]) == 2
    assert "principal point" in capsys.readouterr().err
    assert main(["run", str(frames), *base, "--method", "imu"]) == 2
    assert "defined on 'oxts' rotations" in capsys.readouterr().err
    assert main(["run", str(frames), *base, "--method", "depthmap"]) == 2
    assert "needs depth maps" in capsys.readouterr().err


def test_default_method_is_ours(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    frames, calib, boxes = _cli_setup(tmp_path)
    monkeypatch.setattr(run_setup, "build_odometry", lambda *a, **k: ScriptedOdometry())
    out = tmp_path / "out"
    assert (
        main(
            [
                "run",
                str(frames),
                "--calib",
                str(calib),
                "--boxes",
                str(boxes),
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    assert json.loads((out / "run.json").read_text())["method"] == "ours"


def test_cli_run_on_real_frames_with_lidar_boxes(
    kitti_raw_lead_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from slopedist.io.kitti.raw import (
        KittiRawDrive,
        lidar_vehicle_boxes,
        link_tracks,
        read_velodyne,
    )

    drive = KittiRawDrive.open(kitti_raw_lead_dir)
    truth = link_tracks(
        [
            lidar_vehicle_boxes(read_velodyne(drive.velodyne_paths[k]), drive.calib, (1242, 375), k)
            for k in range(12)
        ]
    )
    boxes = write_box_csv(truth, tmp_path / "lidar_boxes.csv")
    out = tmp_path / "out"
    code = main(
        [
            "run",
            str(drive.image_dir),
            "--calib",
            str(drive.calib_path),
            "--boxes",
            str(boxes),
            "--method",
            "ego",
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert code == 0, capsys.readouterr().err
    frames = read_csv(out / "frames.csv")
    assert len(frames) == 78
    assert sum(r["odometry_state"] == "ok" for r in frames) >= 70
    # level street: the ego gradient stays within a degree
    assert all(abs(float(r["theta_deg"])) < 1.0 for r in frames if r["theta_deg"])
    est = {(int(r["frame"]), int(r["track_id"])): r for r in read_csv(out / "records.csv")}
    assert len(est) == len(truth)
    lead = truth.select(
        (np.abs(truth.extra["x"]) < 1.0)
        & (truth.extra["truncated"] == 0)
        & (truth.extra["z"] < 9.0)
    )
    assert len(lead) >= 10
    errors = [
        float(est[(int(f), int(t))]["distance_m"]) - z
        for f, t, z in zip(lead.frame, lead.track_id, lead.extra["z"])
    ]
    assert np.sqrt(np.mean(np.square(errors))) < 0.5  # metres, lead car at 7–8 m


class RestartingOdometry(ScriptedOdometry):
    """Restarts (segment 1) at t = 1.2 s with an arbitrary jump of its rotation."""

    def process(
        self, image_gray: np.ndarray, timestamp_s: float, mask_boxes: np.ndarray | None = None
    ) -> OdometryResult:
        res = super().process(image_gray, timestamp_s, mask_boxes)
        if timestamp_s < 1.15 or res.R_world_cam is None:
            return res
        return OdometryResult(rot_x(0.3) @ res.R_world_cam, res.state, res.inliers, 1)


def test_no_look_back_across_an_odometry_restart(tmp_path: Path) -> None:
    n = 16
    run_frames(
        open_frames(make_frames(tmp_path / "f", n)),
        boxes_every_frame(n),
        RestartingOdometry(),
        make_estimator("ego", CAM),
        RunConfig(tmp_path / "out", progress=False, columns=RecordColumns.ALL),
    )
    frames = read_csv(tmp_path / "out" / "frames.csv")
    assert [r["segment"] for r in frames[10:14]] == ["0", "0", "1", "1"]
    theta = [float(r["theta_deg"]) for r in frames[11:]]
    # frame 11 looks back a full second; frame 12 starts the new segment (θ = 0) and frame 15
    # looks back only to frame 12: 0.3 s of pitch, never the 0.3 rad jump
    assert theta[0] == pytest.approx(math.degrees(PITCH_RATE), rel=1e-4)
    assert theta[1] == pytest.approx(0.0, abs=1e-9)
    assert theta[4] == pytest.approx(math.degrees(PITCH_RATE * 0.3), rel=1e-3)
    rows = [r for r in read_csv(tmp_path / "out" / "records.csv") if r["frame"] == "15"]
    assert float(rows[0]["theta_deg"]) == pytest.approx(theta[4], rel=1e-6)


# --- ground truth in the records, the sequence name, depth maps, no odometry ------------------


def boxes_with_truth(n: int) -> BoxTable:
    """:func:`boxes_every_frame` with a ground-truth distance per box (unknown on frame 3)."""
    b = boxes_every_frame(n)
    gt = np.tile([10.0, 40.0], n)
    gt[6:8] = np.nan
    return BoxTable.build(b.frame, b.boxes, b.track_id, gt_distance_m=gt)


def test_ground_truth_and_sequence_reach_the_records_and_the_report(tmp_path: Path) -> None:
    from slopedist.evaluation.report import ReportOptions, run_report_data

    n = 15
    for method in ("ego", "flat"):
        run_frames(
            open_frames(make_frames(tmp_path / "clip7", n)),
            boxes_with_truth(n),
            ScriptedOdometry(),
            make_estimator(method, CAM),
            RunConfig(tmp_path / "runs" / method, progress=False),
        )
    rows = read_csv(tmp_path / "runs" / "ego" / "records.csv")
    assert [r["gt_distance_m"] for r in rows[:2]] == ["10", "40"]
    assert [r["gt_distance_m"] for r in rows if r["frame"] == "3"] == ["", ""]
    summary = json.loads((tmp_path / "runs" / "ego" / "run.json").read_text())
    assert summary["sequence"] == "clip7" and summary["ground_truth"] is True
    data = run_report_data(tmp_path / "runs", ReportOptions())
    assert data.sequences == ["clip7"] and data.methods == ["ego", "flat"]
    for method in ("ego", "flat"):
        recs = [
            r
            for r in read_csv(tmp_path / "runs" / method / "records.csv")
            if r["gt_distance_m"] and r["distance_m"]
        ]
        err = [min(float(r["distance_m"]), 80.0) - float(r["gt_distance_m"]) for r in recs]
        assert data.summaries["clip7"][method]["n"] == len(recs) == (28 if method == "flat" else 26)
        assert data.summaries["clip7"][method]["rmse"] == pytest.approx(
            math.sqrt(np.mean(np.square(err))), rel=1e-4
        )


def test_sequence_name_option_and_defaults(tmp_path: Path) -> None:
    from slopedist.streaming.config import default_sequence_name

    run_frames(
        open_frames(make_frames(tmp_path / "f", 3)),
        boxes_every_frame(3),
        ScriptedOdometry(),
        make_estimator("ego", CAM),
        RunConfig(tmp_path / "out", progress=False, sequence="0007"),
    )
    summary = json.loads((tmp_path / "out" / "run.json").read_text())
    assert summary["sequence"] == "0007" and summary["ground_truth"] is False
    nested = tmp_path / "2011_09_26_drive_0001_sync" / "image_02" / "data"
    nested.mkdir(parents=True)
    assert default_sequence_name(nested) == "2011_09_26_drive_0001_sync"
    video = tmp_path / "drive.mp4"
    video.write_bytes(b"")
    assert default_sequence_name(video) == "drive"


class DepthFolder:
    """``.npy`` depth maps in which box 0 reads ``5 + k`` m and box 1 ``30`` m at frame k (no
    map for frame 2)."""

    @staticmethod
    def write(root: Path, n: int) -> Path:
        root.mkdir()
        for k in range(n):
            if k == 2:
                continue
            depth = np.full((H, W), 60.0, np.float32)
            depth[110:151, 100:151] = 5.0 + k
            depth[105:126, 200:231] = 30.0
            np.save(root / f"{k:06d}.npy", depth)
        return root


def test_depth_maps_feed_the_depthmap_method_and_are_timed(tmp_path: Path) -> None:
    from slopedist.io.depth import FileDepthSource

    n = 5
    source = FileDepthSource(DepthFolder.write(tmp_path / "depth", n), missing_ok=True)
    result = run_frames(
        open_frames(make_frames(tmp_path / "f", n)),
        boxes_every_frame(n),
        None,
        make_estimator("depthmap", CAM),
        RunConfig(tmp_path / "out", progress=False),
        depth=source,
    )
    assert result.frames_without_depth == 1 and result.depth_source is not None
    rows = read_csv(tmp_path / "out" / "records.csv")
    assert [float(r["distance_m"]) for r in rows if r["frame"] == "3"] == [8.0, 30.0]
    assert {r["reason"] for r in rows if r["frame"] == "2"} == {"no_depth"}
    frames = read_csv(tmp_path / "out" / "frames.csv")
    assert all(float(r["depth_ms"]) >= 0 for r in frames)
    # no odometry: no rotation, no odometry time, and depthmap does not need either
    assert all(r["odometry_state"] == "" and r["odometry_ms"] == "" for r in frames)
    assert result.estimated == 2 * (n - 1)


def test_depth_and_method_must_match(tmp_path: Path) -> None:
    from slopedist.core.errors import ConfigurationError
    from slopedist.io.depth import FileDepthSource

    frames = open_frames(make_frames(tmp_path / "f", 3))
    with pytest.raises(ConfigurationError, match="needs depth maps"):
        run_frames(
            frames,
            boxes_every_frame(3),
            None,
            make_estimator("depthmap", CAM),
            RunConfig(tmp_path / "out", progress=False),
        )
    source = FileDepthSource(DepthFolder.write(tmp_path / "depth", 3), missing_ok=True)
    with pytest.raises(ConfigurationError, match="does not use them"):
        run_frames(
            frames,
            boxes_every_frame(3),
            None,
            make_estimator("paper", CAM),
            RunConfig(tmp_path / "out", progress=False),
            depth=source,
        )
    assert not (tmp_path / "out").exists()


def test_frames_decoded_ahead_give_the_same_outputs(tmp_path: Path) -> None:
    """The default run decodes frames in a background thread and draws and writes the overlay
    in another; its records, frame log and overlay images are those of a run doing everything
    in the loop (timings aside)."""
    n = 12
    folder = make_frames(tmp_path / "f", n, skip=(5,))
    outputs = []
    for ahead in (0, 3):
        out = tmp_path / f"out{ahead}"
        run_frames(
            open_frames(folder),
            boxes_every_frame(n),
            ScriptedOdometry(),
            make_estimator("ego", CAM),
            RunConfig(out, overlay=out / "overlay", progress=False, decode_ahead=ahead),
        )
        frames = read_csv(out / "frames.csv")
        for row in frames:
            for key in ("odometry_ms", "estimation_ms", "depth_ms"):
                row.pop(key)
        pngs = {p.name: p.read_bytes() for p in sorted((out / "overlay").glob("*.png"))}
        outputs.append((read_csv(out / "records.csv"), frames, pngs))
    assert outputs[0] == outputs[1]
    assert len(outputs[0][2]) == n - 1  # the missing frame has no image
    assert len(outputs[0][1]) == n and outputs[0][1][5]["frame_status"] == "missing"


def test_frames_decoded_ahead_leave_a_core_to_the_decoding_thread(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On two cores, a run decoding ahead runs the loop's OpenCV on one thread (the decoding
    thread has the other core), one decoding in the loop keeps the caller's setting, and the
    setting is given back after the run."""
    monkeypatch.setattr(prefetch, "usable_cores", lambda: 2)
    folder = make_frames(tmp_path / "f", 3)
    before = cv2.getNumThreads()
    cv2.setNumThreads(2)
    try:
        for ahead, threads in ((2, 1), (0, 2)):
            odometry = ThreadCountingOdometry()
            out = tmp_path / f"out{ahead}"
            config = RunConfig(out, progress=False, decode_ahead=ahead)
            estimator = make_estimator("ego", CAM)
            run_frames(open_frames(folder), boxes_every_frame(3), odometry, estimator, config)
            assert odometry.threads == [threads] * 3
            assert cv2.getNumThreads() == 2
    finally:
        cv2.setNumThreads(before)


def test_overlay_and_odometry_mask_use_the_distorted_frames_pixels(tmp_path: Path) -> None:
    """With a strongly distorted camera the boxes are mapped into the ideal camera for the
    estimator, but the overlay draws them (and the odometry masks them) where they are in the
    distorted frames: the original boxes, not the mapped ones (10 px apart here)."""
    intrinsics = Intrinsics(
        np.array([[400.0, 0.0, 160.0], [0.0, 400.0, 100.0], [0.0, 0.0, 1.0]]),
        np.array([-0.5, 0.2, 0.0, 0.0, 0.0]),
    )
    n = 3
    original = BoxTable.build(
        np.repeat(np.arange(n), 2),
        np.tile([[20.0, 30.0, 90.0, 110.0], [200.0, 60.0, 300.0, 150.0]], (n, 1)),
        np.tile([0, 1], n),
    )
    mapped = intrinsics.rectify_table(original)
    assert np.abs(mapped.boxes - original.boxes).max() > 9.0
    odometry = ScriptedOdometry()
    camera = intrinsics.camera(1.5).with_image_size(W, H)
    out = tmp_path / "out"
    config = RunConfig(out, overlay=out / "overlay", progress=False, decode_ahead=0)
    frames = open_frames(make_frames(tmp_path / "f", n))
    run_frames(frames, mapped, odometry, make_estimator("flat", camera), config)
    for _, mask in odometry.calls:
        np.testing.assert_array_equal(mask, original.boxes[:2])
    image = cv2.imread(str(out / "overlay" / f"{n - 1:06d}.png")).astype(int)
    background = 40 + n - 1

    def drawn_share(column: float, rows: tuple[float, float]) -> float:
        pixels = image[round(rows[0]) + 5 : round(rows[1]) - 5, round(column)]
        return float(np.mean(np.abs(pixels - background).max(axis=1) > 30))

    for i, edge in ((0, 0), (1, 2)):  # the left edge of box 0, the right edge of box 1
        rows = (original.boxes[i, 1], original.boxes[i, 3])
        assert drawn_share(original.boxes[i, edge], rows) > 0.8
        assert drawn_share(mapped.boxes[i, edge], rows) < 0.2


def test_an_offline_run_whose_records_fail_at_the_end_keeps_them_and_says_so(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An offline method writes its records once the frames have all run; a write that fails
    then (a full disk) keeps the whole frames before it, closes every output and writes
    ``run.json`` saying where the records stop, as a causal run does."""
    n = 8
    real_writer = runner.CsvStreamWriter

    def failing_records(stream: Any, fields: Any = None) -> Any:
        writer = real_writer(stream, fields)
        if fields is not None:  # not records.csv (whose header is that of its first record)
            return writer
        write_rows, calls = writer.write_rows, [0]

        def write(rows: Any) -> int:
            calls[0] += 1
            if calls[0] > 3:
                raise OSError(28, "No space left on device")
            return write_rows(rows)

        writer.write_rows = write  # type: ignore[method-assign]
        return writer

    monkeypatch.setattr(runner, "CsvStreamWriter", failing_records)
    out = tmp_path / "out"
    with pytest.raises(RunAbortedError, match=r"8 frames.*stop before frame 3.*No space left"):
        run_frames(
            open_frames(make_frames(tmp_path / "f", n)),
            boxes_every_frame(n),
            ScriptedOdometry(),
            make_estimator("ours-offline", CAM),
            RunConfig(out, progress=False),
        )
    assert not list(out.glob("*.partial*"))
    rows = read_csv(out / "records.csv")
    assert sorted({int(r["frame"]) for r in rows}) == [0, 1, 2]
    assert json.loads((out / "run.json").read_text())["method"] == "ours-offline"
    assert len(read_csv(out / "frames.csv")) == n
    summary = json.loads((out / "run.json").read_text())
    assert summary["complete"] is False and "No space left" in summary["error"]
    assert (summary["last_complete_frame"], summary["failed_frame"]) == (2, 3)
    assert summary["records"] == len(rows)


def test_an_offline_runs_time_per_frame_includes_its_pass_over_the_drive(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``estimation_ms_mean`` (Table 2 of ``report``) of an offline method counts the pass
    over the drive it makes at the end, not only the causal pass the frames were shown with."""
    n = 4
    estimator = make_estimator("ours-offline", CAM)
    finish = estimator.finish

    def slow_finish() -> Any:
        time.sleep(0.4)
        return finish()

    monkeypatch.setattr(estimator, "finish", slow_finish)
    result = run_frames(
        open_frames(make_frames(tmp_path / "f", n)),
        boxes_every_frame(n),
        ScriptedOdometry(),
        estimator,
        RunConfig(tmp_path / "out", progress=False),
    )
    assert result.complete and result.estimation_ms_mean >= 400 / n
    assert result.elapsed_s >= 0.4


def test_an_offline_run_stopped_part_way_says_its_records_cover_the_frames_reached(
    tmp_path: Path,
) -> None:
    """A stop (SIGTERM, Ctrl-C) ends an offline run with the records of its pass over the
    frames it reached, and the message says that they are that (not of the whole drive)."""
    n = 8
    config = RunConfig(tmp_path / "out", progress=False, decode_ahead=0)
    frames = StoppingFrames(open_frames(make_frames(tmp_path / "f", n)), config, 2)
    with pytest.raises(
        RunAbortedError,
        match=r"The ours-offline records, from its pass over those frames only, of the 3 frames",
    ):
        run_frames(
            cast(FrameSource, frames),
            boxes_every_frame(n),
            ScriptedOdometry(),
            make_estimator("ours-offline", CAM),
            config,
        )
    rows = read_csv(tmp_path / "out" / "records.csv")
    assert [int(r["frame"]) for r in rows] == [0, 0, 1, 1, 2, 2]
    summary = json.loads((tmp_path / "out" / "run.json").read_text())
    assert summary["method"] == "ours-offline" and summary["complete"] is False
    assert summary["last_complete_frame"] == 2 and summary["records"] == 6


def test_a_run_stopped_part_way_never_replaces_a_complete_earlier_run(tmp_path: Path) -> None:
    """A stop request (raised after frame 2, as SIGTERM does) in a rerun into a folder that
    holds a complete run: that run stays byte for byte; the stopped one's files keep their
    temporary names beside it, whole up to its last frame."""
    n = 8
    out = tmp_path / "out"
    frames_dir = make_frames(tmp_path / "f", n)

    def run(method: str, stop_after: int | None = None) -> None:
        config = RunConfig(out, progress=False, decode_ahead=0)
        frames: Any = open_frames(frames_dir)
        if stop_after is not None:
            frames = StoppingFrames(frames, config, stop_after)
        estimator = make_estimator(method, CAM)
        run_frames(frames, boxes_every_frame(n), ScriptedOdometry(), estimator, config)

    run("flat")
    earlier = {p.name: p.read_bytes() for p in out.iterdir()}
    assert sorted(earlier) == ["frames.csv", "records.csv", "run.json", "tracks.csv"]
    with pytest.raises(RunAbortedError, match=r"complete earlier run in .* is kept") as stopped:
        run("paper", stop_after=2)
    assert stopped.value.records_path == out / "records.partial.csv"
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.name in earlier} == earlier
    rows = read_csv(out / "records.partial.csv")
    assert [int(r["frame"]) for r in rows] == [0, 0, 1, 1, 2, 2]
    summary = json.loads((out / "run.partial.json").read_text())
    assert summary["method"] == "paper"
    assert summary["complete"] is False and summary["last_complete_frame"] == 2
    assert sorted(p.name for p in out.iterdir() if p.name not in earlier) == [
        "frames.partial.csv",
        "records.partial.csv",
        "run.partial.json",
        "tracks.partial.csv",
    ]


@pytest.mark.parametrize("h264", [True, False])
def test_cli_run_overlay_is_h264_or_says_why_not_on_stderr(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    h264: bool,
) -> None:
    """``run --overlay`` writes an MP4 browsers play (FourCC avc1); without an H.264 encoder
    the fallback is a warning line on stderr."""
    frames, calib, boxes = _cli_setup(tmp_path)
    monkeypatch.setattr(run_setup, "build_odometry", lambda *a, **k: ScriptedOdometry())
    if not h264:
        monkeypatch.setattr(overlay, "h264_encoder", lambda: None)
    out = tmp_path / "out"
    base = ["run", str(frames), "--calib", str(calib), "--boxes", str(boxes), "--quiet"]
    assert main([*base, "--out", str(out), "--overlay"]) == 0
    cap = cv2.VideoCapture(str(out / "overlay.mp4"))
    assert fourcc(cap) in ({"avc1", "h264"} if h264 else {"mp4v", "fmp4"})
    cap.release()
    err = capsys.readouterr().err.splitlines()
    assert f"overlay: {out / 'overlay.mp4'} ({overlay.video_codec()})" in err
    warnings = [line for line in err if line.startswith("warning: ") and "mp4v" in line]
    assert len(warnings) == (0 if h264 else 1)
    assert all("browsers do not" in w and "pip install" in w for w in warnings)
