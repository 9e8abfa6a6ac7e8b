"""Box files other tools write: MOTChallenge, COCO JSON and YOLO per-frame ``.txt`` folders.

Each reader returns a :class:`~slopedist.io.detections.boxes.BoxTable` (boxes ``left, top, right,
bottom`` in pixels, 0-based frame indices) and fails with an
:class:`~slopedist.core.errors.InputFileError` naming the file, line (JSON: the element) and field.

- **MOTChallenge** ``det.txt`` / ``gt.txt``: comma-separated ``frame, id, left, top, width,
  height, conf, …`` with 1-based frames (``frame_base``). Nine fields is a ``gt.txt``
  (``…, flag, class, visibility``): rows with flag 0 (to be ignored) are dropped, and the MOT17
  class index is named by :data:`MOT_CLASSES`. Otherwise (7 or 10 fields) it is a ``det.txt``:
  ``id`` −1 = no track, ``conf`` the score (−1 = unknown, as the format's writers put it),
  class ``Car``.
- **COCO JSON**: a results list ``[{"image_id", "category_id", "bbox": [x, y, w, h], "score"},
  …]`` or a dataset file with ``images``/``annotations``/``categories``. ``image_id`` becomes the
  frame through an image-id → frame map (given, read from a dataset file's ``images`` by
  :func:`read_coco_image_map`, or the identity). ``category_id`` is COCO's (car 3, truck 8) and
  named by :data:`COCO_CATEGORIES`; an optional ``track_id`` key is kept. A crowd annotation
  (``iscrowd`` 1: one box around a group of objects, which COCO's own evaluation ignores) is no
  vehicle's box and is left out.
- **YOLO** folder: one ``<name><frame>.txt`` per frame (the trailing number of the name is the
  frame, minus ``frame_base``), lines ``class cx cy w h [conf [track_id]]`` normalised to the image
  size, which must be given. Class indices are YOLO's (COCO order, car 2, see
  :data:`~slopedist.io.detections.onnx_detector.COCO_VEHICLES`), or named by the folder's
  ``classes.txt`` (labelImg's class list) when it has one.

Classes not in a map are dropped; every reader counts the rows it drops, by reason, in the
:class:`~slopedist.io.detections.dropped.DroppedBoxes` it is given. Writers for each (for
``slopedist convert``) are in :mod:`slopedist.io.detections.format_writers`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from slopedist.core.errors import ConfigurationError, InputFileError, MissingInputError
from slopedist.core.limits import MAX_INDEX
from slopedist.core.textfiles import decoded_lines, numbered_lines, read_json
from slopedist.io.detections.boxes import NO_TRACK, BoxTable
from slopedist.io.detections.dropped import DroppedBoxes
from slopedist.io.detections.onnx_detector import COCO_VEHICLES
from slopedist.io.detections.readers import (
    _index,
    _int,
    _parse,
    check_pixel_range,
    score_value,
)
from slopedist.io.framefiles import frame_number

MOT_CLASSES: dict[int, str] = {
    1: "Pedestrian",
    2: "Person_on_vehicle",
    3: "Car",
    4: "Cyclist",
    5: "Motorcycle",
    6: "Non_motorized_vehicle",
    7: "Static_person",
}
"""MOT17/MOT20 ``gt.txt`` class index → slopedist class name (others are not objects)."""

COCO_CATEGORIES: dict[int, str] = {3: "Car", 4: "Motorcycle", 6: "Bus", 8: "Truck"}
"""COCO category id (1-based, with gaps, as in COCO JSON) → slopedist class name."""

MOT_DET_FIELDS = ("frame", "id", "left", "top", "width", "height", "conf")
MOT_UNKNOWN_SCORE = -1.0
"""A ``conf`` of −1: no score (how MOTChallenge files, and slopedist's writer, say so)."""
MOT_GT_FIELDS = (*MOT_DET_FIELDS[:6], "flag", "class", "visibility")


def _corners(
    path: str | Path, xywh: list[float], *, line: int | None = None, field: str
) -> list[float]:
    """Box corners ``[x1, y1, x2, y2]`` (px) of a ``[left, top, width, height]`` box, checked
    by :func:`~slopedist.io.detections.readers.check_pixel_range`."""
    left, top, width, height = xywh
    corners = [left, top, left + width, top + height]
    check_pixel_range(path, corners, line=line, field=field, what=f"box {xywh}")
    return corners


def _corner_array(boxes: list[list[float]]) -> np.ndarray:
    return np.asarray(boxes, dtype=float).reshape(-1, 4)


MOT_KINDS: dict[str, Callable[[str], Any]] = {"flag": _int, "class": _int, "conf": score_value}
"""How the MOTChallenge fields other than frame and id are read (the rest as floats)."""


def read_mot(
    path: str | Path, frame_base: int = 1, dropped: DroppedBoxes | None = None
) -> BoxTable:
    """A MOTChallenge ``det.txt`` or ``gt.txt`` (see the module docstring); the rows left out
    are counted in ``dropped``."""
    dropped = DroppedBoxes() if dropped is None else dropped
    frames, tids, boxes, scores, classes = [], [], [], [], []
    for lineno, line in numbered_lines(path, "MOTChallenge file"):
        tok = [t.strip() for t in line.split(",")]
        if len(tok) not in (7, 9, 10):
            raise InputFileError(
                path, f"expected 7, 9 or 10 comma-separated fields, found {len(tok)}", line=lineno
            )
        names = MOT_GT_FIELDS if len(tok) == 9 else MOT_DET_FIELDS
        v: dict[str, Any] = {
            k: _parse(path, lineno, k, t, MOT_KINDS.get(k, float))
            for k, t in zip(names, tok)
            if k not in ("frame", "id")
        }
        v["frame"] = _index(path, lineno, "frame", tok[0], min(frame_base, 0))
        v["id"] = _index(path, lineno, "id", tok[1], -1)
        if v["frame"] - frame_base < 0:
            raise InputFileError(
                path, f"frame must be ≥ {frame_base}, got {v['frame']}", line=lineno, field="frame"
            )
        if len(tok) == 9:
            if v["flag"] == 0 or v["class"] not in MOT_CLASSES:
                dropped.add(
                    "flag 0 (to be ignored)"
                    if v["flag"] == 0
                    else f"class {v['class']} (not a MOT17 object class)"
                )
                continue
            classes.append(MOT_CLASSES[v["class"]])
            scores.append(np.nan)
        else:
            classes.append("Car")
            scores.append(np.nan if v["conf"] == MOT_UNKNOWN_SCORE else v["conf"])
        frames.append(v["frame"] - frame_base)
        tids.append(v["id"] if v["id"] >= 0 else NO_TRACK)
        xywh = [v["left"], v["top"], v["width"], v["height"]]
        boxes.append(_corners(path, xywh, line=lineno, field="left,top,width,height"))
    return BoxTable.build(frames, _corner_array(boxes), tids, scores, classes)


def _load_json(path: str | Path) -> Any:
    return read_json(path, "COCO JSON file")


def read_coco_image_map(path: str | Path) -> dict[int, int]:
    """Image id → frame from a COCO dataset file's ``images``: their ``frame_id`` (or
    ``frame_index``) when every image has one; else, when every ``file_name`` is named by a
    frame number (``seq/000123.png``), that number, as the frames of an image folder are
    numbered (:mod:`slopedist.io.framefiles`); else the order of their ``file_name``."""
    data = _load_json(path)
    images = data.get("images") if isinstance(data, dict) else None
    if not isinstance(images, list):
        raise InputFileError(path, "no 'images' list (a COCO dataset file is needed)")
    for key in ("frame_id", "frame_index"):
        if images and all(isinstance(im, dict) and key in im for im in images):
            return {
                _coco_index(path, f"images[{i}].id", im.get("id"), None): _coco_index(
                    path, f"images[{i}].{key}", im[key], 0
                )
                for i, im in enumerate(images)
            }
    try:
        names = [str(im["file_name"]) for im in images]
    except (KeyError, TypeError):
        raise InputFileError(
            path, "every image needs an integer 'id' and a 'file_name'", field="images"
        ) from None
    numbers = [frame_number(PurePosixPath(n.replace("\\", "/")).stem) for n in names]
    if images and all(k is not None for k in numbers):
        return _numbered_image_map(path, images, numbers)
    ordered = sorted(range(len(images)), key=lambda i: names[i])
    return {
        _coco_index(path, f"images[{i}].id", images[i].get("id"), None): frame
        for frame, i in enumerate(ordered)
    }


def _numbered_image_map(
    path: str | Path, images: list[Any], numbers: list[int | None]
) -> dict[int, int]:
    """Image id → the frame number of its ``file_name`` (``seq/000123.png`` → 123), as
    :func:`~slopedist.io.framefiles.list_frame_files` numbers the files of an image folder."""
    frames: dict[int, int] = {}
    by_frame: dict[int, int] = {}
    for i, (im, k) in enumerate(zip(images, numbers)):
        frame = _coco_index(path, f"images[{i}].file_name", k, 0)
        if frame in by_frame:
            raise InputFileError(
                path,
                f"frame number {frame} also used by images[{by_frame[frame]}]",
                field=f"images[{i}].file_name",
            )
        by_frame[frame] = i
        frames[_coco_index(path, f"images[{i}].id", im.get("id"), None)] = frame
    return frames


def _coco_class_map(
    path: str | Path, data: Any, class_map: Mapping[int, str] | None
) -> Mapping[int, str]:
    """The given map, else one from the file's ``categories`` names, else COCO's."""
    if class_map is not None:
        return class_map
    if isinstance(data, dict) and isinstance(data.get("categories"), list):
        return vehicle_classes_by_name(
            {
                _coco_index(path, f"categories[{i}].id", c.get("id"), None): str(c["name"])
                for i, c in enumerate(data["categories"])
                if isinstance(c, dict) and "name" in c
            }
        )
    return COCO_CATEGORIES


def vehicle_classes_by_name(names: Mapping[int, str]) -> dict[int, str]:
    """Class index → slopedist class name of the ``names`` (a file's own class list) that name
    one of COCO's vehicle classes, in any case (``car`` → ``Car``)."""
    by_name = {v.lower(): v for v in COCO_CATEGORIES.values()}
    return {k: by_name[v.lower()] for k, v in names.items() if v.lower() in by_name}


def _coco_index(path: str | Path, field: str, value: Any, lowest: int | None) -> int:
    """``value`` as a whole number (JSON ``3`` or ``3.0``, not ``true`` or ``"3"``) in
    ``lowest..MAX_INDEX`` (any integer when ``lowest`` is None: ids), else an error naming
    ``field``."""
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or (isinstance(value, float) and not math.isfinite(value))
        or value != int(value)
    ):
        raise InputFileError(path, f"'{value}' is not an integer", field=field)
    if lowest is not None and not lowest <= value <= MAX_INDEX:
        raise InputFileError(path, f"{int(value)} is outside {lowest}..{MAX_INDEX}", field=field)
    return int(value)


