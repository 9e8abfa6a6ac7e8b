"""``slopedist detect``: a test-built ONNX detector over a frame folder, then ``slopedist run``."""

from __future__ import annotations

import csv
import json
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from slopedist.cli import main

pytest.importorskip("onnxruntime", reason="onnxruntime (extra 'onnx') runs the model")


def _yolov8_output() -> np.ndarray:
    """Two cars and a person as a YOLOv8 output ``[1, 4 + 8, 20]`` of a 320×320 input."""
    out = np.zeros((12, 20))
    for j, (cx, cy, w, h, cls, score) in enumerate(
        [(130, 200, 60, 40, 2, 0.9), (131, 201, 60, 40, 2, 0.6), (250, 190, 40, 30, 0, 0.8)]
    ):
        out[:4, j] = (cx, cy, w, h)
        out[4 + cls, j] = score
    return out[None]


@pytest.fixture
def frames(tmp_path: Path) -> Path:
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(str(folder / f"{i:06d}.png"), np.full((360, 640, 3), 80 + 20 * i, np.uint8))
    (folder / "000003.png").write_bytes(b"not an image")
    return folder


def test_detect_then_run(
    tmp_path: Path, frames: Path, constant_model: Callable[..., Path], capsys: pytest.CaptureFixture
) -> None:
    model = constant_model(tmp_path / "yolo.onnx", {"output0": _yolov8_output()})
    boxes, timing = tmp_path / "boxes.csv", tmp_path / "timing.csv"
    args = ["detect", str(frames), "--detector", str(model), "--out", str(boxes)]
    assert main([*args, "--timing", str(timing)]) == 0
    assert "3 boxes in 3 of 4 frames" in capsys.readouterr().err
    rows = list(csv.DictReader(boxes.open()))
    assert [r["frame"] for r in rows] == ["0", "1", "2"]
    # (130 ± 30, 200 ± 20) in the input → (x / 0.5, (y − 70) / 0.5) in the 640×360 frame
    assert [rows[0][k] for k in ("left", "top", "right", "bottom", "class", "score")] == [
        "200",
        "220",
        "320",
        "300",
        "Car",
        "0.9",
    ]
    times = list(csv.DictReader(timing.open()))
    assert [t["frame_status"] for t in times] == ["ok", "ok", "ok", "unreadable"]
    assert float(times[0]["inference_ms"]) > 0 and times[3]["detection_ms"] == ""

    calib = tmp_path / "calib.txt"
    calib.write_text("P2: 500 0 320 0 0 500 180 0 0 0 1 0\n")
    out = tmp_path / "run"
    run = ["run", str(frames), "--calib", str(calib), "--boxes", str(boxes), "--out", str(out)]
    assert main([*run, "--method", "flat", "--odometry", "none", "--quiet"]) == 0
    records = list(csv.DictReader((out / "records.csv").open()))
    assert len(records) == 3 and records[0]["status"] == "ok"
    assert float(records[0]["distance_m"]) == pytest.approx(500 * 1.65 / (300 - 180), rel=1e-3)


def test_detect_bad_class_map_and_missing_model(tmp_path: Path, frames: Path) -> None:
    args = ["detect", str(frames), "--detector", str(tmp_path / "none.onnx")]
    assert main(args) == 2
    assert main([*args, "--classes", "car"]) == 2


# One car (with a worse duplicate) and a person, in network-input pixels of a 320×320 input:
# (left, top, right, bottom), class, score.
SCENE = [
    ((100, 180, 160, 220), 2, 0.9),
    ((101, 181, 161, 221), 2, 0.6),
    ((230, 175, 270, 205), 0, 0.8),
]
CAR_IN_FRAME = [200.0, 220.0, 320.0, 300.0]  # (x / 0.5, (y − 70) / 0.5) in the 640×360 frame


def _cxcywh(b: tuple[int, int, int, int]) -> list[float]:
    return [(b[0] + b[2]) / 2, (b[1] + b[3]) / 2, b[2] - b[0], b[3] - b[1]]


def _layout_outputs(layout: str) -> dict[str, np.ndarray]:
    """The scene as each output layout, padded to more candidates than columns."""
    n, c = 20, 8
    if layout == "yolov8":
        out = np.zeros((4 + c, n))
        for j, (b, cls, s) in enumerate(SCENE):
            out[:4, j], out[4 + cls, j] = _cxcywh(b), s
        return {"output0": out[None]}
    if layout == "yolov5":
        out = np.zeros((n, 5 + c))
        for j, (b, cls, s) in enumerate(SCENE):
            out[j, :4], out[j, 4], out[j, 5 + cls] = _cxcywh(b), 1.0, s
        return {"output": out[None]}
    if layout == "end2end":
        rows = [[*b, s, cls] for i, (b, cls, s) in enumerate(SCENE) if i != 1]
        return {"output0": np.asarray(rows + [[0] * 6] * 5, float)[None]}
    boxes = np.array([_cxcywh(b) for b, _, _ in SCENE]) / 320
    logits = np.full((len(SCENE), c), -20.0)
    for j, (_, cls, s) in enumerate(SCENE):
        logits[j, cls] = np.log(s / (1 - s))
    return {"pred_boxes": boxes[None], "pred_logits": logits[None]}


