"""The estimators' options: a bad value is a usage error naming the option."""

from __future__ import annotations

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
