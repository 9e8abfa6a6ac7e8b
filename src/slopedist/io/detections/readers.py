"""Readers for box files: KITTI tracking labels, PointRCNN detections, and the slopedist CSV.

Every reader returns a :class:`~slopedist.io.detections.boxes.BoxTable` and fails with an
:class:`~slopedist.core.errors.InputFileError` naming the file, line and field of a malformed value.

The slopedist box CSV (for user boxes) has a header row and these columns::

    frame,left,top,right,bottom[,track_id][,score][,class][,gt_distance_m]
    [,height_m][,width_m][,length_m][,size_sigma_pct]

``frame`` is the 0-based frame index (int); ``left, top, right, bottom`` are pixels of the image
the calibration belongs to (origin top-left); ``track_id`` is an int (-1 or empty = unknown);
``score`` a float (empty = unknown); ``class`` a name such as ``Car`` (empty = ``Car``).
``gt_distance_m`` (optional) is the target's ground-truth distance in metres, longitudinal
(camera z, as KITTI's label z), > 0; empty = unknown. When present it is kept as the box column
``gt_distance_m`` (NaN where unknown): ``slopedist run`` copies it into ``records.csv`` so that
``slopedist report`` can score the run, and the depthmap method's ``truth`` scaling reads it.
``height_m, width_m, length_m`` (optional, each on its own) are the vehicle's dimensions as a
detector knows them, metres in 0.3–30 (empty or ``nan`` = unknown: the class prior's);
``size_sigma_pct`` their 1σ in percent of each dimension, in (0, 100] (empty = 10 %)
(:mod:`slopedist.io.detections.sizes`). Other columns are ignored. A file whose boxes all lie
within 0..1 (normalised coordinates), or whose boxes are mostly inverted (``x, y, width,
height`` columns read as ``right, bottom``), is refused as a whole (:func:`check_box_columns`):
its few boxes that look valid would be wrong.
"""

from __future__ import annotations

import math
import sys
from array import array
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import InputFileError
from slopedist.core.limits import MAX_ABS_PIXEL, MAX_INDEX
from slopedist.core.textfiles import CsvRows, numbered_lines
from slopedist.io.detections.boxes import NO_TRACK, BoxTable
from slopedist.io.detections.dropped import DroppedBoxes
from slopedist.io.detections.sizes import (
    SIZE_COLUMNS,
    SIZE_SIGMA_COLUMN,
    size_sigma_value,
    size_value,
)

CSV_BOX_COLUMNS = ("frame", "left", "top", "right", "bottom", "track_id", "score", "class")
CSV_REQUIRED = ("frame", "left", "top", "right", "bottom")
BOX_SIDES = ("left", "top", "right", "bottom")
CSV_TRUTH_COLUMN = "gt_distance_m"
"""Optional column of the slopedist box CSV: ground-truth distance (camera z), metres."""

KITTI_LABEL_FIELDS = (
    "frame",
    "track_id",
    "type",
    "truncated",
    "occluded",
    "alpha",
    "left",
    "top",
    "right",
    "bottom",
    "height",
    "width",
    "length",
    "x",
    "y",
    "z",
    "rotation_y",
)
POINTRCNN_FIELDS = (
    "frame",
    "type",
    "x1",
    "y1",
    "x2",
    "y2",
    "score",
    "h",
    "w",
    "l",
    "x",
    "y",
    "z",
    "rotation_y",
    "alpha",
)


def score_value(tok: str) -> float:
    """A detection score as written: any finite number (detectors' scores are probabilities or
    logits), NaN for unknown; ``±inf`` is refused (ValueError): it would pass every
    ``--score`` threshold."""
    value = float(tok)
    if math.isinf(value):
        raise ValueError(f"{tok} is not a finite score")
    return value


