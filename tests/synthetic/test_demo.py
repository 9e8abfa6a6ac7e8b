"""``slopedist demo``: a short run of the suite from rendered pixels, its files and tables."""

from __future__ import annotations

import csv
import json
import math
import warnings
from pathlib import Path
from typing import ClassVar

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from slopedist.cli import main
from slopedist.estimators import ESTIMATORS
from slopedist.estimators.ground_contact import EgoGradientEstimator
from slopedist.evaluation.accuracy_tables import uncertainty_table
from slopedist.odometry.base import OdometryResult, OdometryState, RotationTrack
from slopedist.odometry.jumps import JumpMarks
from slopedist.streaming.step import ego_gradients
from slopedist.synthetic import demo_scenario
from slopedist.synthetic.demo import (
    DemoConfig,
    demo_tables,
    format_demo_tables,
    plan_methods,
    pooled_scores,
    run_demo,
)
from slopedist.synthetic.scenarios import load_scenario
from slopedist.synthetic.sequence import SyntheticSequence

FRAMES = 8
SCENARIOS = ("same_flat", "target_steep_uphill")


class _LidarEstimator(EgoGradientEstimator):
    """A method bound to a rotation source the demo does not simulate."""

    name: ClassVar[str] = "lidar-test"
    rotation_source: ClassVar[str | None] = "lidar"


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("demo")
    pytest.importorskip("slopedist.odometry.visual")
    cfg = DemoConfig(out, SCENARIOS, None, "visual", True, True, FRAMES, False)
    return run_demo(cfg, echo=lambda s: None)


def test_files_are_written(demo_run) -> None:
    out = demo_run.config.out_dir
    for name in ("summary.txt", "results.json", "rmse.csv", "timing.csv"):
        assert (out / name).stat().st_size > 0
    for sc in SCENARIOS:
        folder = out / sc
        assert (folder / "distance.png").stat().st_size > 1000
        assert (folder / "theta.png").stat().st_size > 1000
        video = folder / "overlay.mp4"
        if not video.exists():
            video = folder / "overlay.gif"
        assert video.stat().st_size > 1000
    data = json.loads((out / "results.json").read_text())
    assert set(data["scenarios"]) == set(SCENARIOS)
    assert data["scenarios"]["same_flat"]["frames"] == FRAMES


def test_the_demo_overlays_are_h264_browsers_play(demo_run) -> None:
    """With the core dependencies (PyAV's wheels carry an H.264 encoder) the demo's overlays
    read back as H.264 (FourCC avc1), and ``results.json`` says so."""
    out = demo_run.config.out_dir
    for sc in SCENARIOS:
        cap = cv2.VideoCapture(str(out / sc / "overlay.mp4"))
        code = int(cap.get(cv2.CAP_PROP_FOURCC))
        cap.release()
        assert "".join(chr((code >> (8 * i)) & 0xFF) for i in range(4)).lower() in {"avc1", "h264"}
    config = json.loads((out / "results.json").read_text())["config"]
    assert config["overlay_codec"].startswith("h264") and config["overlay_warning"] is None


def test_every_available_method_runs_and_the_table_matches_the_records(demo_run) -> None:
    methods = demo_run.methods
    assert {"flat", "ego", "paper"} <= set(methods)
    text = format_demo_tables(demo_run)
    assert "Table 1" in text and "Table 2" in text
    for sc, run in zip(SCENARIOS, demo_run.runs):
        rows = list(csv.DictReader((demo_run.config.out_dir / sc / "records.csv").open()))
        assert {r["method"] for r in rows} == set(methods)
        for m in ("flat", "paper"):
            mine = [r for r in rows if r["method"] == m]
            d = np.array([float(r["distance_m"]) if r["distance_m"] else math.nan for r in mine])
            d = np.where([r["reason"] == "below_horizon" for r in mine], 80.0, np.minimum(d, 80))
            z = np.array([float(r["truth_z_m"]) for r in mine])
            ok = np.isfinite(d)
            rmse = float(np.sqrt(np.mean((d[ok] - z[ok]) ** 2)))
            assert run.scores[m].metrics()["rmse"] == pytest.approx(rmse, rel=1e-4)
            assert run.scores[m].metrics()["n"] == int(ok.sum())


