"""``slopedist eval kitti-tracking``: the JSON report is strict JSON, to a file or stdout."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from slopedist.cli import main


def _strict(text: str) -> Any:
    """``json.loads`` that fails on the non-standard NaN / Infinity tokens."""
    return json.loads(text, parse_constant=lambda c: pytest.fail(f"non-strict JSON token {c}"))


def test_json_with_a_missing_method_is_strict(
    kitti_tracking_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # imu has no OXTS poses on 0014: its metrics are NaN, which used to be written as bare NaN
    out = tmp_path / "out.json"
    args = ["eval", "kitti-tracking", str(kitti_tracking_dir), "--methods", "flat,imu"]
    assert main([*args, "--sequences", "0014", "--json", str(out)]) == 0
    text = out.read_text()
    report = _strict(text)
    assert report["methods"]["imu"]["overall"]["rmse"] is None
    assert report["methods"]["flat"]["overall"]["rmse"] == pytest.approx(16.15, abs=0.01)
    assert "Table 1: RMSE (m) per sequence" in capsys.readouterr().out
    assert b"\r" not in out.read_bytes()


def test_json_dash_writes_only_json_to_stdout(
    kitti_tracking_dir: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    kitti_tracking_dir = kitti_tracking_dir.resolve()
    monkeypatch.chdir(tmp_path)
    args = ["eval", "kitti-tracking", str(kitti_tracking_dir), "--methods", "flat,imu"]
    assert main([*args, "--sequences", "0014", "--json", "-"]) == 0
    captured = capsys.readouterr()
    assert _strict(captured.out)["protocol"]["sequences"] == ["0014"]
    assert "Table 1: RMSE (m) per sequence" in captured.err
    assert not (tmp_path / "-").exists()


def test_offline_adds_its_own_row_and_leaves_ours_alone(
    kitti_tracking_dir: Path, tmp_path: Path
) -> None:
    out, off = tmp_path / "causal.json", tmp_path / "offline.json"
    args = ["eval", "kitti-tracking", str(kitti_tracking_dir), "--sequences", "0014"]
    assert main([*args, "--methods", "paper,ours", "--json", str(out)]) == 0
    assert main([*args, "--methods", "paper,ours", "--offline", "--json", str(off)]) == 0
    causal, offline = _strict(out.read_text()), _strict(off.read_text())
    assert list(offline["methods"]) == ["paper", "ours", "ours-offline"]
    for key in ("rmse", "n", "mae"):  # (the timings differ from run to run)
        assert (
            offline["methods"]["ours"]["overall"][key] == causal["methods"]["ours"]["overall"][key]
        )
    rmse = offline["methods"]["ours-offline"]["overall"]["rmse"]
    assert rmse < causal["methods"]["ours"]["overall"]["rmse"]  # 2.87 against 2.94 m


def _without_times(report: Any) -> Any:
    """The report without its measured times (``ms_per_frame``), which differ run to run."""
    if isinstance(report, dict):
        return {k: _without_times(v) for k, v in report.items() if k != "ms_per_frame"}
    if isinstance(report, list):
        return [_without_times(v) for v in report]
    return report


def test_workers_give_the_results_of_one_worker(
    kitti_tracking_dir: Path, tmp_path: Path, ray_instance: Any
) -> None:
    args = ["eval", "kitti-tracking", str(kitti_tracking_dir), "--sequences", "0001,0009,0014"]
    args += ["--methods", "flat,paper,imu,ours"]  # imu: no OXTS on 0014, a missing method
    reports = []
    for workers in ("1", "2"):
        out = tmp_path / f"w{workers}.json"
        assert main([*args, "--workers", workers, "--json", str(out)]) == 0
        reports.append(_strict(out.read_text()))
    assert _without_times(reports[1]) == _without_times(reports[0])
    assert reports[0]["methods"]["paper"]["overall"]["n"] > 0


def test_workers_without_ray_name_the_extra(
    kitti_tracking_dir: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "ray", None)
    args = ["eval", "kitti-tracking", str(kitti_tracking_dir), "--sequences", "0001"]
    assert main([*args, "--workers", "2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "slopedist: error: --workers 2 (one Ray task per sequence) needs the optional package "
        "'ray', which is not installed; install it with: pip install 'slopedist[batch]'"
    ]


def test_the_learned_peer_row_and_a_declared_reference_from_the_command_line(
    kitti_tracking_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out.json"
    args = ["eval", "kitti-tracking", str(kitti_tracking_dir), "--sequences", "0003"]
    args += ["--methods", "flat,learned-peer", "--gt-reference", "centre", "--json", str(out)]
    assert main(args) == 0
    report = _strict(out.read_text())
    assert report["protocol"]["ground_truth"]["reference"] == "centre"
    assert "leave-one-sequence-out" in report["protocol"]["learned_peer"]
    assert report["methods"]["learned-peer"]["overall"]["n"] > 0
    printed = capsys.readouterr().out
    assert "learned-peer: trained leave-one-sequence-out" in printed
    assert "Truth refers to the vehicle's centre; methods compared at the truth's" in printed


def test_an_unknown_method_names_the_learned_peer_among_the_choices(
    kitti_tracking_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["eval", "kitti-tracking", str(kitti_tracking_dir), "--methods", "nope"]
    assert main(args) != 0
    assert "learned-peer" in capsys.readouterr().err


def test_json_that_is_an_input_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`eval kitti-tracking DATA --json DATA/calib/0000.txt` replaced the calibration."""
    calib = tmp_path / "calib" / "0000.txt"
    calib.parent.mkdir()
    calib.write_text("P2: 721.5 0 609.6 44.9 0 721.5 172.9 0.2 0 0 1 0.003\n")
    before = calib.read_text()
    assert main(["eval", "kitti-tracking", str(tmp_path), "--json", str(calib)]) == 2
    assert "would be overwritten" in capsys.readouterr().err
    assert calib.read_text() == before


@pytest.mark.parametrize("command", [["eval", "kitti-tracking"], ["report"]])
def test_a_sequence_list_that_names_nothing_is_a_usage_error(
    kitti_tracking_dir: Path, capsys: pytest.CaptureFixture[str], command: list[str]
) -> None:
    """``--sequences ","`` ran every sequence (an empty list read as the option left out)."""
    assert main([*command, str(kitti_tracking_dir), "--sequences", ","]) == 2
    assert "'--sequences': names nothing" in capsys.readouterr().err


def test_box_size_options_are_checked(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A size σ outside (0, 100] % is a usage error naming the option; sizes asked of RRC's
    boxes (which have none) fail with the reason."""
    (tmp_path / "label_02").mkdir()
    (tmp_path / "label_02" / "0000.txt").write_text("")
    args = ["eval", "kitti-tracking", str(tmp_path), "--methods", "ours"]
    assert main([*args, "--box-sizes", "--box-size-sigma", "0"]) == 2
    assert "--box-size-sigma" in capsys.readouterr().err
    assert main([*args, "--boxes", "rrc", "--box-sizes"]) != 0
    assert "RRC's boxes carry no vehicle size" in capsys.readouterr().err
