"""Which source ``slopedist report`` was pointed at, and its :class:`ReportData`."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from slopedist.core.errors import MissingInputError
from slopedist.evaluation.report.data import ReportData, ReportOptions, SourceKind
from slopedist.evaluation.report.fleet import fleet_report_data, is_batch_output
from slopedist.evaluation.report.kitti import kitti_report_data
from slopedist.evaluation.report.runs import run_folders, run_report_data
from slopedist.evaluation.report.synthetic import DEMO_RESULTS, synthetic_report_data


def detect_source(path: str | Path) -> SourceKind:
    """Tell a KITTI tracking folder from a ``slopedist demo`` output, a ``slopedist batch``
    output (``status.csv``) and a run output (or a folder of run outputs, or of
    ``slopedist simulate`` outputs with runs inside).

    Raises:
        MissingInputError: the folder does not exist or is neither.
    """
    path = Path(path)
    if not path.is_dir():
        raise MissingInputError(f"report source not found (expected a folder): {path}")
    if (path / "label_02").is_dir() and (path / "calib").is_dir():
        return SourceKind.KITTI_TRACKING
    if (path / DEMO_RESULTS).is_file() and any(path.glob("*/records.csv")):
        return SourceKind.SYNTHETIC
    if is_batch_output(path):
        return SourceKind.FLEET
    if run_folders(path):
        return SourceKind.RUN
    sims = [
        p.parent
        for p in (path / "truth.csv", *path.glob("*/truth.csv"))
        if p.is_file() and (p.parent / "info.json").is_file()
    ]
    if sims:
        raise MissingInputError(
            f"{sims[0]} is a `slopedist simulate` output, which holds the truth but no estimates: "
            f"run the methods on its frames first, e.g. slopedist run {sims[0]}/image_02 --calib "
            f"{sims[0]}/calib.txt --boxes {sims[0]}/boxes.csv --timestamps {sims[0]}/times.txt "
            f"--method paper --out {sims[0]}/run_paper, then report on {path}"
        )
    raise MissingInputError(
        f"{path} is neither a KITTI tracking folder (label_02/ and calib/), a `slopedist demo` "
        f"output ({DEMO_RESULTS} and <scenario>/records.csv) nor a `slopedist run` output "
        f"(records.csv, or sub-folders with records.csv)"
    )


def report_data(
    source: str | Path, opts: ReportOptions, on_sequence: Callable[[str], None] | None = None
) -> ReportData:
    """The report's data from any supported source (see :func:`detect_source`)."""
    kind = detect_source(source)
    if kind is SourceKind.KITTI_TRACKING:
        return kitti_report_data(source, opts, on_sequence)
    if kind is SourceKind.SYNTHETIC:
        return synthetic_report_data(source, opts)
    if kind is SourceKind.FLEET:
        return fleet_report_data(source, opts)
    return run_report_data(source, opts)