def test_the_summary_scores_ours_own_sigma(demo_run) -> None:
    """ours reports a σ per target: the summary has the uncertainty table with its row (and
    no row for a method without one), the shares as the records give them."""
    table = uncertainty_table(pooled_scores(demo_run))
    assert table is not None and "ours" in [r[0] for r in table.rows]
    assert "flat" not in [r[0] for r in table.rows]
    assert "Uncertainty" in format_demo_tables(demo_run)
    err, sigma = [], []
    for run in demo_run.runs:
        ours = run.scores["ours"]
        for d, z, reason, s in zip(ours.distance, ours.truth, ours.reason, ours.sigma):
            if not reason:  # estimated: capped at 80 m as the tables do
                err.append(min(d, 80.0) - z)
                sigma.append(s)
    within_2 = float(np.mean(np.abs(err) <= 2 * np.asarray(sigma)))
    row = next(r for r in table.rows if r[0] == "ours")
    assert row[1] == len(err) and row[3] == pytest.approx(within_2)
    assert 0.0 < row[2] <= row[3] <= row[4] <= 1.0


def test_the_tables_and_plots_say_what_their_truth_is(demo_run) -> None:
    """Table 1, the targets counted at the cap and the uncertainty table name the synthetic
    truth and the point of the vehicle it refers to (not "KITTI z", which named a dataset)."""
    tables = demo_tables(demo_run)
    table1, at_cap, *_, sigma = tables
    assert table1.title.startswith("Table 1. RMSE (m) against the synthetic truth (vehicle centre)")
    assert "against the synthetic truth" in at_cap.title
    assert sigma.title == (
        "Uncertainty: errors against the synthetic truth (vehicle centre) within the methods' own σ"
    )
    assert not any("against KITTI z" in t.title for t in tables)
    results = json.loads((demo_run.config.out_dir / "results.json").read_text())
    assert results["protocol"]["distance"].startswith("the synthetic truth (vehicle centre)")


def test_flat_road_estimates_are_close_to_the_truth(demo_run) -> None:
    # same_flat, first frames: every method within a few metres (the rear-face offset of
    # half a car length is part of the protocol's error)
    run = demo_run.runs[0]
    for m in ("flat", "ego", "paper"):
        assert run.scores[m].metrics()["rmse"] < 5.0


