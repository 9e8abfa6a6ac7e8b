"""The ``slopedist run`` settings of a batch drive beyond its inputs and camera: the reference
point of ``distance_m``, the options of ``ours`` and its generic classes, the vehicle classes,
the offline mode, the overlay, the exports and the columns of ``records.csv``
(:class:`RunSettings`).

Each is a manifest column (:data:`SETTING_COLUMNS`, CSV and TOML) and a batch-wide option of
``slopedist batch`` (the ``slopedist run`` option of the same name); an empty cell takes the
batch-wide value, a non-empty one replaces it (a drive's ``ours_options`` cell replaces the
batch-wide options as a whole). The cells are parsed by the parsers of ``slopedist run``
(:func:`~slopedist.estimators.base.parse_reference`,
:func:`~slopedist.estimators.parse_ours_option_list`, ...). A cell that holds several
items separates them with ``;`` (:data:`LIST_SEPARATOR`): ``odd_object_weight=0;size_learning=
true``, ``Car;Van;Truck``, ``mcap;tum`` (a comma would need quoting in a CSV file).

A batch-wide value applies to the drives whose method takes it (``reference``: every
method; ``ours_options`` and ``generic_classes``: ``ours``, ``ours-selfcal``, ``ours-offline``;
``offline``: the methods with an offline mode), so one batch can compare ``ours`` with
``paper``; a cell for a method that does not take it is an error, as is an ``overlay_format``
cell of a drive without an overlay, a generic class that is not one of the drive's vehicle
classes, and an ``ours`` drive with ``generic_sigma_only=true`` but no generic class (as for
``slopedist run``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, fields
from typing import Any

from slopedist.core.errors import ConfigurationError, InputFileError
from slopedist.core.textfiles import parse_bool
from slopedist.estimators import (
    OURS_OPTION_SEPARATOR,
    EstimatorConfig,
    available_methods,
    idle_sigma_only,
    offline_method,
    parse_ours_option_list,
    takes_ours_options,
    unscored_generic_class,
)
from slopedist.estimators.base import ReferencePoint, parse_reference
from slopedist.estimators.references import DEFAULT_REFERENCE
from slopedist.io.detections.boxes import DEFAULT_VEHICLE_CLASSES, vehicle_class_names
from slopedist.streaming.config import OverlayFormat, RunExport
from slopedist.streaming.step import RecordColumns, parse_columns

LIST_SEPARATOR = OURS_OPTION_SEPARATOR
"""Separator of the items of one manifest cell (``;``)."""

SETTING_COLUMNS = (
    "reference",
    "ours_options",
    "generic_classes",
    "vehicle_classes",
    "offline",
    "overlay",
    "overlay_format",
    "export",
    "columns",
)
"""Manifest columns of :class:`RunSettings` (each the field of that name)."""

OursOptions = tuple[tuple[str, bool | float | None], ...]


@dataclass(frozen=True)
class RunSettings:
    """How a drive is run beyond its inputs and camera (the ``slopedist run`` options of the
    same names).

    Attributes:
        reference: the point of the vehicle every method's ``distance_m`` is moved to
            (``centre``, ``nearest_face``, ``contact``; ``--reference``), None for
            :data:`~slopedist.estimators.references.DEFAULT_REFERENCE` (the nearest face).
        ours_options: ``(key, value)`` options of ``ours`` (``--ours-option``), sorted by key.
        generic_classes: class names ``ours`` reads as a mixture of vehicle types
            (``--generic-class``; a class-blind detector's class).
        vehicle_classes: class names scored as vehicles (``--vehicle-classes``).
        offline: run the method's offline mode (``--offline``: ``ours`` → ``ours-offline``).
        overlay: also write annotated frames (``--overlay``), as ``overlay_format``
            (:class:`~slopedist.streaming.config.OverlayFormat` value).
        export: :class:`~slopedist.streaming.config.RunExport` values (``--export``), in that
            enum's order.
        columns: the columns of ``records.csv`` (``--columns``:
            :class:`~slopedist.streaming.step.RecordColumns` value).
    """

    reference: str | None = None
    ours_options: OursOptions = ()
    vehicle_classes: tuple[str, ...] = DEFAULT_VEHICLE_CLASSES
    offline: bool = False
    overlay: bool = False
    overlay_format: str = OverlayFormat.MP4.value
    export: tuple[str, ...] = ()
    generic_classes: tuple[str, ...] = ()
    columns: str = RecordColumns.DEFAULT.value

    def __post_init__(self) -> None:
        object.__setattr__(self, "ours_options", tuple(sorted(self.ours_options)))
        object.__setattr__(self, "export", export_values(self.export))

    def run_method(self, method: str) -> str:
        """The estimator ``method`` runs as (its offline mode with :attr:`offline`)."""
        return offline_method(method) if self.offline else method

    def estimator(self, method: str) -> EstimatorConfig:
        """The estimator configuration of a drive of ``method`` (other options default; the
        method reports its own point, which the run moves to :meth:`shown_reference`)."""
        return EstimatorConfig(
            method=self.run_method(method),
            ours_options=self.ours_options,
            generic_classes=self.generic_classes,
        )

    def shown_reference(self) -> ReferencePoint:
        """The point of the vehicle the drive's distances are moved to (:attr:`reference`,
        else :data:`~slopedist.estimators.references.DEFAULT_REFERENCE`)."""
        return parse_reference(self.reference) if self.reference else DEFAULT_REFERENCE

    def changed(self) -> dict[str, Any]:
        """The settings that differ from the defaults (``slopedist run`` without them)."""
        default = RunSettings()
        return {
            f.name: getattr(self, f.name)
            for f in fields(self)
            if getattr(self, f.name) != getattr(default, f.name)
        }


def export_values(exports: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """``exports`` as :class:`~slopedist.streaming.config.RunExport` values, once each, in the
    enum's order.

    Raises:
        ValueError: an unknown export.
    """
    wanted = {RunExport(e.strip()) for e in exports}
    return tuple(e.value for e in RunExport if e in wanted)


def _items(text: str) -> list[str]:
    """The items of a list cell (:data:`LIST_SEPARATOR`; empty items dropped)."""
    if "," in text:
        raise ConfigurationError(
            f"'{text}': separate the items with '{LIST_SEPARATOR}' (a comma would need quoting)"
        )
    return [item.strip() for item in text.split(LIST_SEPARATOR) if item.strip()]


def _choice(kind: type[OverlayFormat] | type[RunExport], text: str) -> str:
    try:
        return kind(text.strip()).value
    except ValueError:
        raise ConfigurationError(
            f"'{text.strip()}' is not one of {', '.join(k.value for k in kind)}"
        ) from None


def _flag(text: str) -> bool:
    try:
        return parse_bool(text)
    except ValueError:
        raise ConfigurationError(f"'{text.strip()}' is not true or false") from None


def _class_names(text: str) -> tuple[str, ...]:
    names = tuple(_items(text))
    if not names:
        raise ConfigurationError("names no class")
    return names


CELL_PARSERS: dict[str, Callable[[str], Any]] = {
    "reference": lambda text: parse_reference(text).value,
    "ours_options": parse_ours_option_list,
    "generic_classes": _class_names,
    "vehicle_classes": lambda text: vehicle_class_names(_items(text)),
    "offline": _flag,
    "overlay": _flag,
    "overlay_format": lambda text: _choice(OverlayFormat, text),
    "export": lambda text: tuple(_choice(RunExport, item) for item in _items(text)),
    "columns": lambda text: parse_columns(text.strip()).value,
}
"""How each cell of :data:`SETTING_COLUMNS` is read (raising ConfigurationError)."""


OURS_COLUMNS = ("ours_options", "generic_classes")
"""The setting columns of the methods built on ``ours`` (:func:`ours_methods`)."""


def ours_methods() -> list[str]:
    """The methods that take ``ours_options`` and ``generic_classes``."""
    return [m for m in available_methods() if takes_ours_options(m)]


def _offline_problem(method: str) -> str | None:
    """Why ``method`` cannot run offline, or None when it can."""
    try:
        offline_method(method)
    except ConfigurationError as exc:
        return str(exc)
    return None


def drive_settings(
    cells: Mapping[str, str],
    method: str,
    batch: RunSettings,
    where: Callable[[str, str], InputFileError],
) -> RunSettings:
    """The :class:`RunSettings` of a drive of ``method`` from its (stripped) manifest cells and
    the batch-wide values ``batch`` (see the module docstring); ``where(field, message)``
    builds the error for a bad cell."""
    given: dict[str, Any] = {}
    for column in SETTING_COLUMNS:
        if cells.get(column):
            try:
                given[column] = CELL_PARSERS[column](cells[column])
            except ConfigurationError as exc:
                raise where(column, str(exc)) from None
    ours = takes_ours_options(method)
    for column in OURS_COLUMNS:
        if column in given and not ours:
            raise where(
                column,
                f"is for methods {', '.join(ours_methods())}; this drive's method is '{method}'",
            )
    problem = _offline_problem(method)
    if given.get("offline") and problem:
        raise where("offline", problem)
    settings: dict[str, Any] = {
        "reference": batch.reference,
        "ours_options": batch.ours_options if ours else (),
        "generic_classes": batch.generic_classes if ours else (),
        "vehicle_classes": batch.vehicle_classes,
        "offline": batch.offline and problem is None,
        "overlay": batch.overlay,
        "overlay_format": batch.overlay_format,
        "export": batch.export,
        "columns": batch.columns,
    } | given
    if "overlay_format" in given and not settings["overlay"]:
        raise where("overlay_format", "is for drives with an overlay (overlay = true)")
    mistake = _generic_problem(settings)
    if mistake:
        raise where(*mistake)
    return RunSettings(**settings)


def _generic_problem(settings: Mapping[str, Any]) -> tuple[str, str] | None:
    """``(column, message)`` for generic classes that are not vehicle classes (their boxes
    get no distance), or for ``generic_sigma_only=true`` without a generic class (it would do
    nothing); None when neither."""
    unscored = unscored_generic_class(settings["generic_classes"], settings["vehicle_classes"])
    if unscored is not None:
        return "generic_classes", (
            f"'{unscored}' is not one of the vehicle classes "
            f"({LIST_SEPARATOR.join(settings['vehicle_classes'])}), so its boxes get no "
            "distance; add it to vehicle_classes"
        )
    if idle_sigma_only(settings["ours_options"], settings["generic_classes"]):
        return "ours_options", (
            "generic_sigma_only=true applies to generic classes and this drive has none: name "
            "the class the detector gives to any vehicle in column generic_classes (or "
            "--generic-class NAME)"
        )
    return None


def settings_json(values: Mapping[str, Any]) -> dict[str, Any]:
    """:class:`RunSettings` fields (all or some) as plain JSON values: ``ours_options`` as a
    table ``{key: value}``, the other tuples as lists."""
    return {
        k: dict(v) if k == "ours_options" else list(v) if isinstance(v, tuple) else v
        for k, v in values.items()
    }


def item_text(value: Any) -> str:
    """A scalar as the text of a manifest cell or cell item: ``true``/``false``, ``none``,
    ``0.028`` (what the cell parsers read back)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return "none" if value is None else str(value)