def _parse(path: str | Path, lineno: int, name: str, tok: str, kind: Callable[[str], Any]) -> Any:
    try:
        value = kind(tok)
    except ValueError:
        kind_name = {int: "an integer", _int: "an integer", score_value: "a finite number"}.get(
            kind, "a number"
        )
        raise InputFileError(path, f"'{tok}' is not {kind_name}", line=lineno, field=name) from None
    return value


def _int(tok: str) -> int:
    """Parse an integer, also written as a float with no fraction (``3.0``)."""
    try:
        return int(tok)
    except ValueError:
        value = float(tok)
        if not (value.is_integer() and abs(value) <= MAX_INDEX):
            raise
        return int(value)


def _index(path: str | Path, lineno: int, name: str, tok: str, lowest: int = 0) -> int:
    """A frame index (``lowest`` = 0) or track id (``lowest`` = -1, unknown) in
    ``lowest..MAX_INDEX``."""
    value = int(_parse(path, lineno, name, tok, _int))
    if not lowest <= value <= MAX_INDEX:
        raise InputFileError(
            path, f"{value} is outside {lowest}..{MAX_INDEX}", line=lineno, field=name
        )
    return value


def check_pixel_range(
    path: str | Path, values: Sequence[float], *, line: int | None, field: str, what: str
) -> None:
    """Fail for a finite value beyond :data:`~slopedist.core.limits.MAX_ABS_PIXEL` (NaN/inf pass:
    they are flagged per box later, see ``box_problems``); ``what`` names the values in the
    message (e.g. the box as written)."""
    bad = [v for v in values if np.isfinite(v) and abs(v) > MAX_ABS_PIXEL]
    if bad:
        raise InputFileError(
            path,
            f"{what} reaches beyond ±{MAX_ABS_PIXEL:g} px: not a pixel coordinate",
            line=line,
            field=field,
        )


def _box(path: str | Path, lineno: int, names: Sequence[str], toks: Sequence[str]) -> list[float]:
    """Four box coordinates in pixels, checked by :func:`check_pixel_range` one by one (the
    error names the coordinate's field)."""
    box = [float(_parse(path, lineno, k, t, float)) for k, t in zip(names, toks)]
    for k, v in zip(names, box):
        check_pixel_range(path, [v], line=lineno, field=k, what=f"{v:g} px")
    return box


def read_kitti_labels(path: str | Path) -> BoxTable:
    """KITTI tracking label file (17 fields per line; an 18th ``score`` is allowed).

    Extra columns: ``z`` (longitudinal distance of the box's bottom centre, m, camera 2),
    ``x``, ``y``, ``truncated`` (int), ``occluded`` (int), ``dims_hwl`` ((N, 3), m),
    ``rotation_y`` (rad).
    """
    frames, tids, types, boxes, trunc, occl, dims, xyz, ry, scores = ([] for _ in range(10))
    for lineno, line in numbered_lines(path, "KITTI label file"):
        tok = line.split()
        if len(tok) not in (17, 18):
            raise InputFileError(path, f"expected 17 fields, found {len(tok)}", line=lineno)
        f = dict(zip(KITTI_LABEL_FIELDS, tok))
        frames.append(_index(path, lineno, "frame", f["frame"]))
        tids.append(_index(path, lineno, "track_id", f["track_id"], NO_TRACK))
        types.append(f["type"])
        trunc.append(_parse(path, lineno, "truncated", f["truncated"], float))
        occl.append(_parse(path, lineno, "occluded", f["occluded"], _int))
        _parse(path, lineno, "alpha", f["alpha"], float)
        boxes.append(_box(path, lineno, BOX_SIDES, [f[k] for k in BOX_SIDES]))
        dims.append([_parse(path, lineno, k, f[k], float) for k in ("height", "width", "length")])
        xyz.append([_parse(path, lineno, k, f[k], float) for k in ("x", "y", "z")])
        ry.append(_parse(path, lineno, "rotation_y", f["rotation_y"], float))
        scores.append(
            _parse(path, lineno, "score", tok[17], score_value) if len(tok) == 18 else np.nan
        )
    xyz_a = np.asarray(xyz, dtype=float).reshape(-1, 3)
    return BoxTable.build(
        frames,
        np.asarray(boxes, dtype=float).reshape(-1, 4),
        tids,
        scores,
        types,
        truncated=np.asarray(trunc, dtype=float),
        occluded=np.asarray(occl, dtype=np.int64),
        dims_hwl=np.asarray(dims, dtype=float).reshape(-1, 3),
        x=xyz_a[:, 0],
        y=xyz_a[:, 1],
        z=xyz_a[:, 2],
        rotation_y=np.asarray(ry, dtype=float),
    )


