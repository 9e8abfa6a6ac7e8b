"""``slopedist detect``: a test-built ONNX detector over a frame folder, then ``slopedist run``."""

from __future__ import annotations

import csv
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
