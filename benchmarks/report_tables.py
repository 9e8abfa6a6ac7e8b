"""Print the paper's Table 1 (RMSE per sequence × method) and Table 2 (time per frame per method)
on the shared KITTI tracking data, by running ``slopedist report`` into a temporary folder.

Usage (from the repository root)::

    python benchmarks/report_tables.py [DATA_DIR] [--depth-dir DIR] [other report options]

DATA_DIR defaults to ../shared/data/kitti_tracking. Times are wall-clock on this machine and
vary with its load; the detector is not counted, and KITTI's rotations are precomputed pose
files, so the odometry column stays empty.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from slopedist.cli import main

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kitti_tracking"


def run(argv: list[str]) -> int:
    """Run the report on ``argv`` (data folder first, then options); returns the exit code."""
    data = argv[0] if argv and not argv[0].startswith("-") else str(DEFAULT_DATA)
    rest = argv[1:] if argv and not argv[0].startswith("-") else argv
    if not Path(data).is_dir():
        print(f"no KITTI tracking data at {data}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as out:
        return main(["report", data, "--out", out, "--no-parquet", *rest])


if __name__ == "__main__":
    sys.exit(run(sys.argv[1:]))