def test_methods_the_demo_cannot_feed_are_skipped_with_a_reason(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setitem(ESTIMATORS, "lidar-test", _LidarEstimator)
    from slopedist.core.camera import Camera

    plans = {
        p.name: p
        for p in plan_methods(
            ["paper", "imu", "depthmap", "lidar-test"], Camera(721.5, 609.6, 172.9)
        )
    }
    assert plans["paper"].rotation == "odometry" and not plans["paper"].skipped
    assert plans["imu"].rotation == "imu"
    assert plans["depthmap"].depth and plans["depthmap"].rotation == "none"
    assert "lidar" in plans["lidar-test"].skipped


def test_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(
        [
            "demo",
            "--out",
            str(tmp_path / "d"),
            "--scenarios",
            "curve_flat",
            "--frames",
            "3",
            "--methods",
            "flat,paper",
            "--odometry",
            "truth",
            "--no-video",
            "--no-plots",
            "--quiet",
        ]
    )
    assert code == 0
    out = capsys.readouterr().out
    assert "Table 1" in out and "curve_flat" in out and "TRUE rotations" in out
    assert str(tmp_path / "d" / "summary.txt") in out
    assert main(["demo", "--out", str(tmp_path / "e"), "--methods", "nope"]) == 2
    assert main(["demo", "--out", str(tmp_path / "e"), "--scenarios", "nope.toml"]) == 2


def test_a_scenario_without_targets_runs_and_the_summary_says_so(tmp_path: Path) -> None:
    empty = tmp_path / "empty_road.toml"
    empty.write_text("duration_s = 0.4\n[ego]\nspeed_kmh = 30.0\n")
    out = tmp_path / "d"
    cfg = DemoConfig(
        out, (str(empty), "same_flat"), ("flat", "paper"), "truth", True, True, 3, False
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no matplotlib warning about an empty legend
        result = run_demo(cfg, echo=lambda s: None)
    summary = (out / "summary.txt").read_text()
    assert "empty_road: no box in any frame" in summary
    assert "same_flat: no box" not in summary
    for name in ("records.csv", "frames.csv", "distance.png", "theta.png"):
        assert (out / "empty_road" / name).is_file(), name
    assert list(csv.DictReader((out / "empty_road" / "records.csv").open())) == []
    assert [r.frames for r in result.runs] == [3, 3]


@pytest.mark.parametrize("value", ["", ",", " , "])
def test_an_empty_scenario_list_is_refused(
    tmp_path: Path, value: str, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "d"
    assert main(["demo", "--out", str(out), "--scenarios", value, "--frames", "1", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "'--scenarios'" in err and "names nothing" in err and "same_flat" in err
    assert not out.exists()


@pytest.mark.parametrize("value", ["", ","])
def test_an_empty_method_list_is_refused(
    tmp_path: Path, value: str, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "d"
    args = ["demo", "--out", str(out), "--methods", value, "--frames", "1", "--quiet"]
    assert main(args) == 2  # it ran every method
    assert "'--methods'" in capsys.readouterr().err and not out.exists()


def test_cli_estimator_options_reach_the_methods(tmp_path: Path) -> None:
    """``--alphas`` configures ``paper`` and ``imu`` in the demo as in every other command."""
    args = ["demo", "--scenarios", "target_steep_uphill", "--frames", "3", "--methods"]
    args += ["paper,imu,ego", "--odometry", "truth", "--no-video", "--no-plots", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "default")]) == 0
    # every target below the last threshold: θ + α3
    steep = ["--alphas", "20,30,40", "--thresholds", "1000,999,998"]
    assert main([*args, "--out", str(tmp_path / "steep"), *steep]) == 0

    def adjusted(folder: str) -> dict[str, list[str]]:
        path = tmp_path / folder / "target_steep_uphill" / "records.csv"
        rows = list(csv.DictReader(path.open()))
        return {
            m: [r["theta_adj_deg"] for r in rows if r["method"] == m]
            for m in ("paper", "imu", "ego")
        }

    default, steeper = adjusted("default"), adjusted("steep")
    assert default["ego"] == steeper["ego"]
    for m in ("paper", "imu"):
        assert default[m] != steeper[m], m
        assert all(
            float(a) - float(d) == pytest.approx(40.0, abs=1e-3)
            for a, d in zip(steeper[m], default[m])
        )


RESTART = 5
"""Frame at which the stub odometry below restarts (segment 1)."""


class _RestartingOdometry:
    """The true rotations until :data:`RESTART`, then a new segment whose rotations carry an
    arbitrary pitch offset (rotations of different segments are not related)."""

    def __init__(self, R_true: np.ndarray) -> None:
        self._R = R_true
        self._k = 0

    def process(self, image_gray, timestamp_s, mask_boxes=None):  # type: ignore[no-untyped-def]
        k, self._k = self._k, self._k + 1
        if k < RESTART:
            return OdometryResult(self._R[k], OdometryState.OK, 100, 0)
        return OdometryResult(self._R[k] @ _PITCH_OFFSET, OdometryState.OK, 100, 1)

    def reset(self) -> None:
        self._k = 0


_PITCH_OFFSET = Rotation.from_euler("x", 0.2).as_matrix()


def test_theta_does_not_look_back_across_an_odometry_restart(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    scenario, n = "ego_crest", 16
    seq = SyntheticSequence(load_scenario(scenario))
    R_true = seq.truth.poses_cam0()[:n, :3, :3]
    t = seq.truth.timestamps_s[:n]
    monkeypatch.setattr(
        demo_scenario, "visual_odometry", lambda camera: _RestartingOdometry(R_true)
    )
    cfg = DemoConfig(tmp_path, (scenario,), ("ego",), "visual", False, False, n, False)
    run = run_demo(cfg, echo=lambda s: None).runs[0]
    # θ of each segment on its own (the batch path), never from the other segment's rotations
    mount = seq.camera.mount_angle_rad
    R_odo = np.concatenate([R_true[:RESTART], R_true[RESTART:] @ _PITCH_OFFSET])
    expected = np.concatenate(
        [
            ego_gradients(RotationTrack.from_arrays(t[:RESTART], R_odo[:RESTART]), mount),
            ego_gradients(RotationTrack.from_arrays(t[RESTART:], R_odo[RESTART:]), mount),
        ]
    )
    np.testing.assert_allclose(run.theta_est, expected, atol=1e-9)
    unguarded = JumpMarks(np.zeros(n, bool), np.zeros(n, np.int64))  # no jump check either
    across = ego_gradients(RotationTrack.from_arrays(t, R_odo), mount, jumps=unguarded)
    assert np.max(np.abs(across - expected)) > 0.1  # the restart would show if crossed
    # the estimates use that θ, and frames.csv logs it
    rows = list(csv.DictReader((tmp_path / scenario / "records.csv").open()))
    for r in rows:
        theta = math.degrees(expected[int(r["frame"])])
        assert float(r["theta_deg"]) == pytest.approx(theta, rel=1e-5, abs=1e-9)
    logged = [
        float(r["theta_deg"]) for r in csv.DictReader((tmp_path / scenario / "frames.csv").open())
    ]
    np.testing.assert_allclose(logged, np.degrees(expected), atol=1e-4)


def test_tables_and_frame_logs_have_lf_line_ends_and_results_json_is_strict(demo_run) -> None:
    out = demo_run.config.out_dir
    csvs = [out / "rmse.csv", out / "timing.csv", *sorted(out.glob("*/frames.csv"))]
    assert len(csvs) == 2 + len(SCENARIOS)
    for path in csvs:
        assert b"\r" not in path.read_bytes(), path
    json.loads(
        (out / "results.json").read_text(),
        parse_constant=lambda c: pytest.fail(f"non-strict JSON token {c}"),
    )
    rmse = list(csv.DictReader((out / "rmse.csv").open()))
    assert [r["scenario"] for r in rmse] == [*SCENARIOS, "overall"]


def test_scenarios_in_worker_processes_give_the_same_figures(tmp_path: Path) -> None:
    """Two scenarios run at once in worker processes (their plots written by tasks of their
    own) write what one after the other writes (timings aside), and list the same files."""
    outputs = []
    for jobs in (1, 2):
        out = tmp_path / f"jobs{jobs}"
        cfg = DemoConfig(
            out, SCENARIOS, ("flat", "ours"), "visual", False, True, 6, False, jobs=jobs
        )
        result = run_demo(cfg, echo=lambda s: None)
        assert [r.name for r in result.runs] == list(SCENARIOS)
        records = [(out / s / "records.csv").read_text() for s in SCENARIOS]
        rmse = (out / "rmse.csv").read_text()
        files = [[str(Path(f).relative_to(out)) for f in r.files] for r in result.runs]
        listed = json.loads((out / "results.json").read_text())["scenarios"]
        assert [listed[s]["files"] for s in SCENARIOS] == [r.files for r in result.runs]
        for s in SCENARIOS:
            assert (out / s / "distance.png").stat().st_size > 1000
            assert (out / s / "theta.png").stat().st_size > 1000
        outputs.append((records, rmse, files, [r.theta_est.tolist() for r in result.runs]))
    assert outputs[0] == outputs[1]


def test_demo_jobs_are_checked_and_capped() -> None:
    from slopedist.core.errors import ConfigurationError
    from slopedist.synthetic.demo import demo_jobs

    with pytest.raises(ConfigurationError, match="jobs"):
        DemoConfig(jobs=0)
    assert demo_jobs(DemoConfig(scenarios=("same_flat",), jobs=4)) == 1
    assert 1 <= demo_jobs(DemoConfig(scenarios=SCENARIOS)) <= 2


@pytest.mark.parametrize("name", ["..", ".", ".hidden", "-x", "a..b/..", "/abs", "a/b", "a\\\\b"])
def test_a_scenario_name_cannot_write_outside_out(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str
) -> None:
    from slopedist.synthetic.scenarios import builtin_text

    text = builtin_text("same_flat").replace('name = "same_flat"', f'name = "{name}"')
    evil = tmp_path / "evil.toml"
    evil.write_text(text, encoding="utf-8")
    out = tmp_path / "deep" / "out"
    before = sorted(p.name for p in tmp_path.iterdir())
    code = main(["demo", "--scenarios", str(evil), "--out", str(out), "--frames", "2", "--quiet"])
    assert code == 2
    err = capsys.readouterr().err
    assert "cannot name an output folder" in err or "must be letters" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written beside OUT
    assert not out.exists() or not any(out.iterdir())


def test_scenario_folder_accepts_plain_names(tmp_path: Path) -> None:
    from slopedist.synthetic.demo import scenario_folder

    assert scenario_folder(tmp_path, "my_hill-2.v1") == tmp_path / "my_hill-2.v1"


def test_the_targets_counted_at_the_cap_include_the_near_horizon_ones() -> None:
    scores = demo_scenario.MethodScores(
        distance=[math.nan, math.nan, 10.0, math.nan],
        reason=["below_horizon", "near_horizon", "", "no_rotation"],
        truth=[50.0, 60.0, 10.0, 20.0],
    )
    m = scores.metrics()
    assert (m["n"], m["below_horizon"], m["unscored"]) == (3, 2, 1)


class _GlitchingOdometry(_RestartingOdometry):
    """The true rotations, pitched 5° in frame :data:`GLITCH` alone (an odometry glitch)."""

    def process(self, image_gray, timestamp_s, mask_boxes=None):  # type: ignore[no-untyped-def]
        k, self._k = self._k, self._k + 1
        R = self._R[k] @ Rotation.from_euler("x", 5, degrees=True).as_matrix()
        return OdometryResult(R if k == GLITCH else self._R[k], OdometryState.OK, 100, 0)


GLITCH = 8


def test_an_odometry_glitch_is_odometry_jump_in_the_demo(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    scenario, n = "ego_crest", 12
    R_true = SyntheticSequence(load_scenario(scenario)).truth.poses_cam0()[:n, :3, :3]
    monkeypatch.setattr(demo_scenario, "visual_odometry", lambda camera: _GlitchingOdometry(R_true))
    cfg = DemoConfig(tmp_path, (scenario,), ("paper",), "visual", False, False, n, False)
    run = run_demo(cfg, echo=lambda s: None).runs[0]
    assert math.isnan(run.theta_est[GLITCH]) and np.isfinite(run.theta_est[GLITCH + 1 :]).all()
    rows = list(csv.DictReader((tmp_path / scenario / "records.csv").open()))
    glitch = [r for r in rows if int(r["frame"]) == GLITCH]
    assert glitch and {r["reason"] for r in glitch} == {"odometry_jump"}
    assert {r["status"] for r in rows if int(r["frame"]) == GLITCH + 1} == {"ok"}
    # the frame log and the summary say the rotation was a jump, not that the odometry was ok
    log = list(csv.DictReader((tmp_path / scenario / "frames.csv").open()))
    assert [r["odometry_state"] for r in log].count("odometry_jump") == 1
    assert log[GLITCH]["odometry_state"] == "odometry_jump"
    assert run.odometry_states == {"ok": n - 1, "odometry_jump": 1}
