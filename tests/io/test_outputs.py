"""Crash-safe outputs: temporary names, cut-back on a failed write, stop flags, inputs spared."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from slopedist.core.errors import ConfigurationError
from slopedist.io.outputs import (
    OutputFiles,
    OutputWriteError,
    StopFlag,
    check_outputs_spare_inputs,
    partial_path,
    stop_on_signals,
)


def test_partial_names_keep_the_suffix() -> None:
    assert partial_path(Path("a/records.csv")) == Path("a/records.partial.csv")
    assert partial_path(Path("a/overlay.mp4")) == Path("a/overlay.partial.mp4")
    assert partial_path(Path("a/overlay")) == Path("a/overlay.partial")


def test_a_failed_write_names_the_file_and_cuts_it_back_to_whole_rows(tmp_path: Path) -> None:
    files = OutputFiles(tmp_path, ["t.csv"])
    path = files.path("t.csv")
    with path.open("w") as fh, files.writing("t.csv"):
        fh.write("a,b\n1,2\n")
        fh.flush()  # as CsvStreamWriter does after every batch
    with (
        pytest.raises(OutputWriteError, match=r"t\.csv: No space left"),
        path.open("a") as fh,
        files.writing("t.csv"),
    ):
        fh.write("3,")
        fh.flush()
        raise OSError(28, "No space left on device")
    assert path.read_text() == "a,b\n1,2\n"
    files.promote("s.json")
    files.write_summary("s.json", {"rows": 1})
    assert (tmp_path / "t.csv").read_text() == "a,b\n1,2\n" and not path.exists()
    assert (tmp_path / "s.json").read_text().strip().startswith("{")


def test_the_reserved_summary_is_overwritten_whole(tmp_path: Path) -> None:
    files = OutputFiles(tmp_path, [])
    files.reserve("s.json", 100)
    files.write_summary("s.json", {"a": 1})
    assert (tmp_path / "s.json").read_text() == '{\n  "a": 1\n}\n'


def test_promote_replaces_a_previous_overlay_folder(tmp_path: Path) -> None:
    overlay = tmp_path / "overlay"
    overlay.mkdir()
    (overlay / "000009.png").write_bytes(b"old")
    partial_path(overlay).mkdir()
    (partial_path(overlay) / "000000.png").write_bytes(b"new")
    OutputFiles(tmp_path, [], [overlay]).promote("s.json")
    assert sorted(p.name for p in overlay.iterdir()) == ["000000.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["overlay"]


def test_first_signal_sets_the_flag_second_interrupts() -> None:
    flag = StopFlag()
    with stop_on_signals(flag):
        os.kill(os.getpid(), signal.SIGTERM)
        assert flag.signum == signal.SIGTERM
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGTERM)
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


def test_outputs_that_are_inputs_are_refused(tmp_path: Path) -> None:
    (tmp_path / "b.csv").write_text("x")
    with pytest.raises(ConfigurationError, match="would be overwritten"):
        check_outputs_spare_inputs([tmp_path / "." / "b.csv"], [tmp_path / "b.csv", None])
    with pytest.raises(ConfigurationError, match="would be overwritten"):
        check_outputs_spare_inputs([], [tmp_path], tmp_path)
    check_outputs_spare_inputs([tmp_path / "c.csv", None], [tmp_path / "b.csv"], tmp_path / "o")


def test_an_output_that_is_a_hard_link_to_an_input_is_refused(tmp_path: Path) -> None:
    """`slopedist estimate --calib calib.txt ... --out link.txt`, link.txt a hard link of
    calib.txt: the records replaced the calibration."""
    calib = tmp_path / "calib.txt"
    calib.write_text("P2: 1 0 0 0 0 1 0 0 0 0 1 0\n")
    link = tmp_path / "link.txt"
    os.link(calib, link)
    with pytest.raises(ConfigurationError, match=r"link.txt is the input .*calib.txt"):
        check_outputs_spare_inputs([link], [tmp_path / "poses.txt", calib])
    (tmp_path / "copy.txt").write_text(calib.read_text())  # the same content is not the file
    check_outputs_spare_inputs([tmp_path / "copy.txt"], [calib])