def read_pointrcnn(path: str | Path, min_score: float | None = None) -> BoxTable:
    """PointRCNN detection file: ``frame,type(2=car),x1,y1,x2,y2,score,h,w,l,x,y,z,ry,alpha``.

    Rows with ``score < min_score`` are dropped when ``min_score`` is given. Extra columns: ``z``
    (the detector's 3D distance, m; not ground truth) and the detector's vehicle size ``h, w, l``
    as :data:`~slopedist.io.detections.sizes.SIZE_COLUMNS` (metres; its σ unknown, so the
    default's). PointRCNN measures them in a LiDAR point cloud: closer to the truth than a
    camera detector's.
    """
    frames, boxes, scores, dims, zs = [], [], [], [], []
    for lineno, line in numbered_lines(path, "PointRCNN detection file"):
        f = _comma_fields(path, lineno, line, POINTRCNN_FIELDS)
        frame = _index(path, lineno, "frame", f["frame"])
        score = _parse(path, lineno, "score", f["score"], score_value)
        box = _box(path, lineno, ("x1", "y1", "x2", "y2"), [f[k] for k in ("x1", "y1", "x2", "y2")])
        dim = [size_value(path, lineno, k, f[k]) for k in ("h", "w", "l")]
        z = _parse(path, lineno, "z", f["z"], float)
        if min_score is not None and score < min_score:
            continue
        frames.append(frame)
        boxes.append(box)
        scores.append(score)
        dims.append(dim)
        zs.append(z)
    dims_a = np.asarray(dims, dtype=float).reshape(-1, 3)
    sizes = {name: dims_a[:, k] for k, name in enumerate(SIZE_COLUMNS)}
    return _car_table(frames, boxes, scores, z=np.asarray(zs, dtype=float), **sizes)


RRC_FIELDS = ("frame", "x1", "y1", "x2", "y2", "score")
"""Fields of an RRC detection file line (comma-separated, no header)."""


def read_rrc(path: str | Path, min_score: float | None = None) -> BoxTable:
    """RRC car detections (Ren et al., CVPR 2017, as the DeepFusionMOT repository shares them):
    ``frame,x1,y1,x2,y2,score`` per line, box in pixels; class ``Car`` for every box.

    Rows with ``score < min_score`` are dropped when ``min_score`` is given.
    """
    frames, boxes, scores = [], [], []
    for lineno, line in numbered_lines(path, "RRC detection file"):
        f = _comma_fields(path, lineno, line, RRC_FIELDS)
        frame = _index(path, lineno, "frame", f["frame"])
        box = _box(path, lineno, RRC_FIELDS[1:5], [f[k] for k in RRC_FIELDS[1:5]])
        score = _parse(path, lineno, "score", f["score"], score_value)
        if min_score is not None and score < min_score:
            continue
        frames.append(frame)
        boxes.append(box)
        scores.append(score)
    return _car_table(frames, boxes, scores)


def _comma_fields(
    path: str | Path, lineno: int, line: str, fields: Sequence[str]
) -> dict[str, str]:
    """The comma-separated ``fields`` of a detection file's line, by name."""
    tok = [t.strip() for t in line.split(",")]
    if len(tok) != len(fields):
        raise InputFileError(
            path,
            f"expected {len(fields)} comma-separated fields, found {len(tok)}",
            line=lineno,
        )
    return dict(zip(fields, tok))


