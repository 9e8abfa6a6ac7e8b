"""Process memory readings shared by the benchmark scripts (run as ``python benchmarks/x.py``)."""

from __future__ import annotations

import math
import resource
from pathlib import Path


def rss_mb() -> float:
    """Current resident set size of this process, MB (from /proc; NaN where unavailable)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return math.nan


def peak_rss_mb() -> float:
    """Peak resident set size so far, MB (``ru_maxrss`` is in kB on Linux)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
