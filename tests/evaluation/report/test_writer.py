"""The report's files: every CSV with LF line ends, report.json strict JSON, tables as text,
Markdown and HTML from one table."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from slopedist.evaluation.report import ReportOptions, report_data, write_report
from tests.evaluation.report.test_report import _record, write_run


def test_every_csv_has_lf_line_ends_and_the_json_is_strict(tmp_path: Path) -> None:
    rows = [_record(0, 10.0, 11.0), _record(1, "", 30.0, "no_rotation")]
    frames = [
        {
            "frame": k,
            "theta_deg": 0.1,
            "theta_true_deg": 0.2,
            "odometry_ms": 5.0,
            "estimation_ms": 1.0,
        }
        for k in range(2)
    ]
    write_run(tmp_path / "run", rows, frames)
    data = report_data(tmp_path / "run", ReportOptions())
    written = write_report(data, tmp_path / "out", parquet=False)
    csvs = sorted(p.name for p in written.files if p.suffix == ".csv")
    assert {"table1_rmse.csv", "table2_time.csv", "metrics.csv", "records.csv", "theta.csv"} <= set(
        csvs
    )
    for name in csvs:
        data_bytes = (tmp_path / "out" / name).read_bytes()
        assert b"\r" not in data_bytes and data_bytes.endswith(b"\n"), name
    text = (tmp_path / "out" / "report.json").read_text()
    report = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-strict token {c}"))
    # the depth time was never measured: NaN inside, null in the file
    assert math.isnan(data.timing["paper"]["depth_ms"])
    assert report["timing"]["paper"]["depth_ms"] is None
    assert report["kind"] == "run" and report["overall"]["paper"]["n"] == 1


def test_markdown_report_of_a_run_named_with_a_pipe_and_a_tag(tmp_path: Path) -> None:
    """A run folder named ``s<i>|2``: its Table 1 row keeps its columns (the ``|`` split it,
    moving the RMSE under the next header) and its name opens no HTML tag in report.md."""
    rows = [_record(0, 10.0, 11.0), _record(1, 21.0, 20.0)]
    frames = [{"frame": k, "estimation_ms": 1.0} for k in range(2)]
    write_run(tmp_path / "s<i>|2", rows, frames)
    data = report_data(tmp_path / "s<i>|2", ReportOptions())
    write_report(data, tmp_path / "out", parquet=False)
    md = (tmp_path / "out" / "report.md").read_text(encoding="utf-8")
    assert "sequence: s&lt;i>|2." in md  # (a code span shows ``<i>`` as it is)
    table = md[md.index("| sequence |") :].split("\n\n")[0].splitlines()
    widths = {len(re.split(r"(?<!\\)\|", line)) for line in table}
    assert len(widths) == 1, table
    assert any(line.startswith(r"| s&lt;i>\|2 |") for line in table), table
