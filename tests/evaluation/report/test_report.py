"""``slopedist report``: KITTI tracking (2 sequences) with depth maps, run outputs, the HTML
page in headless Chromium."""

from __future__ import annotations

import csv
import math
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from slopedist.cli import main
from slopedist.core.errors import ConfigurationError, InputFileError, MissingInputError
from slopedist.estimators import causal_methods
from slopedist.evaluation.kitti import KittiEvalConfig, evaluate_kitti_tracking
from slopedist.evaluation.report import (
    ReportOptions,
    SourceKind,
    detect_source,
    report_data,
    report_tables,
    write_report,
)
from slopedist.evaluation.report.tables import metric_records
from slopedist.io.depth import write_kitti_depth_png
from slopedist.io.kitti.tracking import load_sequence, protocol_mask
from slopedist.streaming.step import RECORD_FIELDS
from tests.conftest import shared_data_path

SEQS = ("0000", "0014")


def make_depth_folder(root: Path, kitti: Path, seq: str) -> None:
    """Depth maps of a sequence where every protocol target's box holds its label z (far
    targets drawn first, so nearer ones occlude them), elsewhere no value."""
    s = load_sequence(kitti, seq)
    gt = s.labels.select(protocol_mask(s.labels))
    h, w = 375, 1242
    for k in range(s.n_frames):
        depth = np.zeros((h, w))
        sel = np.flatnonzero(gt.frame == k)
        for i in sel[np.argsort(-gt.extra["z"][sel])]:
            left, top, right, bottom = np.round(gt.boxes[i]).astype(int)
            depth[max(top, 0) : bottom + 1, max(left, 0) : right + 1] = gt.extra["z"][i]
        write_kitti_depth_png(root / seq / f"{k:06d}.png", depth)


@pytest.fixture(scope="module")
def kitti_report(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str, Path]:
    kitti = shared_data_path("kitti_tracking")
    tmp = tmp_path_factory.mktemp("report")
    make_depth_folder(tmp / "depth", kitti, "0000")
    out = tmp / "out"
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(
            [
                "report",
                str(kitti),
                "--sequences",
                ",".join(SEQS),
                "--depth-dir",
                str(tmp / "depth"),
                "--out",
                str(out),
            ]
        )
    assert code == 0
    return out, buf.getvalue(), kitti


def _csv(path: Path) -> list[dict[str, str]]:
    with path.open() as fh:
        return list(csv.DictReader(fh))


def test_kitti_tables_match_the_evaluation(kitti_report: tuple[Path, str, Path]) -> None:
    out, printed, kitti = kitti_report
    assert "Table 1: RMSE (m) per sequence and method" in printed
    assert "Table 2: time per frame (ms)" in printed
    table1 = {r["sequence"]: r for r in _csv(out / "table1_rmse.csv")}
    assert set(table1) == {"0000", "0014", "overall", "common"}
    for m in ("flat", "ego", "paper", "imu", "imu-ego", "depthmap"):
        assert m in table1["0000"]
    ref = evaluate_kitti_tracking(kitti, KittiEvalConfig(sequences=list(SEQS)))
    for m in ("flat", "ego", "paper"):
        for s in SEQS:
            assert float(table1[s][m]) == pytest.approx(
                ref["methods"][m]["sequences"][s]["rmse"], abs=1e-4
            )
    # imu and depthmap have nothing on 0014 (no OXTS there; depth given for 0000 only)
    assert table1["0014"]["imu"] == "" and table1["0014"]["depthmap"] == ""
    # common = 0000 only: equals the 0000 row
    for m in ("paper", "imu", "depthmap"):
        assert float(table1["common"][m]) == pytest.approx(float(table1["0000"][m]))
    # depth maps hold the truth except where a nearer target occludes: small error
    assert float(table1["0000"]["depthmap"]) < 1.5
    assert "imu: no result on 0014" in printed and "no depth maps for sequence 0014" in printed