def _run(tmp_path: Path, frames: Path, model: Path, method: str, *extra: str) -> Path:
    calib = tmp_path / "calib.txt"
    calib.write_text("P2: 500 0 320 0 0 500 180 0 0 0 1 0\n")
    out = tmp_path / f"run_{method}"
    args = ["run", str(frames), "--calib", str(calib), "--detector", str(model), "--out", str(out)]
    assert main([*args, "--method", method, "--quiet", *extra]) == 0
    return out


@pytest.mark.parametrize("layout", ["yolov8", "yolov5", "end2end", "detr"])
def test_run_with_a_detector_of_each_layout(
    tmp_path: Path, frames: Path, constant_model: Callable[..., Path], layout: str
) -> None:
    model = constant_model(tmp_path / f"{layout}.onnx", _layout_outputs(layout))
    out = _run(tmp_path, frames, model, "flat", "--odometry", "none")
    records = list(csv.DictReader((out / "records.csv").open()))
    assert [r["frame"] for r in records] == ["0", "1", "2"]  # one car per readable frame
    for r in records:
        assert [float(r[k]) for k in ("left", "top", "right", "bottom")] == CAR_IN_FRAME
        assert r["class"] == "Car" and r["status"] == "ok"
    log = list(csv.DictReader((out / "frames.csv").open()))
    assert all(float(f["detection_ms"]) > 0 for f in log[:3]) and log[3]["detection_ms"] == ""
    summary = json.loads((out / "run.json").read_text())
    assert summary["detector"].endswith(f"{layout}.onnx") and summary["detection_ms_mean"] > 0


@pytest.mark.parametrize("method", ["flat", "ego", "paper", "ours", "ours-selfcal", "depthmap"])
def test_run_with_a_detector_and_every_estimator(
    tmp_path: Path, frames: Path, constant_model: Callable[..., Path], method: str
) -> None:
    model = constant_model(tmp_path / "yolo.onnx", _layout_outputs("yolov8"))
    extra: list[str] = []
    if method == "depthmap":
        depth = tmp_path / "depth"
        depth.mkdir()
        for i in range(3):
            np.save(depth / f"{i:06d}.npy", np.full((360, 640), 7.0, np.float32))
        extra = ["--depth-dir", str(depth), "--odometry", "none"]
    out = _run(tmp_path, frames, model, method, *extra)
    records = list(csv.DictReader((out / "records.csv").open()))
    summary = json.loads((out / "run.json").read_text())
    assert len(records) == 3 and summary["method"] == method
    if method in ("flat", "depthmap"):
        assert all(r["status"] == "ok" for r in records)
    if method == "depthmap":
        assert float(records[0]["distance_m"]) == pytest.approx(7.0, rel=0.05)


def test_run_needs_exactly_one_box_source(
    tmp_path: Path, frames: Path, constant_model: Callable[..., Path], capsys: pytest.CaptureFixture
) -> None:
    calib = tmp_path / "calib.txt"
    calib.write_text("P2: 500 0 320 0 0 500 180 0 0 0 1 0\n")
    args = ["run", str(frames), "--calib", str(calib), "--out", str(tmp_path / "o")]
    assert main(args) == 2
    assert "--boxes" in capsys.readouterr().err
    model = constant_model(tmp_path / "yolo.onnx", _layout_outputs("yolov8"))
    boxes = tmp_path / "b.csv"
    boxes.write_text("frame,left,top,right,bottom\n")
    assert main([*args, "--boxes", str(boxes), "--detector", str(model)]) == 2


def test_video_calibration_yaml_detector_overlay_report(
    tmp_path: Path, frames: Path, constant_model: Callable[..., Path]
) -> None:
    """The README's "your own video" path: OpenCV YAML calibration, ONNX detector, overlay,
    report with the detection time in Table 2."""
    model = constant_model(tmp_path / "yolo.onnx", _layout_outputs("yolov8"))
    calib = tmp_path / "cam.yaml"
    fs = cv2.FileStorage(str(calib), cv2.FILE_STORAGE_WRITE)
    fs.write("camera_matrix", np.array([[500.0, 0, 320], [0, 500, 180], [0, 0, 1]]))
    fs.write("distortion_coefficients", np.zeros((1, 5)))
    fs.release()
    out = tmp_path / "run"
    args = ["run", str(frames), "--calib", str(calib), "--detector", str(model), "--out", str(out)]
    overlay = ["--overlay", "--overlay-format", "png"]
    assert main([*args, "--method", "flat", "--odometry", "none", "--quiet", *overlay]) == 0
    assert len(list((out / "overlay").glob("*.png"))) >= 3  # the readable frames
    report = tmp_path / "report"
    assert main(["report", str(out), "--out", str(report)]) == 0
    rows = list(csv.DictReader((report / "table2_time.csv").open()))
    assert float(rows[0]["detection"]) > 0 and float(rows[0]["estimation"]) > 0
    assert float(rows[0]["total"]) == pytest.approx(float(rows[0]["estimation"]), rel=1e-3)


def test_detect_output_that_is_an_input_is_refused(
    tmp_path: Path, frames: Path, capsys: pytest.CaptureFixture
) -> None:
    """`detect FRAMES --detector m.onnx --out m.onnx` (or --timing) replaced the model."""
    model = tmp_path / "m.onnx"
    model.write_bytes(b"model")
    for option in ("--out", "--timing"):
        argv = ["detect", str(frames), "--detector", str(model), option, str(model)]
        assert main(argv) == 2
        assert "would be overwritten" in capsys.readouterr().err
    assert model.read_bytes() == b"model"
