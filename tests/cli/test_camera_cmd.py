"""``slopedist camera calibrate``: outputs that are inputs."""

from __future__ import annotations

from pathlib import Path

import pytest

from slopedist.cli import main


def test_out_that_is_the_video_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`camera calibrate board.mp4 --out board.mp4` replaced the checkerboard video."""
    video = tmp_path / "board.mp4"
    video.write_bytes(b"video")
    argv = ["camera", "calibrate", str(video), "--pattern", "9x6", "--out", str(video)]
    assert main(argv) == 2
    assert "would be overwritten" in capsys.readouterr().err
    assert video.read_bytes() == b"video"
