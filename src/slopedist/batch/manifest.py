"""The drives of a batch: a CSV or TOML manifest, or a folder of drives in the usual layout.

A CSV manifest has one drive per row and at least the columns ``drive`` (a name, also the output
sub-folder), ``frames`` (image folder, video or drive log), ``calib`` and ``boxes``; ``method`` and
the columns of :data:`OPTIONAL_COLUMNS` are optional (an empty cell takes the batch-wide value
of :class:`DriveDefaults`, the ``slopedist batch`` option of that name).
A drive log (``.bag``, ``.mcap``, ``.db3`` or a ROS 2 bag folder) names its topics in
``image_topic`` (required for a log unless the batch gives one), ``rotation_topic`` and
``speed_topic``, and may leave ``calib`` empty (or a manifest of logs leave the column out) to
use the log's ``camera_info``; ``calib`` is required for image folders and videos. Paths are
relative to the manifest's folder.

The run settings (:mod:`~slopedist.batch.settings`) are the columns ``reference``
(``centre``, ``nearest_face``, ``contact``), ``ours_options`` (``KEY=VALUE`` items separated by
``;``: ``odd_object_weight=0;size_learning=true``), ``vehicle_classes`` (``Car;Van;Truck``),
``offline`` and ``overlay`` (``true``/``false``, ``yes``/``no``, ``1``/``0``),
``overlay_format`` (``mp4``, ``png``) and ``export`` (``mcap``, ``tum``, ``mcap;tum``).
``reference`` and ``ours_options`` are for ``ours``, ``ours-selfcal`` and ``ours-offline``,
``offline`` for a method with an offline mode, ``overlay_format`` for a drive with an overlay.

A TOML manifest holds the same keys in ``[[drive]]`` tables; there a list cell may be a list
(``export = ["mcap", "tum"]``), ``ours_options`` a table (``{odd_object_weight = 0,
size_learning = true}``) or a list of ``KEY=VALUE`` texts, and a flag a boolean.

A folder without a manifest is read as one drive per sub-folder: its frames
(:data:`FRAME_NAMES`, else its one drive log, or the folder itself when it is a ROS 2 bag),
``calib.txt`` (optional for a log), ``boxes.csv`` and optionally ``times.txt`` (not for a log);
a log's image topic is the batch-wide one.

Every mistake is an :class:`~slopedist.core.errors.InputFileError` naming the manifest, the line
(CSV) or drive entry (TOML) and the field.
"""

from __future__ import annotations

import csv
import math
import sys
import unicodedata
from collections.abc import Callable, Iterator, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from slopedist.batch.settings import (
    LIST_SEPARATOR,
    SETTING_COLUMNS,
    RunSettings,
    drive_settings,
    item_text,
    settings_json,
)
from slopedist.core.camera import KITTI_CAMERA_HEIGHT_M
from slopedist.core.errors import ConfigurationError, InputFileError, MissingInputError
from slopedist.core.textfiles import decoded_lines, read_text, repeated_names
from slopedist.estimators import DEFAULT_METHOD, available_methods
from slopedist.io.rosbag import is_log_path
from slopedist.odometry.base import LOOKBACK_S
from slopedist.streaming.pipeline import ODOMETRY_CHOICES

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

REQUIRED_COLUMNS = ("drive", "frames")
"""Columns every manifest has (``calib`` too unless every drive is a drive log)."""
BOX_COLUMNS = ("boxes", "detector")
"""Where a drive's boxes come from: a box file or an ONNX detector (exactly one per drive)."""
LOG_COLUMNS = ("image_topic", "rotation_topic", "speed_topic")
"""Topics of a drive log (``slopedist run --image-topic`` etc.); only for drives whose frames
are a log, and ``image_topic`` is required for those."""
OPTIONAL_COLUMNS = (
    "calib",
    *BOX_COLUMNS,
    *LOG_COLUMNS,
    "method",
    "timestamps",
    "fps",
    "score",
    "odometry",
    "height",
    "mount_angle",
    "lookback",
    "depth_dir",
    "sequence",
    *SETTING_COLUMNS,
)
"""Manifest columns beyond the required ones; each is the ``slopedist run`` option of that name
(``height`` metres, ``mount_angle`` degrees, ``lookback`` seconds, ``fps`` frames/s; the
settings of :mod:`~slopedist.batch.settings`); one of :data:`BOX_COLUMNS` must be there, and
``calib`` unless every drive is a log."""

