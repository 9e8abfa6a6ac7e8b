"""``slopedist odometry eval`` on real frames, and user mistakes ending in exit code 2."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from slopedist.cli import main


def test_eval_on_real_frames(
    kitti_odometry_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "figures" / "seq06.json"
    threads = cv2.getNumThreads()
    code = main(["odometry", "eval", str(kitti_odometry_dir / "seq06_000-050"), "--json", str(out)])
    assert code == 0
    assert cv2.getNumThreads() == threads  # one thread only while timing
    printed = json.loads(capsys.readouterr().out)
    written = json.loads(out.read_text())
    assert printed == written
    assert {"frames", "theta_rms_deg", "rel_rot_median_deg", "ms_per_frame"} <= set(written)
    assert written["frames"] == 51 and written["frames_ok"] == 51
    assert 0.0 < written["theta_rms_deg"] < 0.08
    assert 0.0 < written["rel_rot_median_deg"] < 0.15
    assert written["ms_per_frame"] > 0.0


def test_eval_missing_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["odometry", "eval", str(tmp_path / "nope")])
    assert code == 2
    assert "sequence folder not found" in capsys.readouterr().err


def test_eval_fewer_poses_than_frames(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "image_l").mkdir()
    for k in range(3):
        cv2.imwrite(str(tmp_path / "image_l" / f"{k:06d}.png"), np.zeros((50, 80), np.uint8))
    (tmp_path / "calib.txt").write_text("70 0 40 0 0 70 25 0 0 0 1 0\n")
    (tmp_path / "poses.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n")
    code = main(["odometry", "eval", str(tmp_path)])
    assert code == 2
    assert "1 poses for 3 frames" in capsys.readouterr().err


def test_eval_json_that_is_an_input_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`odometry eval SEQ --json SEQ/poses.txt` replaced the ground truth with the figures."""
    poses = tmp_path / "poses.txt"
    poses.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n")
    assert main(["odometry", "eval", str(tmp_path), "--json", str(poses)]) == 2
    assert "would be overwritten" in capsys.readouterr().err
    assert poses.read_text() == "1 0 0 0 0 1 0 0 0 0 1 0\n"


def test_eval_a_frame_of_another_size_names_its_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A frame cropped or from another camera among the others: one error naming that file."""
    (tmp_path / "image_l").mkdir()
    for k in range(3):
        size = (40, 60) if k == 2 else (50, 80)
        cv2.imwrite(str(tmp_path / "image_l" / f"{k:06d}.png"), np.zeros(size, np.uint8))
    (tmp_path / "calib.txt").write_text("70 0 40 0 0 70 25 0 0 0 1 0\n")
    (tmp_path / "poses.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n" * 3)
    assert main(["odometry", "eval", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "000002.png: frame size 60×40 px differs from the 80×50 px" in err


def test_eval_json_onto_a_frame_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`odometry eval SEQ --json SEQ/image_l/000001.png` replaced that frame with the figures."""
    (tmp_path / "image_l").mkdir()
    for k in range(3):
        cv2.imwrite(str(tmp_path / "image_l" / f"{k:06d}.png"), np.zeros((50, 80), np.uint8))
    (tmp_path / "calib.txt").write_text("70 0 40 0 0 70 25 0 0 0 1 0\n")
    (tmp_path / "poses.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n" * 3)
    frame = tmp_path / "image_l" / "000001.png"
    before = frame.read_bytes()
    assert main(["odometry", "eval", str(tmp_path), "--json", str(frame)]) == 2
    assert "would be overwritten" in capsys.readouterr().err
    assert frame.read_bytes() == before
