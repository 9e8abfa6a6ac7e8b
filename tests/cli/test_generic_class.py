"""``--generic-class NAME`` of ``run`` and ``estimate``: a class-blind detector's class read by
``ours`` as a mixture of vehicle types, and its refusals."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import pytest

from slopedist import estimators
from slopedist.cli import main
from slopedist.core.camera import Camera

P2 = "721.5 0 609.6 44.9 0 721.5 172.9 0.2 0 0 1 0.003"


@pytest.fixture
def van_called_car(tmp_path: Path) -> list[str]:
    """``estimate`` arguments of a van-sized box (2.1 m tall, 1.9 m wide at 14 m: 101 × 91 px)
    that the detector calls ``car``, six frames of a straight drive."""
    (tmp_path / "calib.txt").write_text(f"P2: {P2}\n")
    poses = tmp_path / "poses.txt"
    poses.write_text("".join(f"1 0 0 0 0 1 0 0 0 0 1 {k:.1f}\n" for k in range(6)))
    boxes = tmp_path / "boxes.csv"
    rows = "".join(f"{k},560,151,651,252,1,car\n" for k in range(6))
    boxes.write_text("frame,left,top,right,bottom,track_id,class\n" + rows)
    calib = str(tmp_path / "calib.txt")
    return ["estimate", "--calib", calib, "--poses", str(poses), "--boxes", str(boxes)]


def _last_row(args: list[str], out: Path, *options: str) -> dict[str, str]:
    assert main([*args, "--method", "ours", "--out", str(out), *options]) == 0
    rows = list(csv.DictReader(out.open()))
    assert rows[-1]["status"] == "ok"
    return rows[-1]


def test_a_generic_class_reaches_ours(van_called_car: list[str], tmp_path: Path) -> None:
    """``--generic-class car`` reads the van-sized ``car`` as a mixture of vehicle types: its
    distance changes and its σ widens; with ``generic_sigma_only=true`` only its σ widens. The
    name is compared without regard to case, as ``--vehicle-classes`` are."""
    given = _last_row(van_called_car, tmp_path / "given.csv")
    mixture = _last_row(van_called_car, tmp_path / "mixture.csv", "--generic-class", "CAR")
    flags = ("--generic-class", "Car", "--ours-option", "generic_sigma_only=true")
    sigma_only = _last_row(van_called_car, tmp_path / "sigma.csv", *flags)
    assert float(mixture["distance_m"]) != pytest.approx(float(given["distance_m"]), rel=1e-3)
    assert float(mixture["sigma_m"]) > float(given["sigma_m"])
    assert sigma_only["distance_m"] == given["distance_m"]
    assert float(sigma_only["sigma_m"]) > 1.5 * float(given["sigma_m"])


def _usage_error(args: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


def test_generic_class_refusals(
    van_called_car: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A generic class for a method that is not ours, one that is not a vehicle class, an
    empty one, and ``generic_sigma_only=true`` without a generic class are usage errors, and
    nothing is written."""
    out = tmp_path / "never.csv"
    args = [*van_called_car, "--out", str(out)]
    err = _usage_error([*args, "--method", "paper", "--generic-class", "car"], capsys)
    assert "--generic-class is for methods ours, ours-selfcal, ours-offline" in err
    assert "'paper'" in err
    err = _usage_error([*args, "--method", "ours", "--generic-class", "Tram"], capsys)
    assert "--generic-class Tram: not one of --vehicle-classes" in err
    err = _usage_error([*args, "--method", "ours", "--generic-class", " "], capsys)
    assert "--generic-class" in err
    sigma_only = ["--ours-option", "generic_sigma_only=true"]
    err = _usage_error([*args, "--method", "ours", *sigma_only], capsys)
    assert "generic_sigma_only=true" in err and "--generic-class NAME" in err
    assert not out.exists()


def test_run_hands_the_generic_classes_to_ours(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``slopedist run --generic-class car`` builds ``ours`` (and with ``--offline``
    ``ours-offline``) with ``generic_classes``; ``generic_sigma_only=true`` alone is refused
    before anything runs."""
    from tests.cli.test_run_cmd import setup

    args = ["run", *setup(tmp_path)]
    built: list[tuple[str, dict[str, Any]]] = []
    make = estimators.make_estimator

    def spy(name: str, camera: Camera, **options: Any) -> Any:
        built.append((name, options))
        return make(name, camera, **options)

    monkeypatch.setattr(estimators, "make_estimator", spy)
    assert main([*args, "--method", "ours", "--offline", "--generic-class", "car"]) == 0
    assert built and all(o.get("generic_classes") == ("car",) for _, o in built)
    assert {name for name, _ in built} == {"ours-offline"}
    built.clear()
    err = _usage_error([*args, "--method", "ours", "--ours-option", "generic_sigma_only=1"], capsys)
    assert "--generic-class NAME" in err and not built