FRAME_NAMES = ("image_02", "frames", "images", "video.mp4", "video.avi", "video.mkv")
"""Where a drive folder's frames are, in order of preference (folder layout)."""

CALIB_NAME = "calib.txt"
BOXES_NAME = "boxes.csv"
TIMESTAMPS_NAME = "times.txt"


@dataclass(frozen=True)
class DriveDefaults:
    """Batch-wide values for the cells a manifest leaves empty (and for folder layouts):
    ``settings`` apply to the drives whose method takes them (:func:`~slopedist.batch.
    settings.drive_settings`), ``image_topic`` to drives whose frames are a drive log."""

    method: str = DEFAULT_METHOD
    odometry: str = "builtin"
    height_m: float = KITTI_CAMERA_HEIGHT_M
    mount_angle_deg: float = 0.0
    lookback_s: float = LOOKBACK_S
    settings: RunSettings = field(default_factory=RunSettings)
    image_topic: str | None = None


@dataclass(frozen=True)
class DriveSpec:
    """One drive of a batch: its inputs and the ``slopedist run`` options for it.

    Attributes:
        name: drive name, the output sub-folder ``OUT/<name>``.
        frames: absolute path of the image folder, video or drive log.
        calib: absolute path of the calibration file, or None for a drive log's
            ``camera_info``.
        boxes / detector: the box file, or the ONNX detector run on every frame (default
            settings); exactly one is set.
        method: estimator name.
        timestamps: timestamps file or None; ``fps``: frame rate (frames/s) or None.
        score: minimum box score or None.
        odometry: visual odometry backend (:data:`ODOMETRY_CHOICES`).
        height_m: camera height above the road (metres); ``mount_angle_deg``: camera pitch
            relative to the vehicle (degrees); ``lookback_s``: ego-gradient look-back (seconds).
        depth_dir: folder of per-frame depth maps for the ``depthmap`` method, or None.
        sequence: sequence name in ``run.json`` (default: the drive name).
        image_topic / rotation_topic / speed_topic: a drive log's image topic, orientation
            topic replacing the visual odometry, and ego-speed topic (m/s; headway times), or
            None.
        settings: reference point, ``ours`` options, vehicle classes, offline mode, overlay
            and exports (:class:`~slopedist.batch.settings.RunSettings`).
        origin: where the drive was defined (manifest and line), for messages.
    """

    name: str
    frames: Path
    calib: Path | None
    boxes: Path | None
    method: str = DEFAULT_METHOD
    timestamps: Path | None = None
    fps: float | None = None
    score: float | None = None
    odometry: str = "builtin"
    height_m: float = KITTI_CAMERA_HEIGHT_M
    mount_angle_deg: float = 0.0
    lookback_s: float = LOOKBACK_S
    depth_dir: Path | None = None
    sequence: str | None = None
    detector: Path | None = None
    image_topic: str | None = None
    rotation_topic: str | None = None
    speed_topic: str | None = None
    settings: RunSettings = field(default_factory=RunSettings)
    origin: str = ""


