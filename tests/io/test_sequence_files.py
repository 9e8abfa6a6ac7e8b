"""The files of one sequence (calibration, poses, boxes) read together."""

from __future__ import annotations

from pathlib import Path

import pytest

from slopedist.core.errors import DataMismatchError
from slopedist.io.sequence_files import SequenceFiles, read_sequence_files


def test_boxes_past_the_last_pose_are_counted(tmp_path: Path) -> None:
    """Boxes in frames the pose file does not reach: the error said only how far the boxes go,
    not how many boxes (of how many) lie past the last pose."""
    calib = tmp_path / "calib.txt"
    calib.write_text("P2: 721.5 0 609.6 44.9 0 721.5 172.9 0.2 0 0 1 0.003\n")
    poses = tmp_path / "poses.txt"
    poses.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n" * 5)
    boxes = tmp_path / "boxes.csv"
    rows = "".join(f"{k},500,150,600,250\n" for k in (0, 3, 4, 5, 7, 7))
    boxes.write_text("frame,left,top,right,bottom\n" + rows)
    with pytest.raises(DataMismatchError) as err:
        read_sequence_files(SequenceFiles(calib, poses, boxes))
    message = str(err.value)
    assert message.startswith(f"{poses}: 5 poses do not cover the boxes of {boxes}")
    assert "3 of 6 boxes are in frames 5 to 7, past the last pose (frame 4)" in message
