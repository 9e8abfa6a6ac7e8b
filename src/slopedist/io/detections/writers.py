"""Writing boxes in the slopedist box CSV layout (see :mod:`slopedist.io.detections.readers`)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.readers import CSV_BOX_COLUMNS
from slopedist.io.formatting import CsvStreamWriter, exact_cell


def write_box_csv(boxes: BoxTable, path: str | Path, extra: tuple[str, ...] | None = None) -> Path:
    """Write ``boxes`` as a slopedist box CSV that :func:`~slopedist.io.detections.readers.
    read_box_csv` reads back.

    Columns: ``frame,left,top,right,bottom,track_id,score,class`` then the one-dimensional extra
    columns named in ``extra`` (default: all of them, e.g. ``z`` in metres), which readers
    ignore. Rows are in frame order; the cells follow :mod:`slopedist.io.formatting` (NaN as an
    empty field, LF line ends), numbers in full where ``.6g`` would round them
    (:func:`~slopedist.io.formatting.exact_cell`): the file reads back as the same boxes.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = [k for k, v in boxes.extra.items() if np.ndim(v) == 1] if extra is None else list(extra)
    order = np.argsort(boxes.frame, kind="stable")
    with CsvStreamWriter.open(path, [*CSV_BOX_COLUMNS, *names]) as writer:
        writer.write_values(box_values(boxes.select(order), names))
    return path


def box_values(boxes: BoxTable, extra: list[str] | tuple[str, ...] = ()) -> Iterator[list[object]]:
    """The rows of ``boxes`` as box CSV values (:data:`CSV_BOX_COLUMNS`, then ``extra``), in
    table order, for :meth:`CsvStreamWriter.write_values`."""
    for i in range(len(boxes)):
        yield [
            int(boxes.frame[i]),
            *(exact_cell(v) for v in boxes.boxes[i]),
            int(boxes.track_id[i]),
            exact_cell(boxes.score[i]),
            boxes.cls[i],
            *(exact_cell(boxes.extra[k][i]) for k in extra),
        ]