def _number(text: str, where: Callable[[str, str], InputFileError], name: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise where(name, f"'{text}' is not a number") from None
    if not math.isfinite(value):
        raise where(name, f"'{text}' is not a finite number")
    return value


def _positive(text: str, where: Callable[[str, str], InputFileError], name: str) -> float:
    value = _number(text, where, name)
    if value <= 0:
        raise where(name, f"must be positive, got {text}")
    return value


def check_drive_name(name: str) -> str | None:
    """Why ``name`` cannot be a drive (an output folder name), or None when it can."""
    if not name:
        return "the drive name is empty"
    if name.startswith(".") or any(c in name for c in "/\\") or name != name.strip():
        return f"'{name}' cannot be a folder name (no '/', '\\', leading '.' or spaces)"
    return None


def spec_from_row(
    row: Mapping[str, str],
    base: Path,
    defaults: DriveDefaults,
    where: Callable[[str, str], InputFileError],
    origin: str,
) -> DriveSpec:
    """A :class:`DriveSpec` from one manifest row of strings (relative paths against ``base``).

    ``where(field, message)`` builds the error for a bad field.
    """
    cells = {k: str(v).strip() for k, v in row.items() if v is not None}
    for column in REQUIRED_COLUMNS:
        if not cells.get(column):
            raise where(column, "is empty")
    problem = check_drive_name(cells["drive"])
    if problem:
        raise where("drive", problem)

    def path(column: str) -> Path | None:
        text = cells.get(column, "")
        return (base / text).absolute() if text else None

    method = cells.get("method") or defaults.method
    if method not in available_methods():
        raise where("method", f"unknown method '{method}'; choose from {available_methods()}")
    odometry = cells.get("odometry") or defaults.odometry
    if odometry not in ODOMETRY_CHOICES:
        raise where("odometry", f"'{odometry}' is not one of {', '.join(ODOMETRY_CHOICES)}")
    signed = ("mount_angle", "score")  # any finite number (a score may be a logit: 0, < 0)
    nums = {
        k: _number(cells[k], where, k) if k in signed else _positive(cells[k], where, k)
        for k in ("fps", "score", "height", "mount_angle", "lookback")
        if cells.get(k)
    }
    if bool(cells.get("boxes")) == bool(cells.get("detector")):
        which = "both" if cells.get("boxes") else "neither"
        raise where("boxes", f"give a box file or a detector (exactly one; {which} given)")
    frames = path("frames")
    assert frames is not None
    is_log = is_log_path(frames)
    if is_log and not cells.get("image_topic") and defaults.image_topic:
        cells["image_topic"] = defaults.image_topic
    check_log_cells(cells, is_log, where)
    return DriveSpec(
        name=cells["drive"],
        frames=frames,
        calib=path("calib"),
        boxes=path("boxes"),
        method=method,
        timestamps=path("timestamps"),
        fps=nums.get("fps"),
        score=nums.get("score"),
        odometry=odometry,
        height_m=nums.get("height", defaults.height_m),
        mount_angle_deg=nums.get("mount_angle", defaults.mount_angle_deg),
        lookback_s=nums.get("lookback", defaults.lookback_s),
        depth_dir=path("depth_dir"),
        sequence=cells.get("sequence") or None,
        detector=path("detector"),
        image_topic=cells.get("image_topic") or None,
        rotation_topic=cells.get("rotation_topic") or None,
        speed_topic=cells.get("speed_topic") or None,
        settings=drive_settings(cells, method, defaults.settings, where),
        origin=origin,
    )


def check_log_cells(
    cells: Mapping[str, str], is_log: bool, where: Callable[[str, str], InputFileError]
) -> None:
    """Fail for cells that do not fit the kind of ``frames``: a drive log needs an
    ``image_topic`` and takes no ``timestamps`` (its header stamps are the times); image
    folders and videos need a ``calib`` and take no topics."""
    if is_log:
        if not cells.get("image_topic"):
            raise where(
                "image_topic",
                f"is empty: frames '{cells['frames']}' is a drive log; name its image topic "
                "here or with batch --image-topic (list the topics with: slopedist log info LOG)",
            )
        if cells.get("timestamps"):
            raise where("timestamps", "a drive log's frame times are its header stamps")
        return
    if not cells.get("calib"):
        raise where(
            "calib",
            "is empty: image folders and videos need a calibration file (only a drive log "
            "can use its camera_info topic)",
        )
    for column in LOG_COLUMNS:
        if cells.get(column):
            raise where(
                column,
                f"is for drive logs (.bag, .mcap, .db3 or a ROS 2 bag folder); frames "
                f"'{cells['frames']}' is not one",
            )


def _check_unique(specs: list[DriveSpec], where: Callable[[int, str], InputFileError]) -> None:
    """Each drive's output folder ``OUT/<drive>`` must be its own on any file system: names
    equal but for letter case or Unicode normal form (``Lead``, ``lead``) are one folder on
    macOS and Windows, where the second drive would overwrite the first."""
    seen: dict[str, str] = {}
    for i, spec in enumerate(specs):
        key = unicodedata.normalize("NFC", spec.name).casefold()
        if key in seen:
            first = seen[key]
            same = (
                ""
                if first == spec.name
                else f" as '{first}' (one output folder on macOS and Windows)"
            )
            raise where(i, f"drive '{spec.name}' is listed twice{same} ({spec.origin} and earlier)")
        seen[key] = spec.name


def read_csv_manifest(path: Path, defaults: DriveDefaults = DriveDefaults()) -> list[DriveSpec]:
    """The drives of a CSV manifest (see the module docstring)."""
    reader = csv.DictReader(decoded_lines(path, "batch manifest"))  # strict UTF-8
    try:
        fieldnames = reader.fieldnames or []
    except csv.Error as exc:
        raise InputFileError(path, f"not a valid CSV header ({exc})", line=1) from None
    header = [h.strip() for h in fieldnames]
    twice = repeated_names(header)
    if twice:  # csv.DictReader would keep the last of the cells silently
        message = f"column(s) {', '.join(twice)} named twice in the header"
        raise InputFileError(path, message, line=1, field=twice[0])
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    missing += [] if set(BOX_COLUMNS) & set(header) else ["boxes"]
    if missing:
        names = ", ".join(missing).replace("boxes", "boxes (or detector)")
        raise InputFileError(path, f"missing column(s) {names}", line=1, field=missing[0])
    unknown = [c for c in header if c not in REQUIRED_COLUMNS + OPTIONAL_COLUMNS]
    if unknown:
        raise InputFileError(
            path,
            f"unknown column; known: {', '.join(REQUIRED_COLUMNS + OPTIONAL_COLUMNS)}",
            line=1,
            field=unknown[0],
        )
    reader.fieldnames = header
    specs, lines = [], []
    for row in _rows(reader, path):
        line = reader.line_num
        if not any((v or "").strip() for v in row.values()):
            continue
        if None in row:
            raise InputFileError(path, "more cells than columns", line=line)

        def where(field: str, message: str, line: int = line) -> InputFileError:
            return InputFileError(path, message, line=line, field=field)

        specs.append(spec_from_row(row, path.parent, defaults, where, f"{path}:{line}"))
        lines.append(line)
    _check_unique(specs, lambda i, msg: InputFileError(path, msg, line=lines[i], field="drive"))
    return specs


def _rows(reader: csv.DictReader[str], path: Path) -> Iterator[dict[str | Any, Any]]:
    """The reader's rows; a malformed CSV row (an over-long field, an open quote, a NUL
    byte) is an error naming its line."""
    while True:
        try:
            row = next(reader)
        except StopIteration:
            return
        except csv.Error as exc:
            line = reader.reader.line_num  # DictReader's own count lags on an error
            raise InputFileError(path, f"not a valid CSV row ({exc})", line=line) from None
        yield row


def read_toml_manifest(path: Path, defaults: DriveDefaults = DriveDefaults()) -> list[DriveSpec]:
    """The drives of a TOML manifest: ``[[drive]]`` tables with the CSV manifest's keys
    (``drive`` is the name); errors name the n-th ``[[drive]]`` entry."""
    try:
        data = tomllib.loads(read_text(path, "batch manifest"))
    except tomllib.TOMLDecodeError as exc:
        raise InputFileError(path, f"not valid TOML: {exc}") from None
    entries = data.get("drive")
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise InputFileError(path, "expected [[drive]] tables", field="drive")
    known = REQUIRED_COLUMNS + OPTIONAL_COLUMNS
    specs = []
    for i, entry in enumerate(entries, start=1):

        def where(field: str, message: str, i: int = i) -> InputFileError:
            return InputFileError(path, f"[[drive]] entry {i}: {message}", field=field)

        unknown = [k for k in entry if k not in known]
        if unknown:
            raise where(unknown[0], f"unknown key; known: {', '.join(known)}")
        row = {k: toml_cell(k, v, where) for k, v in entry.items()}
        specs.append(spec_from_row(row, path.parent, defaults, where, f"{path} entry {i}"))
    _check_unique(
        specs, lambda i, msg: InputFileError(path, f"[[drive]] entry {i + 1}: {msg}", field="drive")
    )
    return specs


def toml_cell(key: str, value: Any, where: Callable[[str, str], InputFileError]) -> str:
    """A TOML manifest value as the CSV cell it stands for: a boolean as ``true``/``false``, a
    list as its items joined by ``;`` (:data:`~slopedist.batch.settings.LIST_SEPARATOR`), a
    table (only ``ours_options``) as ``KEY=VALUE`` items joined the same way."""
    if isinstance(value, dict) and key == "ours_options":
        items = [f"{k}={toml_cell(key, v, where)}" for k, v in value.items()]
        return LIST_SEPARATOR.join(items)
    if isinstance(value, list) and all(isinstance(v, (str, bool, int, float)) for v in value):
        return LIST_SEPARATOR.join(toml_cell(key, v, where) for v in value)
    if isinstance(value, (dict, list)):
        raise where(key, f"expected a string, number or boolean, got {value!r}")
    return item_text(value)


def _first_existing(folder: Path, names: tuple[str, ...]) -> Path | None:
    return next((folder / n for n in names if (folder / n).exists()), None)


def folder_log(folder: Path) -> Path | None:
    """The drive log of a drive folder (folder layout): the folder itself when it is a ROS 2
    bag folder, else its one ``.bag``, ``.mcap`` or ``.db3`` file or ROS 2 bag sub-folder
    (hidden names ignored); None when it holds none.

    Raises:
        ConfigurationError: the folder holds several logs (which one is the drive is unclear).
    """
    if is_log_path(folder):
        return folder
    logs = sorted(p for p in folder.iterdir() if not p.name.startswith(".") and is_log_path(p))
    if len(logs) > 1:
        raise ConfigurationError(
            f"drive folder {folder} holds several drive logs ({', '.join(p.name for p in logs)}); "
            "keep one per folder, or name the drives in a manifest"
        )
    return logs[0] if logs else None


def _log_drive(folder: Path, log: Path, defaults: DriveDefaults) -> DriveSpec:
    """The drive of a folder whose frames are the drive log ``log`` (folder layout): its
    ``calib.txt`` if there is one (else the log's ``camera_info``), the batch-wide image topic
    (``times.txt`` is not read: a log's frame times are its header stamps)."""
    if not defaults.image_topic:
        raise ConfigurationError(
            f"drive folder {folder}: frames '{log.name}' are a drive log; name its image topic "
            "with --image-topic (list the topics with: slopedist log info LOG)"
        )
    calib = folder / CALIB_NAME
    return _folder_drive(
        folder, log, calib if calib.is_file() else None, None, defaults, defaults.image_topic
    )


def _folder_drive(
    folder: Path,
    frames: Path,
    calib: Path | None,
    timestamps: Path | None,
    defaults: DriveDefaults,
    image_topic: str | None = None,
) -> DriveSpec:
    """A drive of the folder layout with the batch-wide options of ``defaults``."""
    method = defaults.method

    def where(field: str, message: str) -> InputFileError:  # the batch-wide options' errors
        return InputFileError(folder, message, field=field)

    return DriveSpec(
        name=folder.name,
        frames=frames.absolute(),
        calib=calib.absolute() if calib is not None else None,
        boxes=(folder / BOXES_NAME).absolute(),
        method=method,
        timestamps=timestamps.absolute() if timestamps is not None else None,
        odometry=defaults.odometry,
        height_m=defaults.height_m,
        mount_angle_deg=defaults.mount_angle_deg,
        lookback_s=defaults.lookback_s,
        image_topic=image_topic,
        settings=drive_settings({}, method, defaults.settings, where),
        origin=str(folder),
    )


def discover_drives(root: Path, defaults: DriveDefaults = DriveDefaults()) -> list[DriveSpec]:
    """One drive per sub-folder of ``root`` that holds frames (:data:`FRAME_NAMES`, else a
    drive log: :func:`folder_log`), a ``calib.txt`` or a ``boxes.csv`` (sorted by name; hidden
    folders are ignored). A missing input makes that drive fail alone when it runs.

    Raises:
        ConfigurationError: a folder with several logs, or a log without the batch-wide
            ``image_topic``.
    """
    specs = []
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        if check_drive_name(folder.name):
            continue
        frames = _first_existing(folder, FRAME_NAMES)
        log = folder_log(folder) if frames is None else None
        if log is not None:
            specs.append(_log_drive(folder, log, defaults))
            continue
        calib, boxes = folder / CALIB_NAME, folder / BOXES_NAME
        if not (frames or calib.exists() or boxes.exists()):
            continue
        times = folder / TIMESTAMPS_NAME
        frames = frames or folder / FRAME_NAMES[0]
        specs.append(
            _folder_drive(folder, frames, calib, times if times.is_file() else None, defaults)
        )
    return specs


def load_drives(source: str | Path, defaults: DriveDefaults = DriveDefaults()) -> list[DriveSpec]:
    """The drives of a manifest (``.csv`` or ``.toml``) or of a folder of drives.

    Raises:
        MissingInputError: ``source`` does not exist, or a folder holds no drive.
        InputFileError: a bad manifest (file, line or entry, field), or one that lists no drive.
    """
    path = Path(source)
    if path.is_dir():
        specs = discover_drives(path, defaults)
        if not specs:
            raise MissingInputError(
                f"no drives in {path}: expected sub-folders with frames "
                f"({' or '.join(FRAME_NAMES[:3])}, a video or a drive log), {CALIB_NAME} and "
                f"{BOXES_NAME}"
            )
        return specs
    if not path.is_file():
        raise MissingInputError(f"batch source not found: {path} (a manifest or a folder)")
    if path.suffix.lower() == ".toml":
        specs = read_toml_manifest(path, defaults)
    else:
        specs = read_csv_manifest(path, defaults)
    if not specs:
        raise InputFileError(path, "lists no drives (a manifest needs a row or [[drive]] each)")
    return specs


def spec_summary(spec: DriveSpec, changed_only: bool = False) -> dict[str, Any]:
    """The run-relevant fields of ``spec`` as plain JSON values (paths as strings; the
    settings flattened, ``ours_options`` as a table), in a fixed order; ``origin`` is left out
    (moving a manifest row does not change a drive). ``changed_only``: the settings only where
    they differ from ``slopedist run``'s defaults (the form the input stamp hashes, so that a
    drive completed before a setting existed keeps its stamp)."""
    summary = {
        k: (str(v) if isinstance(v, Path) else v)
        for k, v in asdict(spec).items()
        if k not in ("origin", "settings")
    }
    settings = spec.settings.changed() if changed_only else asdict(spec.settings)
    return summary | settings_json(settings)
