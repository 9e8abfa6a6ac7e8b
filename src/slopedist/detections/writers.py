"""Writing boxes in the slopedist box CSV layout (see :mod:`slopedist.detections.readers`)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from slopedist.detections.boxes import BoxTable
from slopedist.detections.readers import CSV_BOX_COLUMNS


def write_box_csv(boxes: BoxTable, path: str | Path, extra: tuple[str, ...] | None = None) -> Path:
    """Write ``boxes`` as a slopedist box CSV that :func:`~slopedist.detections.readers.
    read_box_csv` reads back.

    Columns: ``frame,left,top,right,bottom,track_id,score,class`` then the one-dimensional extra
    columns named in ``extra`` (default: all of them, e.g. ``z`` in metres), which readers
    ignore. Rows are in frame order; NaN is written as an empty field.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = [k for k, v in boxes.extra.items() if np.ndim(v) == 1] if extra is None else list(extra)
    order = np.argsort(boxes.frame, kind="stable")
    with path.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow([*CSV_BOX_COLUMNS, *names])
        for i in order:
            row: list[object] = [
                int(boxes.frame[i]),
                *(_num(v) for v in boxes.boxes[i]),
                int(boxes.track_id[i]),
                _num(boxes.score[i]),
                boxes.cls[i],
            ]
            row += [_num(boxes.extra[k][i]) for k in names]
            writer.writerow(row)
    return path


def _num(value: object) -> object:
    if isinstance(value, (int, np.integer)):
        return int(value)
    x = float(value)  # type: ignore[arg-type]
    return "" if not math.isfinite(x) else f"{x:.6g}"
