"""Shared options: the camera's mount is checked where it is typed, naming the option."""

from __future__ import annotations

import math
from pathlib import Path

import click
import pytest
from click.testing import CliRunner
from hypothesis import given
from hypothesis import strategies as st

from slopedist.cli import cli
from slopedist.cli.options import BoundedFloat, height_option, mount_option
from slopedist.core.camera import MAX_CAMERA_HEIGHT_M
from slopedist.core.errors import InputFileError
from slopedist.io.calibration import read_calibration


def _echo_mount() -> click.Command:
    @click.command()
    @height_option
    @mount_option
    def echo(height_m: float, mount_angle_deg: float) -> None:
        click.echo(f"{height_m} {mount_angle_deg}")

    return echo


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--height", "0"], "'--height': '0' is not in (0, 50] m"),
        (["--height", "nan"], "'--height': 'nan' is not in (0, 50] m"),
        (["--height", "1e308"], "'--height'"),
        (["--height", "-1.2"], "'--height'"),
        (["--mount-angle", "inf"], "'--mount-angle': 'inf' is not in [-60, 60] °"),
        (["--mount-angle", "61"], "'--mount-angle'"),
        (["--height", "tall"], "'--height': 'tall' is not a valid float"),
    ],
)
def test_a_bad_mount_is_a_usage_error_naming_the_option(args: list[str], message: str) -> None:
    result = CliRunner().invoke(_echo_mount(), args)
    assert result.exit_code == 2 and message in result.output


def test_the_bounds_themselves_are_accepted() -> None:
    args = ["--height", str(MAX_CAMERA_HEIGHT_M), "--mount-angle", "-60"]
    result = CliRunner().invoke(_echo_mount(), args)
    assert result.exit_code == 0 and result.output.split() == ["50.0", "-60.0"]


@given(st.floats(allow_nan=True, allow_infinity=True))
def test_a_bounded_float_keeps_what_is_inside_and_refuses_the_rest(value: float) -> None:
    kind = BoundedFloat(0.0, 50.0, "m")
    inside = math.isfinite(value) and 0.0 < value <= 50.0
    try:
        assert kind.convert(repr(value), None, None) == value and inside
    except click.BadParameter:
        assert not inside


def test_an_implausible_focal_length_names_the_calibration_file(tmp_path: Path) -> None:
    calib = tmp_path / "calib.txt"
    calib.write_text("P2: 10 0 600 0 0 10 180 0 0 0 1 0\n", encoding="utf-8")
    with pytest.raises(InputFileError, match=r"calib.txt: camera focal length f = 10 px"):
        read_calibration(calib)
    result = CliRunner().invoke(cli, ["estimate", "--calib", str(calib), "--height", "0"])
    assert result.exit_code == 2 and "'--height'" in result.output


@pytest.mark.parametrize("command", ["estimate", "run", "eval"])
def test_a_score_threshold_that_is_not_finite_is_a_usage_error(command: str) -> None:
    """``--score nan`` kept every box (no score compares with NaN), ``inf`` none."""
    args = {"estimate": ["estimate"], "run": ["run", "x"], "eval": ["eval", "kitti-tracking", "x"]}
    for bad in ("nan", "inf"):
        result = CliRunner().invoke(cli, [*args[command], "--score", bad])
        assert result.exit_code == 2 and f"'--score': '{bad}' is not a finite number" in (
            result.output
        )


_COMMANDS = {
    "run": ["run", "x"],
    "estimate": ["estimate"],
    "calibrate": ["calibrate"],
    "batch": ["batch", "x"],
    "eval": ["eval", "kitti-tracking", "x"],
    "odometry": ["odometry", "eval", "x"],
    "camera": ["camera", "calibrate", "."],
    "detect": ["detect", "."],
}


@pytest.mark.parametrize(
    ("command", "option", "message"),
    [
        *(
            (c, "--lookback", "a finite number > 0 s")
            for c in _COMMANDS
            if c not in ("camera", "detect")
        ),
        ("estimate", "--frame-period", "in (0, 1000] s"),
        ("calibrate", "--frame-period", "in (0, 1000] s"),
        ("run", "--fps", "in [0.001, 100000] frames/s"),
        ("calibrate", "--fps", "in [0.001, 100000] frames/s"),
        ("calibrate", "--every", "a finite number > 0 s"),
        ("camera", "--square", "a finite number > 0 m"),
        ("run", "--depth-scale", "a finite number > 0"),
    ],
)
@pytest.mark.parametrize("bad", ["nan", "inf", "-inf", "0", "-1", "1e-320"])
def test_a_number_option_refuses_what_is_meaningless_naming_the_option(
    command: str, option: str, message: str, bad: str
) -> None:
    """``FloatRange(min=0, min_open=True)`` let ``nan`` and ``inf`` through (``--lookback nan``
    failed later without naming the option; ``--fps 1e-320`` stopped the run at frame 1 with an
    infinite timestamp)."""
    result = CliRunner().invoke(cli, [*_COMMANDS[command], option, bad])
    if bad == "1e-320" and option != "--fps":  # a tiny duration or size is harmless
        assert f"'{option}'" not in result.output
        return
    assert result.exit_code == 2, result.output
    assert f"Invalid value for '{option}': '{bad}' is not {message}" in result.output


@pytest.mark.parametrize("prefix", ["detect", "run"])
@pytest.mark.parametrize(
    ("option", "bad", "message"),
    [
        *(("pixel-scale", bad, "a finite number > 0") for bad in ("nan", "inf", "0", "-1")),
        *(("score", bad, "in [0, 1]") for bad in ("nan", "inf", "-0.1")),
        *(("iou", bad, "in (0, 1]") for bad in ("nan", "0", "1.5")),
        ("threads", "0", "0 is not in the range x>=1"),
    ],
)
def test_a_meaningless_detector_option_is_a_usage_error(
    prefix: str, option: str, bad: str, message: str
) -> None:
    """``--detector-pixel-scale nan`` (or 0, or negative) fed the network garbage and silently
    gave no detections; ``--detector-score nan`` passed ``FloatRange(0, 1)``."""
    name = f"--{option}" if prefix == "detect" else f"--detector-{option}"
    args = ["detect", ".", name, bad] if prefix == "detect" else ["run", "x", name, bad]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 2, result.output
    assert f"Invalid value for '{name}'" in result.output and message in result.output


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["camera", "calibrate", ".", "--pattern", "9", "--out", "cam.yaml"], "--pattern"),
        (["convert", ".", "out.csv", "--image-size", "wide"], "--image-size"),
        (["detect", ".", "--detector", "m.onnx", "--input-size", "big"], "--input-size"),
    ],
)
def test_a_malformed_size_names_its_option(tmp_path: Path, args: list[str], option: str) -> None:
    """``--pattern 9`` said "Invalid value: expected COLUMNSxROWS of inner corners", naming no
    option (so did ``convert --image-size`` and the detector's input size)."""
    (tmp_path / "m.onnx").write_bytes(b"")
    args = [str(tmp_path / a) if a == "m.onnx" else a for a in args]
    result = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert result.exit_code == 2 and f"Invalid value for {option}: expected" in result.output
