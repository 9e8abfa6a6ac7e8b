"""``estimate --calib`` in other forms: an OpenCV YAML with fx ≠ fy gives the KITTI result."""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest

from slopedist.cli import main

P2 = "721.5 0 609.6 44.9 0 721.5 172.9 0.2 0 0 1 0.003"
BOXES = [(0, 500, 150, 600, 250, 7), (1, 520, 200, 640, 300, 7), (2, 10, 190, 90, 240, 8)]


def _estimate(tmp_path: Path, calib: Path, boxes: list, name: str) -> list[float]:
    poses = tmp_path / "poses.txt"
    poses.write_text("".join(f"1 0 0 0 0 1 0 0 0 0 1 {k:.1f}\n" for k in range(3)))
    box_csv = tmp_path / f"{name}.csv"
    box_csv.write_text(
        "frame,left,top,right,bottom,track_id\n"
        + "".join(",".join(map(str, b)) + "\n" for b in boxes)
    )
    out = tmp_path / f"{name}_records.csv"
    args = ["estimate", "--calib", str(calib), "--poses", str(poses), "--boxes", str(box_csv)]
    assert main([*args, "--method", "flat", "--out", str(out)]) == 0
    return [float(r["distance_m"]) for r in csv.DictReader(out.open())]


def test_stretched_frames_with_opencv_yaml_match_kitti(tmp_path: Path) -> None:
    kitti = tmp_path / "calib.txt"
    kitti.write_text(f"P2: {P2}\n")
    reference = _estimate(tmp_path, kitti, BOXES, "kitti")
    sx, sy = 1920 / 1226, 1080 / 370  # frames stretched: fx ≠ fy
    yaml = tmp_path / "cam.yaml"
    fs = cv2.FileStorage(str(yaml), cv2.FILE_STORAGE_WRITE)
    fs.write(
        "camera_matrix",
        np.array([[721.5 * sx, 0, 609.6 * sx], [0, 721.5 * sy, 172.9 * sy], [0, 0, 1]]),
    )
    fs.write("distortion_coefficients", np.zeros((1, 5)))
    fs.release()
    stretched = [(f, le * sx, t * sy, r * sx, b * sy, tid) for f, le, t, r, b, tid in BOXES]
    distances = _estimate(tmp_path, yaml, stretched, "stretched")
    assert np.all(np.isfinite(reference))
    np.testing.assert_allclose(distances, reference, rtol=1e-6)


def test_bad_calibration_yaml_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    yaml = tmp_path / "cam.yaml"
    yaml.write_text("camera_matrix:\n  data: [1, 2, 3]\n")
    poses = tmp_path / "p.txt"
    poses.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n")
    boxes = tmp_path / "b.csv"
    boxes.write_text("frame,left,top,right,bottom\n0,1,2,3,4\n")
    args = ["estimate", "--calib", str(yaml), "--poses", str(poses), "--boxes", str(boxes)]
    assert main([*args, "--method", "flat", "--out", str(tmp_path / "o.csv")]) == 2
    assert "cam.yaml, field 'camera_matrix': expected 9 numbers, found 3" in capsys.readouterr().err
