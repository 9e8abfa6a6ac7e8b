"""The report's data from a ``slopedist demo`` output (``results.json``,
``<scenario>/records.csv`` and ``<scenario>/frames.csv``): Table 1 per scenario × method
against the synthetic truth, θ of the odometry against the true θ, times from
``results.json``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from slopedist.core.errors import InputFileError
from slopedist.core.textfiles import read_json
from slopedist.evaluation.report.data import ReportData, ReportOptions, SourceKind, default_title
from slopedist.evaluation.report.runs import demo_number, run_report_data

DEMO_RESULTS = "results.json"
"""File that marks a ``slopedist demo`` output folder (with ``<scenario>/records.csv``)."""


def _read_results(path: Path) -> dict[str, Any]:
    results = read_json(path, "demo results")
    if not isinstance(results, dict) or not isinstance(results.get("scenarios"), dict):
        raise InputFileError(path, "lacks 'scenarios' (not a slopedist demo output?)")
    return results


def _timing(data: ReportData, results: dict[str, Any], path: Path, m: str) -> dict[str, float]:
    """Table 2's times of ``m``: frame-weighted means over the scenarios it has records of;
    odometry only for methods fed visual-odometry rotations."""
    scenarios: dict[str, Any] = results["scenarios"]
    est = odo = frames = 0.0
    for name in data.sequences:
        if data.summaries[name][m].get("missing"):
            continue  # no records of m in this scenario
        n = demo_number(scenarios, path, name, "frames")
        frames += n
        est += n * demo_number(scenarios, path, name, "methods", m, "estimation_ms_per_frame")
        odo += n * demo_number(scenarios, path, name, "odometry_ms_per_frame")
    rotation = (results.get("methods") or {}).get(m, {}).get("rotation")
    return {
        "odometry_ms": odo / frames if frames and rotation == "odometry" else math.nan,
        "estimation_ms": est / frames if frames else math.nan,
        "depth_ms": math.nan,
        "frames": frames,
    }


def _notes(config: dict[str, Any]) -> list[str]:
    odometry = (
        "the built-in visual odometry on the rendered frames"
        if config.get("odometry", "visual") == "visual"
        else "the TRUE rotations (demo --odometry truth)"
    )
    return [
        f"Rotations from {odometry}; noisy detector boxes.",
        "Ground truth: the synthetic vehicles' centre (KITTI's convention: camera z of the 3D "
        "box's bottom centre); "
        "the same cap rule as KITTI (estimates above 80 m count as 80 m, below-horizon "
        "targets as 80 m).",
        "Methods bound to an IMU get the true rotations with simulated IMU noise; depth-map "
        "methods get the true depth with simulated network noise (no inference, so no depth "
        "time).",
        "Times per frame from results.json: odometry (for methods fed odometry rotations) and "
        "estimation; rendering and the detector are excluded. θ: the odometry's ego gradient "
        "against the true one (frames.csv of each scenario).",
    ]


def synthetic_report_data(root: str | Path, opts: ReportOptions) -> ReportData:
    """Read a ``slopedist demo`` output: the per-scenario records of the scenarios
    ``results.json`` lists (scored against the synthetic truth, ``truth_z_m``), θ from
    ``<scenario>/frames.csv`` against the true θ, and the times of ``results.json`` (odometry
    only for methods fed visual-odometry rotations).

    Raises:
        InputFileError: ``results.json`` is not JSON, lacks a figure or lists no scenario
            folder; a scenario folder without ``records.csv``.
    """
    root = Path(root)
    path = root / DEMO_RESULTS
    results = _read_results(path)
    # the scenarios of this demo: a folder left by an earlier demo into the same --out is not
    folders = [root / name for name in results["scenarios"] if (root / name).is_dir()]
    if not folders:
        raise InputFileError(path, "lists no scenario with a folder here")
    data = run_report_data(root, opts, folders)
    listed = list(results.get("methods") or {})  # the demo's own order of the methods
    data.methods.sort(key=lambda m: listed.index(m) if m in listed else len(listed))
    data.timing = {m: _timing(data, results, path, m) for m in data.methods}
    config = results.get("config") or {}
    data.kind = SourceKind.SYNTHETIC
    data.protocol = {
        "source": "synthetic",
        "demo": str(root),
        "config": config,
        "demo_protocol": results.get("protocol"),
    }
    data.notes = _notes(config)
    if opts.title is None:
        data.title = default_title(SourceKind.SYNTHETIC, data.sequences, data.methods)
    return data