def test_kitti_outputs_are_complete(kitti_report: tuple[Path, str, Path]) -> None:
    out, _, _ = kitti_report
    md = (out / "report.md").read_text()
    assert "| sequence | n | flat |" in md and "**" in md
    for name in ("distance_over_time.png", "error_vs_distance.png", "theta_over_time.png"):
        assert (out / "figures" / name).stat().st_size > 5000
        assert f"figures/{name}" in md
    page = (out / "report.html").read_text()
    assert page.count('src="data:image/png;base64,') == 3
    assert "<b>" in page and 'src="figures/' not in page  # self-contained
    timing = {r["method"]: r for r in _csv(out / "table2_time.csv")}
    assert timing["depthmap"]["depth"] != "" and float(timing["depthmap"]["depth"]) > 0
    assert timing["paper"]["odometry"] == ""  # precomputed poses: not timed
    records = _csv(out / "records.csv")
    # every registered method runs by default (methods added later included)
    assert {r["method"] for r in records} == set(causal_methods())
    theta = _csv(out / "theta_agreement.csv")
    assert [(r["sequence"], r["source"]) for r in theta] == [("0000", "orbslam3")]
    assert float(theta[0]["RMS diff"]) < 0.1  # ORB-SLAM3 agrees with OXTS to < 0.1°
    metrics = _csv(out / "metrics.csv")
    assert any(r["scope"] == "common" and r["metric"] == "abs_rel" for r in metrics)
    if _has_pyarrow():
        assert (out / "table1_rmse.parquet").is_file() and (out / "records.parquet").is_file()


def _has_pyarrow() -> bool:
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        return False
    return True


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def chromium_command(profile: Path, action: str, page: Path) -> list[str]:
    """Headless Chromium loading ``page`` with a fresh profile and no network chatter, doing
    ``action`` (``--dump-dom``, ``--screenshot=PATH``)."""
    return [
        str(CHROMIUM),
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        f"--user-data-dir={profile}",
        "--virtual-time-budget=10000",
        action,
        page.as_uri(),
    ]


@pytest.mark.skipif(
    CHROMIUM is None,
    reason="headless Chromium not installed (Debian package 'chromium'; .ci/run installs it)",
)
def test_html_figures_render_in_headless_chromium(
    kitti_report: tuple[Path, str, Path], tmp_path: Path
) -> None:
    out, _, _ = kitti_report
    cmd = chromium_command(tmp_path / "profile", "--dump-dom", out / "report.html")
    dom = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False).stdout
    body = re.search(r"<body[^>]*>", dom)
    assert body is not None, f"no <body> in Chromium's DOM dump: {dom[:300]!r}"
    total = re.search(r'data-figures-total="(\d+)"', body.group(0))
    loaded = re.search(r'data-figures-loaded="(\d+)"', body.group(0))
    assert total and loaded, f"the page's load script did not run: {body.group(0)}"
    assert int(total.group(1)) == 3 and int(loaded.group(1)) == 3


# --- run outputs ----------------------------------------------------------------------------


