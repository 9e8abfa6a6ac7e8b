"""End to end on a short synthetic scenario: ``slopedist simulate`` → ``slopedist run`` (three
methods, from the rendered pixels, into the simulation's folder) → ``slopedist report`` on the
folder of simulations scores them in one Table 1 row and compares θ with the true θ."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest

from slopedist.cli import main
from slopedist.core.errors import MissingInputError
from slopedist.evaluation.report import detect_source
from slopedist.io.detections.readers import read_box_csv

FRAMES = 14
SCENARIO = "ego_crest"


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def chain(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    pytest.importorskip("slopedist.odometry.visual")
    root = tmp_path_factory.mktemp("chain")
    sim = root / "sim"
    assert (
        main(["simulate", SCENARIO, "--out", str(sim), "--frames", str(FRAMES), "--depth", "png"])
        == 0
    )
    info = json.loads((sim / "info.json").read_text())
    camera = [
        "--height",
        str(info["camera_height_m"]),
        "--mount-angle",
        str(info["mount_angle_deg"]),
    ]
    common = [
        str(sim / "image_02"),
        "--calib",
        str(sim / "calib.txt"),
        "--boxes",
        str(sim / "boxes.csv"),
        "--timestamps",
        str(sim / "times.txt"),
        *camera,
        "--quiet",
    ]
    for method in ("paper", "flat"):
        assert main(["run", *common, "--method", method, "--out", str(sim / method)]) == 0
    assert (
        main(
            [
                "run",
                *common,
                "--method",
                "depthmap",
                "--odometry",
                "none",
                "--depth-dir",
                str(sim / "depth"),
                "--out",
                str(sim / "depthmap"),
            ]
        )
        == 0
    )
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["report", str(root), "--out", str(root / "report"), "--no-parquet"]) == 0
    return root, buf.getvalue()


def test_records_carry_the_true_distance_of_each_target(chain: tuple[Path, str]) -> None:
    root, _ = chain
    truth = {
        (r["frame"], r["track_id"]): float(r["z_m"]) for r in read_csv(root / "sim" / "truth.csv")
    }
    rows = read_csv(root / "sim" / "paper" / "records.csv")
    assert len(rows) >= FRAMES
    for r in rows:
        assert float(r["gt_distance_m"]) == pytest.approx(
            truth[(r["frame"], r["track_id"])], rel=1e-5
        )
    exact = read_box_csv(root / "sim" / "boxes_exact.csv")
    np.testing.assert_allclose(exact.extra["gt_distance_m"], exact_z(root / "sim"), rtol=1e-5)
    # the image folder is image_02: the sequence is named after the simulation folder
    assert json.loads((root / "sim" / "paper" / "run.json").read_text())["sequence"] == "sim"


def test_report_scores_every_method_in_one_row(chain: tuple[Path, str]) -> None:
    root, printed = chain
    assert "Table 1: RMSE (m) per sequence and method" in printed
    table1 = {r["sequence"]: r for r in read_csv(root / "report" / "table1_rmse.csv")}
    assert set(table1) == {"sim", "overall"}
    for method in ("paper", "flat", "depthmap"):
        rows = [r for r in read_csv(root / "sim" / method / "records.csv") if r["distance_m"]]
        err = [min(float(r["distance_m"]), 80.0) - float(r["gt_distance_m"]) for r in rows]
        assert len(rows) > FRAMES // 2
        assert float(table1["sim"][method]) == pytest.approx(
            math.sqrt(float(np.mean(np.square(err)))), rel=1e-3, abs=1e-3
        )
    # true depth at the box centre: within a few metres of KITTI z (centre vs. rear face)
    assert float(table1["sim"]["depthmap"]) < 5.0
    timing = {r["method"]: r for r in read_csv(root / "report" / "table2_time.csv")}
    assert float(timing["paper"]["odometry"]) > 0 and timing["depthmap"]["odometry"] == ""
    assert timing["flat"]["odometry"] == ""  # flat ran with odometry but does not use it
    assert float(timing["depthmap"]["depth"]) > 0 and timing["paper"]["depth"] == ""
    html = (root / "report" / "report.html").read_text()
    assert html.count('src="data:image/png;base64,') == 3


def exact_z(sim: Path) -> list[float]:
    return [float(r["z"]) for r in read_csv(sim / "boxes_exact.csv")]


def test_a_simulation_without_runs_says_what_to_do(tmp_path: Path, chain: tuple[Path, str]) -> None:
    root, _ = chain
    sim = tmp_path / "sims" / "bare"
    sim.mkdir(parents=True)
    for name in ("truth.csv", "info.json"):
        (sim / name).write_bytes((root / "sim" / name).read_bytes())
    with pytest.raises(MissingInputError, match=r"holds the truth but no estimates.*slopedist run"):
        detect_source(tmp_path / "sims")


def test_theta_of_each_run_is_compared_with_the_simulated_truth(chain: tuple[Path, str]) -> None:
    root, _ = chain
    truth = {r["frame"]: float(r["theta_true_deg"]) for r in read_csv(root / "sim" / "frames.csv")}
    rows = read_csv(root / "report" / "theta_agreement.csv")
    assert {r["source"] for r in rows} == {"paper", "flat"}  # depthmap ran without odometry
    for r in rows:
        run = [x for x in read_csv(root / "sim" / r["source"] / "frames.csv") if x["theta_deg"]]
        diff = [float(x["theta_deg"]) - truth[x["frame"]] for x in run]
        assert int(r["frames"]) == len(run) >= FRAMES - 2
        assert float(r["RMS diff"]) == pytest.approx(
            math.sqrt(float(np.mean(np.square(diff)))), abs=2e-3
        )
