"""KITTI tracking sequences on disk: which sequences a root holds."""

from __future__ import annotations

from pathlib import Path

import pytest

from slopedist.core.errors import MissingInputError
from slopedist.io.kitti.tracking import list_sequences, load_sequence

P2 = "P2: 721.5 0 609.6 44.9 0 721.5 172.9 0.2 0 0 1 0.003\n"
LABEL = "0 0 Car 0 0 -1.5 300 160 450 290 1.5 1.6 3.9 -1 1.7 10 -1.6\n"


def test_a_sequence_without_its_calibration_is_named_not_left_out(tmp_path: Path) -> None:
    """A label file whose calib/ file is missing used to drop the sequence from an evaluation
    of every sequence without a word (and `--sequences` called it "not found")."""
    for name in ("0000", "0001"):
        (tmp_path / "label_02").mkdir(exist_ok=True)
        (tmp_path / "label_02" / f"{name}.txt").write_text(LABEL)
    (tmp_path / "calib").mkdir()
    (tmp_path / "calib" / "0000.txt").write_text(P2)
    assert list_sequences(tmp_path) == ["0000", "0001"]
    assert load_sequence(tmp_path, "0000").n_frames == 1
    with pytest.raises(MissingInputError, match=r"sequence 0001: no calibration, expected .*"):
        load_sequence(tmp_path, "0001")
