"""Any supported box layout in, any out: the library side of ``slopedist convert``.

Layouts (:class:`BoxFormat`): the slopedist CSV, KITTI labels and PointRCNN
(:mod:`slopedist.io.detections.readers`), MOTChallenge, COCO JSON and YOLO folders
(:mod:`slopedist.io.detections.formats`). ``AUTO`` tells them apart by content: a folder is YOLO,
``.json`` is COCO, otherwise the first line decides (see :func:`sniff_format`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

import numpy as np

from slopedist.core.errors import ConfigurationError, InputFileError
from slopedist.core.textfiles import numbered_lines
from slopedist.io.detections.boxes import NO_TRACK, BoxTable
from slopedist.io.detections.dropped import DroppedBoxes
from slopedist.io.detections.format_writers import (
    class_indices,
    write_coco,
    write_mot,
    write_yolo_folder,
    yolo_optional_columns,
)
from slopedist.io.detections.formats import (
    read_coco,
    read_coco_image_map,
    read_mot,
    read_yolo_folder,
)
from slopedist.io.detections.onnx_detector import COCO_VEHICLES
from slopedist.io.detections.readers import (
    CSV_BOX_COLUMNS,
    CSV_REQUIRED,
    POINTRCNN_FIELDS,
    read_box_csv,
    read_kitti_labels,
    read_pointrcnn,
)
from slopedist.io.detections.writers import write_box_csv


class BoxFormat(str, Enum):
    """A box file layout."""

    AUTO = "auto"
    CSV = "csv"
    KITTI = "kitti"
    POINTRCNN = "pointrcnn"
    MOT = "mot"
    COCO = "coco"
    YOLO = "yolo"


WRITABLE = (BoxFormat.CSV, BoxFormat.MOT, BoxFormat.COCO, BoxFormat.YOLO)
"""Layouts :func:`write_boxes` writes."""


def target_format_of(target: str | Path, fmt: BoxFormat | str = BoxFormat.AUTO) -> BoxFormat:
    """The layout to write ``target`` in: ``fmt`` when given, else COCO for a ``.json`` file
    and the slopedist CSV for any other.

    Raises:
        ConfigurationError: ``fmt`` and the suffix disagree about JSON (COCO to a file that is
            not ``.json``, another layout to ``.json``): the file would not read back as what
            its name says.
    """
    kind, is_json = BoxFormat(fmt), Path(target).suffix.lower() == ".json"
    if kind is BoxFormat.AUTO:
        return BoxFormat.COCO if is_json else BoxFormat.CSV
    if is_json != (kind is BoxFormat.COCO):
        suffix = Path(target).suffix or "suffix-less"
        raise ConfigurationError(
            f"{target}: a {suffix} target for the '{kind.value}' layout; JSON is COCO's: name "
            "the file after its layout, or leave --to out"
        )
    return kind


@dataclass(frozen=True)
class BoxFileOptions:
    """What some layouts need besides the file.

    Attributes:
        image_size: ``(width, height)`` in pixels (YOLO's normalised boxes).
        coco_images: a COCO dataset JSON whose ``images`` map image ids to frames.
        frame_base: number of the first frame in MOT (default 1) or YOLO (default 0) files.
        min_score: drop boxes scored below this (unknown scores are kept).
    """

    image_size: tuple[int, int] | None = None
    coco_images: Path | None = None
    frame_base: int | None = None
    min_score: float | None = None


def _yolo_size(options: BoxFileOptions) -> tuple[int, int]:
    if options.image_size is None:
        raise ConfigurationError("YOLO label files are normalised: give the image size")
    return options.image_size


def sniff_format(path: str | Path) -> BoxFormat:
    """The layout of ``path`` from its content (see the module docstring)."""
    path = Path(path)
    if path.is_dir():
        return BoxFormat.YOLO
    if path.suffix.lower() == ".json":
        return BoxFormat.COCO
    lineno, first = next(iter(numbered_lines(path, "box file")), (1, ""))
    commas = len(first.split(","))
    if _is_csv_header(first):
        return BoxFormat.CSV
    if commas > 1 and not _is_number(first.split(",")[0]):
        raise InputFileError(
            path,
            f"the header '{first[:120]}' is not a box file's: the slopedist CSV needs the "
            f"columns {','.join(CSV_BOX_COLUMNS)} (the first five required, in any order; rename "
            "yours), and MOTChallenge and PointRCNN files have no header",
            line=lineno,
        )
    if commas == len(POINTRCNN_FIELDS):
        return BoxFormat.POINTRCNN
    if commas in (7, 9, 10):
        return BoxFormat.MOT
    if len(first.split()) in (17, 18):
        return BoxFormat.KITTI
    raise InputFileError(
        path,
        "unrecognised box file layout (expected the slopedist CSV with a 'frame,left,top,right,"
        "bottom' header, PointRCNN, KITTI labels, MOTChallenge, COCO JSON or a YOLO folder)",
        line=1,
    )


def _is_csv_header(line: str) -> bool:
    """Whether ``line`` is the slopedist CSV's header: ``frame`` first, or the required columns
    in any order (:func:`~slopedist.io.detections.readers.read_box_csv` finds them by name; the
    names compared without regard to case, whose difference it then names, and to quotes)."""
    names = [name.strip().strip('"').strip().lower() for name in line.split(",")]
    return names[0] == "frame" or set(CSV_REQUIRED) <= set(names)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_boxes(
    path: str | Path,
    fmt: BoxFormat | str = BoxFormat.AUTO,
    options: BoxFileOptions | None = None,
    class_map: Mapping[int, str] | None = None,
    dropped: DroppedBoxes | None = None,
) -> BoxTable:
    """Boxes of a file or folder in layout ``fmt`` (AUTO: :func:`sniff_format`).

    The rows the reader left out (not those below ``min_score``) are counted in ``dropped``
    (a new one per file) and, when there are any, logged as one warning
    (:meth:`~slopedist.io.detections.dropped.DroppedBoxes.warn`).
    """
    opt = options or BoxFileOptions()
    kind = BoxFormat(fmt)
    kind = sniff_format(path) if kind is BoxFormat.AUTO else kind
    tally = DroppedBoxes() if dropped is None else dropped
    if kind is BoxFormat.YOLO:
        table = read_yolo_folder(path, _yolo_size(opt), class_map, opt.frame_base or 0, tally)
    elif kind is BoxFormat.COCO:
        frames = None if opt.coco_images is None else read_coco_image_map(opt.coco_images)
        table = read_coco(path, frames, class_map, tally)
    elif kind is BoxFormat.MOT:
        table = read_mot(path, 1 if opt.frame_base is None else opt.frame_base, tally)
    elif kind is BoxFormat.POINTRCNN:
        table = read_pointrcnn(path)
    elif kind is BoxFormat.KITTI:
        table = read_kitti_labels(path)
    else:
        table = read_box_csv(path)
    tally.warn(path, len(table))
    if opt.min_score is not None:
        table = table.select(~(table.score < opt.min_score))
    return table


def write_boxes(
    table: BoxTable,
    path: str | Path,
    fmt: BoxFormat | str,
    options: BoxFileOptions | None = None,
) -> int:
    """Write ``table`` in layout ``fmt`` (one of :data:`WRITABLE`); returns the boxes left out
    because the layout has no index for their class."""
    opt = options or BoxFileOptions()
    kind = BoxFormat(fmt)
    if kind is BoxFormat.CSV:
        write_box_csv(table, path)
        return 0
    if kind is BoxFormat.MOT:
        return write_mot(table, path, 1 if opt.frame_base is None else opt.frame_base)
    if kind is BoxFormat.COCO:
        return write_coco(table, path)
    if kind is BoxFormat.YOLO:
        return write_yolo_folder(table, path, _yolo_size(opt))
    raise ConfigurationError(
        f"cannot write '{kind.value}' boxes; choose one of {', '.join(f.value for f in WRITABLE)}"
    )


def unkept(table: BoxTable, fmt: BoxFormat | str) -> list[str]:
    """What writing ``table`` in layout ``fmt`` does not keep, one note per field (empty: the
    boxes read back as they are; boxes left out for their class are counted by
    :func:`write_boxes`)."""
    kind = BoxFormat(fmt)
    notes = []
    n = len(table)
    if kind is BoxFormat.MOT:
        other = sorted({str(c) for c in table.cls} - {"Car"})
        if other:
            k = int(np.count_nonzero(table.cls != "Car"))
            notes.append(
                f"class: MOT det.txt has none; {k} boxes of class {', '.join(other)} read back "
                "as Car"
            )
        k = int(np.count_nonzero(~np.isfinite(table.score)))
        if k:
            notes.append(
                f"score: {k} unknown scores written as -1 (MOT's placeholder, read back as unknown)"
            )
    if kind is BoxFormat.YOLO:
        _, ok = class_indices(table, COCO_VEHICLES)
        with_score, with_track = yolo_optional_columns(table, ok)
        if not with_score:
            k = int(np.count_nonzero(~np.isfinite(table.score[ok])))
            notes.append(f"score: {k} of {int(ok.sum())} boxes have none, so no box's is written")
        if not with_track and np.any(table.track_id[ok] != NO_TRACK):
            notes.append("track_id: written only with scores, so not written")
    if kind is not BoxFormat.CSV:
        lost = list(table.extra)
    else:
        lost = [k for k, v in table.extra.items() if np.ndim(v) != 1]
    if lost and n:
        notes.append(f"column(s) {', '.join(lost)}: not in the '{kind.value}' layout")
    return notes


def convert_boxes(
    source: str | Path,
    target: str | Path,
    source_format: BoxFormat | str = BoxFormat.AUTO,
    target_format: BoxFormat | str = BoxFormat.AUTO,
    options: BoxFileOptions | None = None,
) -> tuple[int, int, list[str]]:
    """Read ``source`` and write it to ``target`` (in ``target_format``, or the layout its
    suffix names: :func:`target_format_of`); returns (boxes read, boxes left out, what the
    target does not keep: :func:`unkept`)."""
    target_format = target_format_of(target, target_format)
    if target_format is BoxFormat.YOLO and (options or BoxFileOptions()).image_size is None:
        raise ConfigurationError("YOLO label files are normalised: give the image size")
    table = read_boxes(source, source_format, options)
    notes = unkept(table, target_format)
    return len(table), write_boxes(table, target, target_format, options), notes