def settings_cell(value: Any) -> Any:
    """A value of :func:`settings_json` as a manifest cell: a table as ``key=value`` items and
    a list as its items, joined by :data:`LIST_SEPARATOR` (what the manifest column reads back);
    other values as they are."""
    if isinstance(value, dict):
        return LIST_SEPARATOR.join(f"{k}={item_text(v)}" for k, v in value.items())
    if isinstance(value, list):
        return LIST_SEPARATOR.join(str(v) for v in value)
    return value


def unapplied(batch: RunSettings, drive_methods: Iterable[str]) -> list[str]:
    """Warnings for batch-wide ``ours_options``, ``generic_classes`` and ``offline`` values
    that no
    drive takes (none of the drives' methods ``drive_methods`` is one they apply to), so that
    a batch of ``paper`` drives given ``--offline`` says it ran them causally."""
    methods = list(drive_methods)
    ours = any(takes_ours_options(m) for m in methods)
    offline = any(_offline_problem(m) is None for m in methods)
    given = {
        "--ours-option": bool(batch.ours_options) and not ours,
        "--generic-class": bool(batch.generic_classes) and not ours,
        "--offline": batch.offline and not offline,
    }
    return [
        f"{option} applies to no drive of this batch (methods: {', '.join(sorted(set(methods)))})"
        for option, unused in given.items()
        if unused
    ]
