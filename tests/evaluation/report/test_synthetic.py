"""``slopedist report`` on a ``slopedist demo`` output (the synthetic-hill suite): the tables agree
with the demo's own, θ is compared with the true θ, the HTML page has its figures."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import shutil
from pathlib import Path

import pytest

from slopedist.cli import main
from slopedist.core.errors import InputFileError
from slopedist.evaluation.report import ReportOptions, SourceKind, detect_source, report_data
from slopedist.synthetic.demo import DemoConfig, run_demo

FRAMES = 8
SCENARIOS = ("same_flat", "target_steep_uphill")
METHODS = ("flat", "paper", "imu", "depthmap")


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def demo_report(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, str]:
    pytest.importorskip("slopedist.odometry.visual")
    root = tmp_path_factory.mktemp("demo_report")
    demo = root / "demo"
    run_demo(
        DemoConfig(
            demo,
            SCENARIOS,
            METHODS,
            "visual",
            video=False,
            plots=False,
            max_frames=FRAMES,
            progress=False,
        ),
        echo=lambda s: None,
    )
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["report", str(demo), "--out", str(root / "report"), "--no-parquet"]) == 0
    return demo, root / "report", buf.getvalue()


def test_table1_is_the_demo_rmse_per_scenario_and_method(
    demo_report: tuple[Path, Path, str],
) -> None:
    demo, out, printed = demo_report
    assert detect_source(demo) is SourceKind.SYNTHETIC
    assert "Table 1: RMSE (m) per sequence and method" in printed
    mine = {r["sequence"]: r for r in read_csv(out / "table1_rmse.csv")}
    theirs = {r["scenario"]: r for r in read_csv(demo / "rmse.csv")}
    assert set(mine) == set(theirs) == {*SCENARIOS, "overall"}
    for sc, row in theirs.items():
        assert int(mine[sc]["n"]) == int(row["n"]) > 0
        for m in METHODS:
            assert float(mine[sc][m]) == pytest.approx(float(row[m]), abs=1e-3)
    metrics = {r["method"]: r for r in read_csv(out / "metrics_overall.csv")}
    assert set(metrics) == set(METHODS)
    assert 0 < float(metrics["paper"]["δ<1.25"]) <= 1
    assert (out / "metrics_by_distance.csv").is_file()


def test_table2_and_theta_come_from_the_demo(demo_report: tuple[Path, Path, str]) -> None:
    demo, out, _ = demo_report
    mine = {r["method"]: r for r in read_csv(out / "table2_time.csv")}
    theirs = {r["method"]: r for r in read_csv(demo / "timing.csv")}
    for m in METHODS:
        assert float(mine[m]["estimation"]) == pytest.approx(
            float(theirs[m]["estimation_ms"]), rel=1e-3, abs=1e-3
        )
        assert mine[m]["depth"] == ""  # simulated depth noise: nothing inferred
    assert float(mine["paper"]["odometry"]) == pytest.approx(
        float(theirs["paper"]["odometry_ms"]), rel=1e-3
    )
    assert mine["imu"]["odometry"] == "" and mine["flat"]["odometry"] == ""
    results = json.loads((demo / "results.json").read_text())
    theta = {r["sequence"]: r for r in read_csv(out / "theta_agreement.csv")}
    for sc in SCENARIOS:
        ok_frames = results["scenarios"][sc]["odometry_states"].get("ok", 0)
        assert theta[sc]["source"] == "run"
        assert 0 < int(theta[sc]["frames"]) <= ok_frames
        assert float(theta[sc]["RMS diff"]) < 0.5  # degrees, the odometry on rendered frames


def test_html_page_has_every_figure(demo_report: tuple[Path, Path, str]) -> None:
    _, out, _ = demo_report
    page = (out / "report.html").read_text()
    assert page.count('src="data:image/png;base64,') == 3
    for name in ("distance_over_time.png", "error_vs_distance.png", "theta_over_time.png"):
        assert (out / "figures" / name).stat().st_size > 5000
    assert "synthetic" in page


def test_damaged_demo_results_name_the_file(
    demo_report: tuple[Path, Path, str], tmp_path: Path
) -> None:
    demo, _, _ = demo_report
    copy = tmp_path / "demo"
    shutil.copytree(demo, copy)
    (copy / "results.json").write_text("{not json")
    with pytest.raises(InputFileError, match=r"results\.json.*not valid JSON"):
        report_data(copy, ReportOptions())
    (copy / "results.json").write_text(json.dumps({"scenarios": {"same_flat": {"frames": "x"}}}))
    with pytest.raises(InputFileError, match=r"results\.json.*frames is not a number"):
        report_data(copy, ReportOptions())


def test_a_scenario_folder_of_an_earlier_demo_is_not_read(
    demo_report: tuple[Path, Path, str], tmp_path: Path
) -> None:
    """A demo into the --out of an earlier one over other scenarios leaves their folders: the
    report reads the scenarios results.json lists (it failed on the stale one's timing)."""
    demo, _, _ = demo_report
    copy = tmp_path / "demo"
    shutil.copytree(demo, copy)
    shutil.copytree(copy / "same_flat", copy / "ego_crest")  # left by an earlier demo
    assert report_data(copy, ReportOptions()).sequences == sorted(SCENARIOS)
