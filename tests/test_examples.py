"""The Python guide as a user runs it: the quick start of docs/python.md, copied as written,
prints distances on a drive's frames, and each script of examples/ runs on one (KITTI raw
frames when ../shared/data has them, else a rendered scenario)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import cv2
import pytest

from slopedist.io.frames import open_frames

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
GUIDE = ROOT / "docs" / "python.md"

FAKE_ULTRALYTICS = '''"""A stand-in for ultralytics: ``YOLO(weights)(image)`` gives, call by call,
the recorded boxes of the drive's frames as ultralytics ``Results`` (COCO class 2, car)."""

import os
from types import SimpleNamespace

import numpy as np

import slopedist


class YOLO:
    def __init__(self, weights):
        self.by_frame = slopedist.read_boxes(os.environ["FAKE_YOLO_BOXES"]).frame_lookup()
        self.calls = 0

    def __call__(self, image, verbose=True):
        table = self.by_frame.get(self.calls)
        self.calls += 1
        xyxy = np.zeros((0, 4)) if table is None else table.boxes
        n = len(xyxy)
        boxes = SimpleNamespace(xyxy=xyxy, conf=np.full(n, 0.9), cls=np.full(n, 2.0), id=None)
        return [SimpleNamespace(boxes=boxes, names={2: "car"})]
'''

DISTANCE_LINE = re.compile(r"^frame \d+: \w+ -?\d+ at \d+\.\d m$", re.MULTILINE)


def quick_start() -> str:
    """The first ``python`` block under the guide's "Quick start" heading."""
    text = GUIDE.read_text(encoding="utf-8")
    section = text.split("## Quick start", 1)[1]
    return section.split("```python\n", 1)[1].split("```", 1)[0]


@pytest.fixture(scope="module")
def drive_video(drive_files: Any, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The drive's frames as an MP4 at 10 frames per second (OpenCV's ``mp4v``)."""
    path = tmp_path_factory.mktemp("video") / "drive.mp4"
    frames = [f.image for f in open_frames(drive_files.frames) if f.image is not None]
    height, width = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (width, height))
    for image in frames:
        writer.write(image)
    writer.release()
    return path


def python(args: list[str], cwd: Path, **env: str) -> subprocess.CompletedProcess[str]:
    paths = [env.pop("PYTHONPATH", ""), *sys.path]
    environment = {**os.environ, **env, "PYTHONPATH": os.pathsep.join(p for p in paths if p)}
    return subprocess.run(
        [sys.executable, *args], cwd=cwd, env=environment, capture_output=True, text=True
    )


def camera_options(drive_files: Any) -> list[str]:
    options = dict(zip(drive_files.run_options[::2], drive_files.run_options[1::2], strict=True))
    return [f"--height={options.get('--height', 1.65)}"] if options else []


def test_the_quick_start_runs_as_written(
    tmp_path: Path, drive_files: Any, drive_video: Path
) -> None:
    pytest.importorskip("slopedist.odometry.visual")
    (tmp_path / "quick_start.py").write_text(quick_start(), encoding="utf-8")
    shutil.copy(drive_files.calib, tmp_path / "calib.txt")
    shutil.copy(drive_video, tmp_path / "drive.mp4")
    fake = tmp_path / "fake" / "ultralytics"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text(FAKE_ULTRALYTICS, encoding="utf-8")
    done = python(
        ["quick_start.py"],
        tmp_path,
        PYTHONPATH=str(fake.parent),
        FAKE_YOLO_BOXES=str(drive_files.boxes),
    )
    assert done.returncode == 0, done.stderr
    lines = DISTANCE_LINE.findall(done.stdout)
    assert len(lines) > (50 if drive_files.real else 0), done.stdout[-2000:]


def test_the_detector_loop_prints_the_nearest_vehicle(
    tmp_path: Path, drive_files: Any, drive_video: Path
) -> None:
    pytest.importorskip("slopedist.odometry.visual")
    d = drive_files
    method = "ours" if d.real else "paper"  # the rendered scenario's camera is not KITTI's height
    args = [str(EXAMPLES / "detector_loop.py"), str(drive_video), str(d.calib), str(d.boxes)]
    done = python([*args, "--method", method], tmp_path)
    assert done.returncode == 0, done.stderr
    assert re.search(r"nearest: \w+ \(track -?\d+\) at \d+\.\d", done.stdout), done.stdout


def test_the_live_stream_drops_rather_than_queues(
    tmp_path: Path, drive_files: Any, drive_video: Path
) -> None:
    pytest.importorskip("slopedist.odometry.visual")
    d = drive_files
    args = [str(EXAMPLES / "live_stream.py"), str(drive_video), str(d.calib), str(d.boxes)]
    done = python([*args, "--method", "paper"], tmp_path)
    assert done.returncode == 0, done.stderr
    summary = re.search(r"(\d+) frames stepped, (\d+) dropped of (\d+) read", done.stdout)
    assert summary is not None, done.stdout
    stepped, dropped, read = (int(v) for v in summary.groups())
    assert stepped + dropped == read == len(list(open_frames(d.frames)))
    times = [float(t) for t in re.findall(r"t +(\d+\.\d+) s", done.stdout)]
    assert times == sorted(times) and len(set(times)) == stepped
    assert re.search(r"Car \d+\.\d m", done.stdout, re.IGNORECASE)


def test_the_evaluation_scores_each_method(tmp_path: Path, drive_files: Any) -> None:
    pytest.importorskip("slopedist.odometry.visual")
    d = drive_files
    options = dict(zip(d.run_options[::2], d.run_options[1::2], strict=True))
    extra = [f"--{k.lstrip('-')}={v}" for k, v in options.items()]
    reference = "nearest_face" if d.real else "centre"  # LiDAR truth; a scenario's label z
    args = [str(EXAMPLES / "evaluate_drive.py"), str(d.frames), str(d.calib), str(d.boxes)]
    args += ["--out", str(tmp_path / "eval"), "--methods", "flat,paper", "--reference", reference]
    done = python([*args, *extra], tmp_path)
    assert done.returncode == 0, done.stderr
    rows = re.findall(r"^(flat|paper) +\d+ +(\d+) +(\d+\.\d+)", done.stdout, re.MULTILINE)
    assert [r[0] for r in rows] == ["flat", "paper"], done.stdout
    assert all(int(n) > 0 and float(rmse) < 20.0 for _, n, rmse in rows)
    assert (tmp_path / "eval" / "paper" / "records.csv").is_file()