def _car_table(
    frames: list[int], boxes: list[list[float]], scores: list[float], **extra: NDArray
) -> BoxTable:
    """The boxes of a one-class car detector (class ``Car``, no track ids)."""
    return BoxTable.build(
        frames,
        np.asarray(boxes, dtype=float).reshape(-1, 4),
        None,
        scores,
        np.full(len(frames), "Car", dtype=object),
        **extra,
    )


def read_box_csv(path: str | Path) -> BoxTable:
    """The slopedist box CSV (see the module docstring for its columns).

    The columns are gathered in compact typed buffers (8 bytes per number, one shared string
    per class name), not as Python objects per field, so a box file of a long drive (100,000
    boxes) costs a few MB while it is read rather than tens.
    """
    rows = CsvRows(path, "box CSV")
    path = rows.path
    missing = [c for c in CSV_REQUIRED if c not in rows.header]
    if missing:
        raise InputFileError(
            path,
            f"header lacks column(s) {', '.join(missing)}; expected {','.join(CSV_BOX_COLUMNS)}"
            + _case_hint(rows.header),
            line=1,
        )
    has_truth = CSV_TRUTH_COLUMN in rows.header
    size_names = [c for c in (*SIZE_COLUMNS, SIZE_SIGMA_COLUMN) if c in rows.header]
    sizes = {c: array("d") for c in size_names}
    frames, tids, lines = array("q"), array("q"), array("q")
    boxes, scores, truth = array("d"), array("d"), array("d")
    classes: list[str] = []
    for lineno, row in rows:
        lines.append(lineno)
        frames.append(_index(path, lineno, "frame", (row["frame"] or "").strip()))
        boxes.extend(_box(path, lineno, BOX_SIDES, [(row[k] or "").strip() for k in BOX_SIDES]))
        tid = (row.get("track_id") or "").strip()
        tids.append(_index(path, lineno, "track_id", tid, NO_TRACK) if tid else NO_TRACK)
        sc = (row.get("score") or "").strip()
        scores.append(_parse(path, lineno, "score", sc, score_value) if sc else np.nan)
        classes.append(sys.intern((row.get("class") or "").strip() or "Car"))
        if has_truth:
            truth.append(_truth_distance(path, lineno, row.get(CSV_TRUTH_COLUMN)))
        for c in size_names:
            read = size_sigma_value if c == SIZE_SIGMA_COLUMN else size_value
            sizes[c].append(read(path, lineno, c, row.get(c) or ""))
    extra = {CSV_TRUTH_COLUMN: np.array(truth, dtype=float)} if has_truth else {}
    extra.update({c: np.array(v, dtype=float) for c, v in sizes.items()})
    box_array = np.array(boxes, dtype=float).reshape(-1, 4)
    check_box_columns(path, box_array, np.array(lines, dtype=np.int64))
    return BoxTable.build(
        np.array(frames, dtype=np.int64),
        box_array,
        np.array(tids, dtype=np.int64),
        np.array(scores, dtype=float),
        np.asarray(classes, dtype=object),
        **extra,
    )


def _case_hint(header: list[str]) -> str:
    """A hint naming the header's columns that differ from the box CSV's only in case."""
    known = {c.lower(): c for c in CSV_BOX_COLUMNS}
    near = [
        f"'{h}' is '{known[h.lower()]}'"
        for h in header
        if h.lower() in known and h not in known.values()
    ]
    return f" (column names are lower case: {', '.join(near)})" if near else ""


