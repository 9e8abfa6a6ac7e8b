"""The estimators' options: a bad value is a usage error naming the option."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from slopedist.cli import cli


@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("--alphas", "nan,5,6"),
        ("--alphas", "3,inf,6"),
        ("--thresholds", "0,-10,-inf"),
        ("--depth-mean", "nan,0,0"),
        ("--depth-std", "1,1,inf"),
    ],
)
@pytest.mark.parametrize("command", [["run", "x"], ["eval", "kitti-tracking", "x"]])
def test_a_triple_that_is_not_finite_is_a_usage_error(
    command: list[str], option: str, value: str
) -> None:
    """``--alphas nan,5,6`` ran to the end (eq. 7 with a NaN step), ``--thresholds 0,-10,-inf``
    passed the decreasing check, ``--depth-mean nan,0,0`` fed the depth model NaNs."""
    if option.startswith("--depth-"):
        if command[0] != "run":
            return
        command = [*command, "--depth-model", "model.onnx", "--depth-input-size", "640x192"]
    result = CliRunner().invoke(cli, [*command, option, value])
    assert result.exit_code == 2, result.output
    assert f"Invalid value for {option}: '{value}' is not three finite numbers" in result.output


@pytest.mark.parametrize(
    "command",
    [
        ["eval", "kitti-tracking"],  # its default methods (flat, ego, paper) have no offline mode
        ["eval", "kitti-tracking", "--methods", "paper"],
        ["report", "--methods", "flat,paper", "--out", "OUT"],
    ],
)
def test_offline_without_a_method_that_has_one_is_a_usage_error(
    command: list[str], kitti_tracking_dir: Path, tmp_path: Path
) -> None:
    """``eval kitti-tracking DIR --offline`` ran flat, ego and paper and printed no offline
    figure and no word about it; the offline figures asked for are there, or an error says
    why not."""
    args = [a.replace("OUT", str(tmp_path / "out")) for a in command]
    args.insert(2 if command[0] == "eval" else 1, str(kitti_tracking_dir))
    result = CliRunner().invoke(cli, [*args, "--sequences", "0001", "--offline"])
    assert result.exit_code == 2, result.output
    assert "--offline: none of the methods" in result.output
    assert "methods with one: ours" in result.output
    assert not (tmp_path / "out").exists()