def write_run(
    folder: Path,
    rows: list[dict[str, object]],
    frames: list[dict[str, object]],
    extra: tuple[str, ...] = ("gt_distance_m",),
) -> None:
    """A `slopedist run` output folder: records.csv (RECORD_FIELDS + extras) and frames.csv."""
    folder.mkdir(parents=True)
    with (folder / "records.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=[*RECORD_FIELDS, *extra], restval="")
        w.writeheader()
        w.writerows(rows)
    with (folder / "frames.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(frames[0]))
        w.writeheader()
        w.writerows(frames)


def _record(frame: int, d: float | str, gt: float, reason: str = "") -> dict[str, object]:
    return {
        "frame": frame,
        "timestamp_s": 0.1 * frame,
        "track_id": 3,
        "class": "Car",
        "method": "paper",
        "distance_m": d,
        "status": "missing" if reason else "ok",
        "reason": reason,
        "theta_deg": 0.1,
        "gt_distance_m": gt,
    }


def test_run_output_is_scored_and_timed(tmp_path: Path) -> None:
    rows = [
        _record(0, 10.0, 11.0),
        _record(1, 21.0, 20.0),
        _record(2, "", 30.0, "below_horizon"),
        _record(3, "", 30.0, "no_rotation"),
        _record(4, 95.0, 70.0),
    ]
    frames = [
        {
            "frame": k,
            "timestamp_s": 0.1 * k,
            "theta_deg": 0.1 * k,
            "theta_true_deg": 0.1 * k + 0.05,
            "odometry_ms": 10.0 + k,
            "estimation_ms": 1.0,
            "depth_ms": "",
        }
        for k in range(5)
    ]
    write_run(tmp_path / "seqA", rows, frames)
    assert detect_source(tmp_path / "seqA") is SourceKind.RUN
    assert detect_source(tmp_path) is SourceKind.RUN  # a folder of run outputs
    data = report_data(tmp_path, ReportOptions())
    assert data.methods == ["paper"] and data.sequences == ["seqA"]
    # below_horizon → 80 m, 95 → 80 m (cap), no_rotation unscored
    err = np.array([10 - 11, 21 - 20, 80 - 30, 80 - 70])
    assert data.overall["paper"]["rmse"] == pytest.approx(math.sqrt(np.mean(err**2)))
    assert data.overall["paper"]["n"] == 4 and data.overall["paper"]["n_unscored"] == 1
    assert data.timing["paper"]["odometry_ms"] == pytest.approx(12.0)
    assert data.timing["paper"]["estimation_ms"] == pytest.approx(1.0)
    assert math.isnan(data.timing["paper"]["depth_ms"])
    keys = [t.key for t in report_tables(data)]
    assert keys[0] == "table1_rmse" and "table2_time" in keys and "theta_agreement" in keys
    theta = next(t for t in report_tables(data) if t.key == "theta_agreement")
    assert theta.rows[0][3] == pytest.approx(0.05)
    written = write_report(data, tmp_path / "out", parquet=False)
    assert (tmp_path / "out" / "report.html").is_file()
    assert {f.name for f in written.figures} == {
        "distance_over_time.png",
        "error_vs_distance.png",
        "theta_over_time.png",
    }


def test_a_run_with_its_own_sigma_gets_the_uncertainty_table(tmp_path: Path) -> None:
    rows = [_record(0, 10.0, 11.0), _record(1, 21.0, 20.0), _record(2, 33.0, 30.0)]
    for r, sigma in zip(rows, (2.0, 0.5, 1.0)):  # |error|/σ = 0.5, 2, 3
        r["method"], r["sigma_m"] = "ours", sigma
    write_run(tmp_path / "seqA", rows, [{"frame": 0}], extra=("gt_distance_m", "sigma_m"))
    data = report_data(tmp_path, ReportOptions())
    u = data.overall["ours"]["uncertainty"]
    assert u["n_sigma"] == 3 and u["within_1sigma"] == pytest.approx(1 / 3)
    assert u["within_2sigma"] == pytest.approx(2 / 3) and u["within_3sigma"] == 1.0
    assert u["z_rms"] == pytest.approx(math.sqrt((0.25 + 4 + 9) / 3))
    table = next(t for t in report_tables(data) if t.key == "uncertainty")
    assert table.rows == [["ours", 3, 1 / 3, 2 / 3, 1.0, u["z_rms"]]]
    longform = {(r["scope"], r["metric"]): r["value"] for r in metric_records(data)}
    assert longform[("overall", "within_2sigma")] == pytest.approx(2 / 3)


def test_run_output_without_truth_has_no_table1(tmp_path: Path) -> None:
    rows = [_record(0, 10.0, math.nan), _record(1, 12.0, math.nan)]
    for r in rows:
        r.pop("gt_distance_m")
    write_run(tmp_path / "r", rows, [{"frame": 0, "estimation_ms": 2.0}], extra=())
    data = report_data(tmp_path / "r", ReportOptions())
    assert not data.has_truth
    assert [t.key for t in report_tables(data)] == ["tracks", "table2_time"]
    written = write_report(data, tmp_path / "out", parquet=False)
    assert written.figures == []  # track 3 is seen in 2 frames: too few to plot
    written = write_report(data, tmp_path / "out", tracks=[("r", 3)], parquet=False)
    assert [f.name for f in written.figures] == ["track_r_3.png"]


def test_bad_sources_and_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(MissingInputError, match="neither a KITTI tracking folder"):
        detect_source(tmp_path)
    assert main(["report", str(tmp_path / "nothing"), "--out", str(tmp_path / "o")]) == 2
    assert "report source not found" in capsys.readouterr().err
    write_run(tmp_path / "bad", [_record(0, "ten", 11.0)], [{"frame": 0}])
    with pytest.raises(InputFileError, match=r"records\.csv, line 2, field 'distance_m'"):
        report_data(tmp_path / "bad", ReportOptions())
    (tmp_path / "bad2").mkdir()
    (tmp_path / "bad2" / "records.csv").write_text("frame,method\n0,paper\n")
    with pytest.raises(InputFileError, match="missing column"):
        report_data(tmp_path / "bad2", ReportOptions())
    assert main(["report", str(tmp_path / "bad2"), "--tracks", "0000"]) == 2
    assert "SEQUENCE:TRACK_ID" in capsys.readouterr().err


@pytest.mark.kitti
def test_out_that_is_the_source_or_one_of_its_runs_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`report run/ --out run/` replaced the run's records.csv with the report's."""
    write_run(tmp_path / "runs" / "a", [_record(0, 10.0, 11.0)], [{"frame": 0}])
    before = (tmp_path / "runs" / "a" / "records.csv").read_text()
    for source, out in (("runs/a", "runs/a"), ("runs", "runs"), ("runs", "runs/a")):
        argv = ["report", str(tmp_path / source), "--out", str(tmp_path / out), "--no-parquet"]
        assert main(argv) == 2
        assert "would be overwritten" in capsys.readouterr().err
    assert (tmp_path / "runs" / "a" / "records.csv").read_text() == before
    assert not (tmp_path / "runs" / "records.csv").exists()
    assert main(["report", str(tmp_path / "runs"), "--out", str(tmp_path / "rep")]) == 0


def test_depthmap_needs_a_depth_folder_and_unknown_tracks(tmp_path: Path) -> None:
    kitti = shared_data_path("kitti_tracking")
    opts = ReportOptions(eval=KittiEvalConfig(sequences=["0000"], methods=("depthmap",)))
    with pytest.raises(ConfigurationError, match="--depth-dir"):
        report_data(kitti, opts)
    data = report_data(
        kitti, ReportOptions(eval=KittiEvalConfig(sequences=["0000"], methods=("flat",)))
    )
    with pytest.raises(ConfigurationError, match="track 999 of sequence 0000"):
        write_report(data, tmp_path / "o", tracks=[("0000", 999)], parquet=False)


def test_runs_of_different_methods_on_one_sequence_are_grouped(tmp_path: Path) -> None:
    frames = [{"frame": 0, "estimation_ms": 1.0}]
    for method, d in (("paper", 10.0), ("flat", 12.0)):
        rec = _record(0, d, 11.0)
        rec["method"] = method
        write_run(tmp_path / f"run_{method}", [rec], frames)
        (tmp_path / f"run_{method}" / "run.json").write_text('{"sequence": "lead"}')
    data = report_data(tmp_path, ReportOptions())
    assert data.sequences == ["lead"] and data.methods == ["flat", "paper"]
    assert data.summaries["lead"]["flat"]["rmse"] == pytest.approx(1.0)
    assert data.common is None
    rec = _record(0, 9.0, 11.0)
    write_run(tmp_path / "again", [rec], frames)
    (tmp_path / "again" / "run.json").write_text('{"sequence": "lead"}')
    with pytest.raises(ConfigurationError, match="method paper appears twice for sequence lead"):
        report_data(tmp_path, ReportOptions())


@pytest.mark.kitti
def test_offline_adds_its_own_rows_to_a_kitti_report(tmp_path: Path) -> None:
    kitti = shared_data_path("kitti_tracking")
    out = tmp_path / "out"
    args = ["report", str(kitti), "--sequences", "0014", "--methods", "paper,ours"]
    assert main([*args, "--offline", "--out", str(out), "--no-parquet"]) == 0
    table1 = {r["sequence"]: r for r in _csv(out / "table1_rmse.csv")}
    assert float(table1["0014"]["ours-offline"]) < float(table1["0014"]["ours"])
    assert main(["report", str(tmp_path / "out"), "--offline", "--out", str(tmp_path / "o")]) == 2


def test_kitti_report_with_workers_is_that_of_one_worker(
    kitti_tracking_dir: Path, ray_instance: object
) -> None:
    from dataclasses import replace

    from slopedist.evaluation.report.tables import metric_records

    cfg = KittiEvalConfig(sequences=["0001", "0014"], methods=("flat", "paper", "imu", "ours"))
    one = report_data(kitti_tracking_dir, ReportOptions(eval=cfg))
    two = report_data(kitti_tracking_dir, ReportOptions(eval=replace(cfg, workers=2)))
    assert one.records.names == two.records.names and len(one.records) > 0
    for name in one.records.names:
        np.testing.assert_equal(two.records.data[name], one.records.data[name], err_msg=name)
    for name in one.theta.names:
        np.testing.assert_equal(two.theta.data[name], one.theta.data[name], err_msg=name)
    scores = [
        [r for r in metric_records(d) if r["scope"] != "timing" and r["metric"] != "ms_per_frame"]
        for d in (one, two)
    ]
    np.testing.assert_equal(scores[1], scores[0])
    assert one.protocol == two.protocol


@pytest.mark.kitti
def test_the_learned_peer_row_in_the_kitti_report(tmp_path: Path) -> None:
    """The report's peer row is the evaluation's, with its training protocol in the notes and
    no rotation; a declared truth reference reaches the notes."""
    from slopedist.estimators.base import ReferencePoint
    from slopedist.evaluation.learned_peer import PEER_METHOD

    kitti = shared_data_path("kitti_tracking")
    cfg = KittiEvalConfig(
        sequences=["0003"], methods=("flat", PEER_METHOD), gt_reference=ReferencePoint.CENTRE
    )
    data = report_data(kitti, ReportOptions(eval=cfg))
    ref = evaluate_kitti_tracking(kitti, cfg)
    assert data.overall[PEER_METHOD]["rmse"] == pytest.approx(
        ref["methods"][PEER_METHOD]["overall"]["rmse"]
    )
    notes = " ".join(data.notes)
    assert "leave-one-sequence-out" in notes and "learned-peer = none" in notes
    assert "referring to the vehicle's centre" in notes
    written = write_report(data, tmp_path / "o", parquet=False)
    assert PEER_METHOD in (tmp_path / "o" / "report.md").read_text()
    assert written.files


@pytest.mark.kitti
def test_kitti_report_has_the_oxts_theta_truth_without_an_imu_method(
    kitti_tracking_dir: Path,
) -> None:
    # no method is fed OXTS, yet the sequence has them: θ is still compared with them (the
    # caption said "no IMU truth in this source")
    cfg = KittiEvalConfig(sequences=["0001"], methods=("flat", "paper"))
    data = report_data(kitti_tracking_dir, ReportOptions(eval=cfg))
    assert data.truth_source == "oxts"
    theta = next(t for t in report_tables(data) if t.key == "theta_agreement")
    assert [(r[0], r[1]) for r in theta.rows] == [("0001", "orbslam3")]
    assert theta.rows[0][3] < 0.1  # ORB-SLAM3 agrees with OXTS to < 0.1° RMS