def check_box_columns(
    path: str | Path, boxes: NDArray[np.float64], lines: NDArray[np.int64]
) -> None:
    """Fail when a box file's ``(N, 4)`` boxes (left, top, right, bottom; read from ``lines``)
    cannot be pixel corners: every box within 0..1 (normalised coordinates, which would be
    sub-pixel boxes at the top-left corner), or more than half of them, and at least two,
    inverted (``x, y, width, height`` columns: the boxes that are not inverted would be
    read with a wrong right and bottom, at a wrong distance)."""
    finite = np.isfinite(boxes).all(axis=1)
    b, at = boxes[finite], lines[finite]
    if len(b) and bool(((b >= 0.0) & (b <= 1.0)).all()):
        raise InputFileError(
            path,
            "every box lies within 0..1: normalised coordinates? Boxes are pixels of the "
            "image (origin top-left): multiply x by the image width and y by its height",
            line=int(at[0]),
            field="left",
        )
    inverted = (b[:, 2] < b[:, 0]) | (b[:, 3] < b[:, 1])
    if inverted.sum() >= 2 and inverted.sum() > len(b) / 2:
        k = int(np.flatnonzero(inverted)[0])
        side = "right" if b[k, 2] < b[k, 0] else "bottom"
        raise InputFileError(
            path,
            f"{int(inverted.sum())} of {len(b)} boxes have right < left or bottom < top: are "
            "the columns x, y, width, height? They must be left, top, right, bottom (pixels)",
            line=int(at[k]),
            field=side,
        )


def _truth_distance(path: Path, lineno: int, value: str | None) -> float:
    """A ``gt_distance_m`` field: metres > 0, or NaN when empty."""
    tok = (value or "").strip()
    if not tok:
        return float("nan")
    d = float(_parse(path, lineno, CSV_TRUTH_COLUMN, tok, float))
    if not (np.isfinite(d) and d > 0):
        raise InputFileError(
            path,
            f"ground-truth distance must be a finite number of metres "
            f"> 0 (or empty = unknown), got '{tok}'",
            line=lineno,
            field=CSV_TRUTH_COLUMN,
        )
    return d


def read_box_file(
    path: str | Path, min_score: float | None = None, dropped: DroppedBoxes | None = None
) -> BoxTable:
    """Read boxes from a file of any supported layout, chosen by its content.

    A first line with a ``frame`` header is the slopedist CSV; 15 comma-separated fields is
    PointRCNN; 17–18 space-separated fields is a KITTI label file; other layouts (MOTChallenge,
    COCO JSON) are read by :func:`slopedist.io.detections.convert.read_boxes`, which counts the
    rows it leaves out in ``dropped`` and logs them as one warning.

    Example:
        >>> import pathlib, tempfile
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "boxes.csv"
        >>> _ = path.write_text("frame,left,top,right,bottom,track_id,score,class\\n"
        ...                     "0,560,185,660,255,7,0.9,Car\\n")
        >>> boxes = read_box_file(path)
        >>> boxes.frame.tolist(), boxes.track_id.tolist(), boxes.cls.tolist()
        ([0], [7], ['Car'])
    """
    path = Path(path)
    if path.suffix.lower() == ".json":
        return _read_other_layout(path, min_score, dropped)
    first = next(iter(numbered_lines(path, "box file")), (0, ""))[1]
    if first.replace(" ", "").lower().startswith("frame,"):
        table = read_box_csv(path)
        if min_score is not None:
            table = table.select(~(table.score < min_score))
        return table
    if len(first.split(",")) == len(POINTRCNN_FIELDS):
        return read_pointrcnn(path, min_score)
    if len(first.split()) in (17, 18):
        return read_kitti_labels(path)
    return _read_other_layout(path, min_score, dropped)


def _read_other_layout(
    path: Path, min_score: float | None, dropped: DroppedBoxes | None
) -> BoxTable:
    """MOTChallenge or COCO JSON boxes (:mod:`slopedist.io.detections.formats`)."""
    from slopedist.io.detections.convert import BoxFileOptions, read_boxes  # imports this module

    return read_boxes(path, options=BoxFileOptions(min_score=min_score), dropped=dropped)