def _coco_number(
    path: str | Path, index: int, item: dict, key: str, kind: Callable[[Any], Any]
) -> Any:
    value = item.get(key)
    try:
        if isinstance(value, bool) or value is None:
            raise TypeError
        number = kind(value)
        if kind is int and number != value:
            raise ValueError
    except (TypeError, ValueError):
        raise InputFileError(
            path,
            f"'{value}' is not {'an integer' if kind is int else 'a finite number'}",
            field=f"[{index}].{key}",
        ) from None
    return number


def read_coco(
    path: str | Path,
    image_frames: Mapping[int, int] | None = None,
    class_map: Mapping[int, str] | None = None,
    dropped: DroppedBoxes | None = None,
) -> BoxTable:
    """A COCO results list or dataset file (see the module docstring); the annotations left
    out are counted in ``dropped``."""
    dropped = DroppedBoxes() if dropped is None else dropped
    data = _load_json(path)
    items = data.get("annotations") if isinstance(data, dict) else data
    if not isinstance(items, list):
        raise InputFileError(path, "expected a list of detections or an 'annotations' list")
    if image_frames is None and isinstance(data, dict) and "images" in data:
        image_frames = read_coco_image_map(path)
    cmap = _coco_class_map(path, data, class_map)
    frames, tids, boxes, scores, classes = [], [], [], [], []
    for i, item in enumerate(items):
        if not isinstance(item, dict):
            raise InputFileError(path, "expected an object", field=f"[{i}]")
        category = _coco_number(path, i, item, "category_id", int)
        image = _coco_number(path, i, item, "image_id", int)
        bbox = item.get("bbox")
        if not (isinstance(bbox, list) and len(bbox) == 4):
            raise InputFileError(path, "expected [x, y, width, height]", field=f"[{i}].bbox")
        xywh = [_coco_number(path, i, {"bbox": b}, "bbox", float) for b in bbox]
        if category not in cmap:
            dropped.add(f"category_id {category} (not in the class map)")
            continue
        if item.get("iscrowd") in (1, True):
            dropped.add("crowd annotations (iscrowd 1)")
            continue
        if image_frames is not None and image not in image_frames:
            raise InputFileError(
                path,
                f"image id {image} is not in the image-id → frame map",
                field=f"[{i}].image_id",
            )
        frame = image if image_frames is None else image_frames[image]
        frames.append(_coco_index(path, f"[{i}].image_id", frame, 0))
        boxes.append(_corners(path, xywh, field=f"[{i}].bbox"))
        scores.append(
            _coco_number(path, i, item, "score", score_value) if "score" in item else np.nan
        )
        tid = item.get("track_id")
        tids.append(NO_TRACK if tid is None else _coco_index(path, f"[{i}].track_id", tid, -1))
        classes.append(cmap[category])
    return BoxTable.build(frames, _corner_array(boxes), tids, scores, classes)


