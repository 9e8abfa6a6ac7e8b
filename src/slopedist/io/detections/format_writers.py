"""Writing boxes as MOTChallenge ``det.txt``, COCO results JSON and YOLO label folders.

The layouts are those :mod:`slopedist.io.detections.formats` reads back. Numbers are formatted by
:func:`slopedist.io.formatting.exact_cell` (in full where ``.6g`` would round them: the boxes read
back as written). A box whose class has no index in the target format (e.g. ``DontCare`` in
COCO) is left out; each writer returns how many were.

- MOT ``det.txt``: ``frame+frame_base, id, left, top, width, height, conf, -1, -1, -1``; no class;
  an unknown track id or score is written ``-1`` (MOT's placeholder).
- COCO results: ``image_id`` = frame, ``category_id`` COCO's, ``bbox`` ``[x, y, w, h]``, then
  ``score`` and ``track_id`` when known.
- YOLO: ``<frame:06d>.txt`` per frame with ``class cx cy w h`` normalised to the image size, then
  ``conf`` when every box of the table has a score, then ``track_id`` when, in addition, any box
  has one.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from slopedist.core.errors import ConfigurationError
from slopedist.io.detections.boxes import NO_TRACK, BoxTable
from slopedist.io.detections.formats import COCO_CATEGORIES, MOT_UNKNOWN_SCORE
from slopedist.io.detections.onnx_detector import COCO_VEHICLES
from slopedist.io.formatting import exact_cell, write_json

EXTRA_NAME_ALIASES = {"Van": "Car"}
"""Classes written as another one when the target format has no index of their own."""


def class_indices(table: BoxTable, class_map: Mapping[int, str]) -> tuple[np.ndarray, np.ndarray]:
    """Per box: the format's class index (−1 = none) and whether it has one."""
    by_name = {name: idx for idx, name in sorted(class_map.items(), reverse=True)}
    ids = np.array(
        [by_name.get(c, by_name.get(EXTRA_NAME_ALIASES.get(c, ""), -1)) for c in table.cls],
        dtype=np.int64,
    )
    return ids, ids >= 0


def yolo_optional_columns(table: BoxTable, kept: np.ndarray) -> tuple[bool, bool]:
    """Whether a YOLO label folder of the ``kept`` boxes of ``table`` has its optional columns:
    ``(conf, track_id)``. A column is all or nothing: ``conf`` only when every kept box has a
    score, ``track_id`` only after ``conf`` and when some kept box has a track."""
    with_score = bool(np.all(np.isfinite(table.score[kept])))
    with_track = with_score and bool(np.any(table.track_id[kept] != NO_TRACK))
    return with_score, with_track


def _line(values: list[object], sep: str) -> str:
    return sep.join(str(exact_cell(v)) for v in values) + "\n"


def write_mot(table: BoxTable, path: str | Path, frame_base: int = 1) -> int:
    """A MOTChallenge ``det.txt``; returns 0 (MOT keeps every box, without its class)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    order = np.argsort(table.frame, kind="stable")
    with path.open("w", encoding="utf-8", newline="") as fh:
        for i in order:
            left, top, right, bottom = table.boxes[i]
            score = table.score[i] if np.isfinite(table.score[i]) else MOT_UNKNOWN_SCORE
            row = [int(table.frame[i]) + frame_base, int(table.track_id[i]), left, top]
            fh.write(_line([*row, right - left, bottom - top, score, -1, -1, -1], ","))
    return 0


def write_coco(
    table: BoxTable, path: str | Path, categories: Mapping[int, str] | None = None
) -> int:
    """A COCO results JSON list (``-`` = standard output); returns the boxes left out."""
    ids, ok = class_indices(table, COCO_CATEGORIES if categories is None else categories)
    items = []
    for i in np.flatnonzero(ok)[np.argsort(table.frame[ok], kind="stable")]:
        left, top, right, bottom = table.boxes[i]
        item: dict[str, object] = {
            "image_id": int(table.frame[i]),
            "category_id": int(ids[i]),
            "bbox": [left, top, right - left, bottom - top],
        }
        if np.isfinite(table.score[i]):
            item["score"] = table.score[i]
        if table.track_id[i] != NO_TRACK:
            item["track_id"] = int(table.track_id[i])
        items.append(item)
    write_json(path, items)
    return int(np.count_nonzero(~ok))


def write_yolo_folder(
    table: BoxTable,
    folder: str | Path,
    image_size: tuple[int, int],
    class_map: Mapping[int, str] | None = None,
) -> int:
    """One YOLO ``.txt`` per frame in ``folder``; returns the boxes left out.

    Raises:
        ConfigurationError: ``folder`` already holds ``.txt`` files (the label files of another
            box set would be mixed with these: frames this table has no boxes for keep theirs),
            or a box's centre lies outside the ``image_size`` image (YOLO's coordinates are
            fractions of the image: the size is not the boxes' images).
    """
    w, h = image_size
    if w <= 0 or h <= 0:
        raise ConfigurationError(f"image size must be positive, got {w}×{h}")
    centres = (table.boxes[:, :2] + table.boxes[:, 2:]) / 2
    outside = np.flatnonzero(~np.all((centres >= 0) & (centres <= (w, h)), axis=1))
    if outside.size:
        i = int(outside[0])
        raise ConfigurationError(
            f"{outside.size} boxes have their centre outside the {w}×{h} px image, e.g. frame "
            f"{int(table.frame[i])}: ({', '.join(f'{v:g}' for v in table.boxes[i])}); is "
            f"{w}x{h} the size of the boxes' images?"
        )
    folder = Path(folder)
    old = sorted(p.name for p in folder.glob("*.txt")) if folder.is_dir() else []
    if old:
        raise ConfigurationError(
            f"{folder} already holds {len(old)} .txt files ({old[0]}, ...): they would be mixed "
            "with the new label files; choose a new or empty folder"
        )
    folder.mkdir(parents=True, exist_ok=True)
    ids, ok = class_indices(table, COCO_VEHICLES if class_map is None else class_map)
    with_score, with_track = yolo_optional_columns(table, ok)
    kept = table.select(ok)
    for (frame, boxes), cls in zip(kept.by_frame(), _ids_by_frame(kept, ids[ok])):
        lines = []
        for j in range(len(boxes)):
            left, top, right, bottom = boxes.boxes[j]
            row: list[object] = [int(cls[j]), (left + right) / 2 / w, (top + bottom) / 2 / h]
            row += [(right - left) / w, (bottom - top) / h]
            row += [boxes.score[j]] if with_score else []
            row += [int(boxes.track_id[j])] if with_track else []
            lines.append(_line(row, " "))
        (folder / f"{frame:06d}.txt").write_text("".join(lines), encoding="utf-8")
    return int(np.count_nonzero(~ok))


def _ids_by_frame(table: BoxTable, ids: np.ndarray) -> list[np.ndarray]:
    """``ids`` split like :meth:`BoxTable.by_frame` (frame order, stable)."""
    order = np.argsort(table.frame, kind="stable")
    splits = np.flatnonzero(np.diff(table.frame[order])) + 1
    return np.split(ids[order], splits) if len(order) else []
