"""The one top-level error handler: one line per error, exit 2 for user errors, 1 for bugs,
tracebacks only with --debug, a quiet exit on a closed pipe; and commands on empty box tables."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import click
import pytest

from slopedist.cli import DEBUG_ENV, cli, main
from slopedist.core.errors import InputFileError

P2 = "721.5 0 609.6 44.9 0 721.5 172.9 0.2 0 0 1 0.003"
SRC = Path(__file__).resolve().parents[2] / "src"


def _add_command(monkeypatch: pytest.MonkeyPatch, exc: BaseException) -> None:
    def fail() -> None:
        raise exc

    monkeypatch.setitem(cli.commands, "fail", click.Command("fail", callback=fail))


@pytest.mark.parametrize(
    ("exc", "code", "line"),
    [
        (InputFileError("b.csv", "'x' is not a number", line=3, field="left"), 2, "b.csv, line 3"),
        (FileNotFoundError(2, "No such file or directory", "gone.txt"), 2, "(gone.txt)"),
        (PermissionError(13, "Permission denied", "locked.csv"), 2, "Permission denied"),
        (ZeroDivisionError("division by zero"), 1, "internal error: ZeroDivisionError"),
        (IndexError("index 0 is out of bounds"), 1, "run again with --debug"),
    ],
)
def test_every_error_is_one_line_with_its_exit_code(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    exc: Exception,
    code: int,
    line: str,
) -> None:
    monkeypatch.delenv(DEBUG_ENV, raising=False)
    _add_command(monkeypatch, exc)
    assert main(["fail"]) == code
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("slopedist: error: ") and line in err
    assert "Traceback" not in err


@pytest.mark.parametrize("how", ["option", "env"])
def test_debug_shows_the_traceback(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], how: str
) -> None:
    _add_command(monkeypatch, KeyError("row"))
    if how == "env":
        monkeypatch.setenv(DEBUG_ENV, "1")
        argv = ["fail"]
    else:
        monkeypatch.delenv(DEBUG_ENV, raising=False)
        argv = ["--debug", "fail"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err and "raise exc" in err
    assert err.rstrip().endswith("report it)")


def test_usage_errors_help_and_interrupts(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["estimate", "--bogus"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("Usage: slopedist estimate") and "--help" in err[1]
    assert err[-1].startswith("slopedist: error: No such option")  # the house's last line
    assert main(["nosuchcommand"]) == 2
    assert capsys.readouterr().err.splitlines()[-1].startswith("slopedist: error: No such command")
    assert main(["--help"]) == 0 and "Commands:" in capsys.readouterr().out
    assert main(["--version"]) == 0
    _add_command(monkeypatch, KeyboardInterrupt())
    assert main(["fail"]) == 130


def _sequence(folder: Path, n_frames: int, boxes: str) -> list[str]:
    (folder / "calib.txt").write_text(f"P2: {P2}\n")
    (folder / "poses.txt").write_text(
        "".join(f"1 0 0 0 0 1 0 0 0 0 1 {k:.1f}\n" for k in range(n_frames))
    )
    (folder / "boxes.csv").write_text(boxes)
    return [
        "estimate",
        "--calib",
        str(folder / "calib.txt"),
        "--poses",
        str(folder / "poses.txt"),
        "--boxes",
        str(folder / "boxes.csv"),
    ]


def test_closed_pipe_exits_quietly(tmp_path: Path) -> None:
    rows = "".join(f"{k},500,150,600,250,{j}\n" for k in range(2000) for j in range(3))
    argv = _sequence(tmp_path, 2000, "frame,left,top,right,bottom,track_id\n" + rows)
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    env.pop(DEBUG_ENV, None)
    proc = subprocess.Popen(
        [sys.executable, "-m", "slopedist", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
    )
    assert proc.stdout is not None and proc.stderr is not None
    assert proc.stdout.readline().startswith(b"frame,")
    proc.stdout.close()  # what `| head -1` does
    err = proc.stderr.read()
    assert proc.wait(timeout=60) == 0
    assert err == b""


@pytest.mark.parametrize(
    ("boxes", "score"),
    [
        ("frame,left,top,right,bottom,track_id,score\n", None),
        ("frame,left,top,right,bottom,score\n0,500,150,600,250,0.4\n2,500,150,600,250,0.9\n", "2"),
    ],
)
def test_estimate_with_no_box_writes_an_empty_table(
    tmp_path: Path, boxes: str, score: str | None
) -> None:
    out = tmp_path / "records.csv"
    argv = [*_sequence(tmp_path, 5, boxes), "--out", str(out)]
    assert main(argv + (["--score", score] if score else [])) == 0
    rows = list(csv.reader(out.open()))
    assert rows[0][:2] == ["frame", "timestamp_s"] and len(rows) == 1


@pytest.mark.kitti
def test_eval_with_every_detection_filtered_out(
    kitti_tracking_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["eval", "kitti-tracking", str(kitti_tracking_dir), "--methods", "paper"]
    assert main([*argv, "--boxes", "pointrcnn", "--score", "100"]) == 0
    assert "Pooled over all sequences" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "suggestion"),
    [
        (["run", "frames", "--method", "our"], "unknown method 'our'; did you mean 'ours'?"),
        (["run", "frames", "--odometry", "builtn"], "; did you mean 'builtin'?"),
        (["run", "frames", "--columns", "al"], "; did you mean 'all'?"),
        (["estimate", "--reference", "nearest-face"], "; did you mean 'nearest_face'?"),
        (["rn"], "No such command 'rn'; did you mean 'run'?"),
        (["run", "frames", "--ours-option", "box_sigma=1"], "did you mean 'box_sigma_px'?"),
        (
            ["eval", "kitti-trackin"],
            "No such command 'kitti-trackin'; did you mean 'kitti-tracking'?",
        ),
    ],
)
def test_a_mistyped_value_or_command_is_one_line_with_did_you_mean(
    argv: list[str], suggestion: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("slopedist: error: ") and suggestion in err[0]


def test_a_value_like_no_choice_gets_no_suggestion(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "frames", "--method", "zzzz"]) == 2
    err = capsys.readouterr().err
    assert "did you mean" not in err and "choose from flat, ego, paper" in err
