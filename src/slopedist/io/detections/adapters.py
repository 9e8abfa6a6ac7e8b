"""Detections already in memory, from other libraries, as a :class:`BoxTable`.

Duck-typed: nothing is imported from those libraries, so they stay optional. Tensors (torch,
with ``.cpu()``) and numpy arrays are both accepted.

- ultralytics ``Results`` (``model(frame)[0]`` or ``model.track(...)``): ``results.boxes.xyxy``
  (pixels, left, top, right, bottom), ``.conf``, ``.cls`` (model class index) and ``.id`` (track
  ids, None without tracking);
- supervision ``Detections``: ``.xyxy``, ``.confidence``, ``.class_id`` and ``.tracker_id``
  (each but ``xyxy`` may be None).

- plain boxes (:func:`as_box_table`): an ``(N, 4)`` array of left, top, right, bottom pixels,
  ``(N, 5)`` with a score, ``(N, 6)`` with a class index, or a list of such tuples (the sixth
  value may also be a class name).

Class indices go through a class map (default :data:`~slopedist.io.detections.onnx_detector.
COCO_VEHICLES`); boxes of classes not in the map are dropped. Without class indices every box is
kept, as class ``Car``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import DataMismatchError
from slopedist.io.detections.boxes import NO_TRACK, BoxTable, concat_boxes
from slopedist.io.detections.onnx_detector import COCO_VEHICLES


def _array(value: Any, dtype: type) -> NDArray | None:
    """``value`` (None, a torch tensor or array-like) as a flat-or-2D numpy array."""
    if value is None:
        return None
    if hasattr(value, "cpu"):
        value = value.cpu()
    if hasattr(value, "numpy"):
        value = value.numpy()
    return np.asarray(value, dtype=dtype)


def _table(
    frame: int,
    xyxy: Any,
    score: Any,
    class_id: Any,
    track_id: Any,
    class_map: Mapping[int, str] | None,
    source: str,
) -> BoxTable:
    boxes = _array(xyxy, float)
    if boxes is None or boxes.size % 4 or (boxes.ndim != 2 and boxes.size):
        raise DataMismatchError(f"{source}: boxes must be an (N, 4) array, got {np.shape(xyxy)}")
    boxes = boxes.reshape(-1, 4)
    n = boxes.shape[0]
    columns = {"score": _array(score, float), "class": _array(class_id, float)}
    columns["track"] = _array(track_id, float)
    for name, col in columns.items():
        if col is not None and col.reshape(-1).shape[0] != n:
            raise DataMismatchError(f"{source}: {n} boxes but {col.size} values of '{name}'")
    cls_idx = columns["class"]
    mapping = COCO_VEHICLES if class_map is None else class_map
    if cls_idx is None:
        keep = np.ones(n, bool)
        names = np.full(n, "Car", dtype=object)
    else:
        ids = cls_idx.reshape(-1).astype(np.int64)
        keep = np.isin(ids, np.array(list(mapping), dtype=np.int64))
        names = np.array([mapping.get(int(i), "") for i in ids], dtype=object)
    tracks = columns["track"]
    return BoxTable.build(
        np.full(n, frame, np.int64),
        boxes,
        None if tracks is None else np.nan_to_num(tracks.reshape(-1), nan=NO_TRACK),
        columns["score"],
        names,
    ).select(keep)


def from_ultralytics(
    results: Any, frame: int = 0, class_map: Mapping[int, str] | None = None
) -> BoxTable:
    """One ultralytics ``Results`` (one frame), or a list of them (frames ``frame, frame+1, …``)."""
    if isinstance(results, (list, tuple)):
        return concat_boxes(
            [from_ultralytics(r, frame + i, class_map) for i, r in enumerate(results)]
        )
    boxes = getattr(results, "boxes", None)
    if boxes is None or not hasattr(boxes, "xyxy"):
        raise DataMismatchError("not an ultralytics Results: it has no 'boxes.xyxy'")
    return _table(
        frame,
        boxes.xyxy,
        getattr(boxes, "conf", None),
        getattr(boxes, "cls", None),
        getattr(boxes, "id", None),
        class_map,
        "ultralytics Results",
    )


def from_supervision(
    detections: Any, frame: int = 0, class_map: Mapping[int, str] | None = None
) -> BoxTable:
    """One supervision ``Detections`` (one frame)."""
    if not hasattr(detections, "xyxy"):
        raise DataMismatchError("not a supervision Detections: it has no 'xyxy'")
    return _table(
        frame,
        detections.xyxy,
        getattr(detections, "confidence", None),
        getattr(detections, "class_id", None),
        getattr(detections, "tracker_id", None),
        class_map,
        "supervision Detections",
    )


def from_frames(
    per_frame: Iterable[tuple[int, Any]], class_map: Mapping[int, str] | None = None
) -> BoxTable:
    """``(frame index, Results or Detections)`` pairs, e.g. from a video loop, as one table."""
    tables = []
    for index, det in per_frame:
        if hasattr(det, "boxes"):
            tables.append(from_ultralytics(det, index, class_map))
        else:
            tables.append(from_supervision(det, index, class_map))
    return concat_boxes(tables)


def as_box_table(
    boxes: Any, frame: int = 0, class_map: Mapping[int, str] | None = None
) -> BoxTable:
    """The boxes of one frame, in any form a detector gives them, as a :class:`BoxTable` of
    frame ``frame``: a :class:`BoxTable` (of one frame), an ultralytics ``Results`` (or a
    list holding one), a supervision ``Detections``, an ``(N, 4)``, ``(N, 5)`` or ``(N, 6)``
    array (left, top, right, bottom pixels; score; class index) or a list of such tuples,
    whose sixth value may be a class name instead (see the module docstring).

    Example:
        >>> table = as_box_table([(100, 150, 220, 240, 0.9, 2)], frame=3)
        >>> table.frame.tolist(), table.cls.tolist(), table.boxes.tolist()
        ([3], ['Car'], [[100.0, 150.0, 220.0, 240.0]])

    Raises:
        DataMismatchError: another shape or object, or a table of several frames.
    """
    if isinstance(boxes, BoxTable):
        return _one_frame(boxes, frame)
    if isinstance(boxes, (list, tuple)) and len(boxes) == 1 and hasattr(boxes[0], "boxes"):
        boxes = boxes[0]  # model(frame) gives one Results per image
    if hasattr(boxes, "boxes"):
        return from_ultralytics(boxes, frame, class_map)
    if hasattr(boxes, "xyxy"):
        return from_supervision(boxes, frame, class_map)
    if isinstance(boxes, (list, tuple)) and any(_named(row) for row in boxes):
        return _named_rows(boxes, frame)
    rows = _array(boxes, float)
    if rows is None or rows.ndim > 2 or (rows.ndim == 1 and rows.size):
        raise DataMismatchError(f"boxes must be (N, 4), (N, 5) or (N, 6), got {np.shape(boxes)}")
    rows = rows.reshape(-1, rows.shape[-1] if rows.ndim == 2 else 4)
    if rows.shape[1] not in (4, 5, 6):
        raise DataMismatchError(
            f"boxes must be (N, 4), (N, 5) or (N, 6) (left, top, right, bottom[, score[, "
            f"class]]), got {rows.shape[1]} values per box"
        )
    score = rows[:, 4] if rows.shape[1] > 4 else None
    class_id = rows[:, 5] if rows.shape[1] > 5 else None
    return _table(frame, rows[:, :4], score, class_id, None, class_map, "boxes")


def _one_frame(table: BoxTable, frame: int) -> BoxTable:
    """``table`` as the boxes of frame ``frame`` (it must hold one frame's boxes)."""
    if len(np.unique(table.frame)) > 1:
        raise DataMismatchError(
            f"a box table of one frame was expected, got frames {sorted(set(table.frame.tolist()))}"
        )
    return BoxTable(
        np.full(len(table), frame, np.int64),
        table.boxes,
        table.track_id,
        table.score,
        table.cls,
        table.extra,
    )


def _named(row: object) -> bool:
    """Whether a box tuple names its class (a text sixth value)."""
    return isinstance(row, Sequence) and len(row) == 6 and isinstance(row[5], str)


def _named_rows(rows: Sequence[Any], frame: int) -> BoxTable:
    """Box tuples ``(left, top, right, bottom, score, class name)``."""
    if not all(_named(row) for row in rows):
        raise DataMismatchError(
            "box tuples that name their class must all be (left, top, right, bottom, score, name)"
        )
    n = len(rows)
    return BoxTable.build(
        np.full(n, frame, np.int64),
        [row[:4] for row in rows],
        score=[row[4] for row in rows],
        classes=np.array([row[5] for row in rows], dtype=object),
    )