YOLO_CLASS_NAMES = "classes.txt"
"""The class list labelImg and other YOLO label tools write beside the label files: one name
per line, line k naming class index k."""

YOLO_PX_DECIMALS = 9
"""Decimals of a pixel the corners of a YOLO box are rounded to (its normalised values are
fractions of the image size, which binary floats hold inexactly)."""

_TRAILING_NUMBER = re.compile(r"(\d+)$")


def _yolo_frame(path: Path, frame_base: int) -> int:
    match = _TRAILING_NUMBER.search(path.stem)
    if match is None:
        raise InputFileError(path, "YOLO label file name must end with the frame number")
    frame = int(match.group(1)) - frame_base
    if frame < 0:
        raise InputFileError(path, f"frame number must be ≥ {frame_base}")
    return frame


def read_yolo_folder(
    folder: str | Path,
    image_size: tuple[int, int],
    class_map: Mapping[int, str] | None = None,
    frame_base: int = 0,
    dropped: DroppedBoxes | None = None,
) -> BoxTable:
    """A folder of YOLO ``.txt`` label files of images ``image_size = (width, height)`` pixels;
    the labels left out are counted in ``dropped``."""
    dropped = DroppedBoxes() if dropped is None else dropped
    folder = Path(folder)
    if not folder.is_dir():
        raise MissingInputError(f"YOLO label folder not found: {folder}")
    w, h = image_size
    if w <= 0 or h <= 0:
        raise ConfigurationError(f"image size must be positive, got {w}×{h}")
    names = folder / YOLO_CLASS_NAMES
    if class_map is None and names.is_file():
        listed = [line.strip() for line in decoded_lines(names, "YOLO class list")]
        class_map = vehicle_classes_by_name(dict(enumerate(listed)))
    cmap = COCO_VEHICLES if class_map is None else class_map
    frames, tids, boxes, scores, classes = [], [], [], [], []
    for path in sorted(p for p in folder.glob("*.txt") if p.name != YOLO_CLASS_NAMES):
        frame = _yolo_frame(path, frame_base)
        for lineno, line in numbered_lines(path, "YOLO label file"):
            tok = line.split()
            if len(tok) not in (5, 6, 7):
                raise InputFileError(path, f"expected 5 to 7 fields, found {len(tok)}", line=lineno)
            cls = _parse(path, lineno, "class", tok[0], _int)
            c = [
                _parse(path, lineno, k, t, float) for k, t in zip(("cx", "cy", "w", "h"), tok[1:5])
            ]
            score = _parse(path, lineno, "conf", tok[5], score_value) if len(tok) > 5 else np.nan
            tid = _parse(path, lineno, "track_id", tok[6], _int) if len(tok) > 6 else NO_TRACK
            if cls not in cmap:
                dropped.add(f"class {cls} (not in the class map)")
                continue
            frames.append(frame)
            xywh = [(c[0] - c[2] / 2) * w, (c[1] - c[3] / 2) * h, c[2] * w, c[3] * h]
            corners = _corners(path, xywh, line=lineno, field="cx,cy,w,h")
            # to the nanopixel: fractions of the image (1/720) leave ~1e-13 px of rounding,
            # so that a box write_yolo_folder wrote comes back as it was (200, not 199.99…97)
            boxes.append([round(v, YOLO_PX_DECIMALS) for v in corners])
            scores.append(score)
            tids.append(tid)
            classes.append(cmap[cls])
    return BoxTable.build(frames, _corner_array(boxes), tids, scores, classes)
