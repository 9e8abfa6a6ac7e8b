"""Scenario files: the built-in suite (TOML files shipped in the package) and user files.

A scenario is a small TOML file; copy a built-in one (``slopedist simulate --list`` names them,
they live in ``slopedist/datasets/synthetic/scenarios/``) and edit it. Every field is checked;
a mistake is reported as an :class:`~slopedist.errors.InputFileError` naming the file, the line
and the field (e.g. ``target[1].speed_kmh``).

Layout (units are in the names; every table and field is optional unless marked *required*)::

    name = "my_hill"                  # default: the file name
    description = "..."
    duration_s = 12.0                 # seconds of driving
    frame_rate_hz = 10.0
    seed = 1                          # seeds the world, pitch noise, box noise, image noise

    [camera]                          # defaults: KITTI camera 2 (P2), 1.65 m high
    image_width = 1242
    image_height = 375
    focal_px = 721.5377
    cx_px = 609.5593
    cy_px = 172.854
    height_m = 1.65                   # above the road
    mount_angle_deg = 0.0             # θ0, positive = optical axis pitched up
    forward_m = 0.0                   # camera ahead of the ego's box centre
    pitch_noise_deg = 0.05            # RMS suspension pitch noise
    pitch_noise_band_hz = [0.5, 2.0]

    [road]
    lanes = 2                         # lane 0 is the rightmost
    lane_width_m = 3.5
    verge_m = 6.0                     # carriageway edge to roadside structures
    start_grade_pct = 0.0

    [[road.grade_change]]             # grade changes linearly over length_m centred on at_m
    at_m = 60.0                       # (a crest when the grade falls, a sag when it rises)
    grade_pct = 12.0                  # required
    length_m = 20.0

    [[road.curve]]                    # clothoid in, arc, clothoid out
    start_m = 40.0                    # required
    length_m = 80.0                   # required, the constant-radius arc
    radius_m = 150.0                  # required, positive turns left
    transition_m = 20.0

    [[road.bump]]                     # raised-cosine speed bump
    at_m = 30.0                       # required
    height_m = 0.08
    length_m = 3.7

    [ego]                             # required
    speed_kmh = 36.0                  # required
    accel_mps2 = 0.0
    start_m = 0.0                     # plan distance of the ego's centre at t = 0
    lane = 0                          # or lateral_m = offset from the centreline, left > 0
    length_m = 4.5
    width_m = 1.8
    height_m = 1.5
    wheelbase_m = 2.7

    [[target]]                        # one or more, required
    id = 1                            # track id (default: 1, 2, ...)
    start_m = 25.0                    # required, plan distance of its centre at t = 0
    speed_kmh = 36.0                  # required
    accel_mps2 = 0.0
    lane = 0                          # or lateral_m
    length_m = 4.5
    width_m = 1.8
    height_m = 1.5
    wheelbase_m = 2.7
    colour_rgb = [170, 40, 40]
    class = "Car"

    [noise]                           # the detector-noise model (slopedist...synthetic.noise)
    jitter_px = 1.0
    scale_sigma_pct = 2.0
    miss_rate = 0.03
    truncate = true
    min_visible = 0.3
    min_height_px = 12.0

    [world]
    structure_height_m = [3.0, 14.0]
    structure_segment_m = [6.0, 16.0]
    post_spacing_m = 20.0
    object_spacing_m = 8.0

Distances along the road (``at_m``, ``start_m``) are plan distances from the ego's start region,
metres; the road is modelled from 60 m behind the rearmost vehicle to 450 m ahead of the
farthest point any vehicle reaches.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

from slopedist.datasets.synthetic.noise import BoxNoiseSpec
from slopedist.datasets.synthetic.road import GradeChange, HorizontalCurve, RoadSpec, SpeedBump
from slopedist.datasets.synthetic.scene import CameraSpec, Scenario, WorldSpec
from slopedist.datasets.synthetic.vehicles import CameraRig, VehicleSpec
from slopedist.errors import ConfigurationError, InputFileError, MissingInputError
from slopedist.io.text import read_text

if TYPE_CHECKING:
    from importlib.abc import Traversable

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

BUILTIN_PACKAGE = "slopedist.datasets.synthetic"
BUILTIN_FOLDER = "scenarios"
"""The built-in TOML files live in this folder of that package (package data)."""
SUITE = (
    "same_flat",
    "same_downhill",
    "curve_flat",
    "bumps_and_curves",
    "target_steep_uphill",
    "ego_crest",
    "ego_sag",
)
"""The built-in scenarios, in the order of the demo's tables."""

ROAD_MARGIN_BEHIND_M = 60.0
ROAD_MARGIN_AHEAD_M = 450.0


# --- locating fields in the file (for line numbers in messages) -------------------------------

_HEADER = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.\-\s\"]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"^\s*([A-Za-z0-9_\-]+|\"[^\"]*\")\s*=")


def field_lines(text: str) -> dict[str, int]:
    """Map dotted field paths (``road.curve[1].radius_m``, ``target[0]``) to 1-based lines.

    A best-effort scan of the file's table headers and ``key =`` lines (enough for messages;
    inline tables are located by their key).
    """
    lines: dict[str, int] = {}
    counts: dict[str, int] = {}
    prefix = ""
    for lineno, raw in enumerate(text.splitlines(), start=1):
        m = _HEADER.match(raw)
        if m and not raw.lstrip().startswith("#"):
            name = m.group(2).replace(" ", "").replace('"', "")
            if m.group(1) == "[[":
                i = counts.get(name, 0)
                counts[name] = i + 1
                prefix = f"{name}[{i}]"
            else:
                prefix = name
            lines.setdefault(prefix, lineno)
            continue
        k = _KEY.match(raw)
        if k:
            key = k.group(1).strip('"')
            lines.setdefault(f"{prefix}.{key}" if prefix else key, lineno)
    return lines


MAX_MAGNITUDE = 1e6
"""Largest magnitude of any number in a scenario (metres, km/h, pixels, ...): a road of
1000 km is more than any scenario needs, and larger values only overflow the renderer."""

MAX_SCENARIO_BYTES = 1_000_000
"""Largest scenario file read, bytes."""


class _Reader:
    """Typed access to a parsed TOML table with errors naming file, line and field."""

    def __init__(self, path: str, lines: dict[str, int]) -> None:
        self.path = path
        self.lines = lines

    def fail(self, field: str, message: str) -> InputFileError:
        line = self.lines.get(field)
        if line is None:  # fall back to the enclosing table
            parent = field.rsplit(".", 1)[0] if "." in field else ""
            line = self.lines.get(parent)
        return InputFileError(self.path, message, line=line, field=field)

    def table(
        self, data: dict[str, Any], key: str, where: str, allowed: tuple[str, ...]
    ) -> dict[str, Any]:
        value = data.get(key, {})
        field = f"{where}.{key}" if where else key
        if not isinstance(value, dict):
            raise self.fail(field, f"must be a table ([{field}]), got {_kind(value)}")
        self.check_keys(value, field, allowed)
        return value

    def array_of_tables(
        self, data: dict[str, Any], key: str, where: str, allowed: tuple[str, ...]
    ) -> list[dict[str, Any]]:
        value = data.get(key, [])
        field = f"{where}.{key}" if where else key
        if isinstance(value, dict):
            value = [value]
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.fail(field, f"must be an array of tables ([[{field}]]), got {_kind(value)}")
        for i, item in enumerate(value):
            self.check_keys(item, f"{field}[{i}]", allowed)
        return value

    def check_keys(self, table: dict[str, Any], where: str, allowed: tuple[str, ...]) -> None:
        for key in table:
            if key not in allowed:
                field = f"{where}.{key}" if where else key
                raise self.fail(
                    field, f"unknown field '{key}'; expected one of {', '.join(allowed)}"
                )

    def _value(self, table: dict[str, Any], key: str, where: str, default: Any) -> tuple[str, Any]:
        """``(field path, value)``; a missing field takes ``default`` (None = required)."""
        field = f"{where}.{key}" if where else key
        if key not in table:
            if default is None:
                raise self.fail(field, "required field is missing")
            return field, default
        return field, table[key]

    def number(
        self,
        table: dict[str, Any],
        key: str,
        where: str,
        default: float | None = None,
        check: Callable[[float], bool] | None = None,
        expect: str = "",
    ) -> float:
        field, value = self._value(table, key, where, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(field, f"must be a number, got {_kind(value)}")
        value = float(value)
        if not (math.isfinite(value) and abs(value) <= MAX_MAGNITUDE):
            raise self.fail(field, f"must be finite and within ±{MAX_MAGNITUDE:g}, got {value:g}")
        if check is not None and not check(value):
            raise self.fail(field, f"must be {expect}, got {value:g}")
        return value

    def integer(
        self,
        table: dict[str, Any],
        key: str,
        where: str,
        default: int | None = None,
        check: Callable[[int], bool] | None = None,
        expect: str = "",
    ) -> int:
        field, value = self._value(table, key, where, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(field, f"must be an integer, got {_kind(value)}")
        if check is not None and not check(value):
            raise self.fail(field, f"must be {expect}, got {value}")
        return value

    def string(self, table: dict[str, Any], key: str, where: str, default: str) -> str:
        field, value = self._value(table, key, where, default)
        if not isinstance(value, str):
            raise self.fail(field, f"must be a string, got {_kind(value)}")
        return value

    def boolean(self, table: dict[str, Any], key: str, where: str, default: bool) -> bool:
        field, value = self._value(table, key, where, default)
        if not isinstance(value, bool):
            raise self.fail(field, f"must be true or false, got {_kind(value)}")
        return value

    def numbers(
        self, table: dict[str, Any], key: str, where: str, n: int, default: tuple[float, ...]
    ) -> tuple[float, ...]:
        field, value = self._value(table, key, where, list(default))
        if (
            not isinstance(value, list)
            or len(value) != n
            or not all(
                isinstance(v, (int, float))
                and not isinstance(v, bool)
                and math.isfinite(v)
                and abs(v) <= MAX_MAGNITUDE
                for v in value
            )
        ):
            raise self.fail(field, f"must be a list of {n} finite numbers, got {value!r}")
        return tuple(float(v) for v in value)

    def build(self, field: str, factory: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """Call a constructor; its ConfigurationError becomes an error naming ``field``."""
        try:
            return factory(*args, **kwargs)
        except ConfigurationError as exc:
            raise self.fail(field, str(exc)) from None


def _kind(value: Any) -> str:
    if isinstance(value, bool):
        return f"the boolean {str(value).lower()}"
    if isinstance(value, str):
        return f"the string {value!r}"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "an array"
    return f"{type(value).__name__} {value!r}"


def _positive(x: float) -> bool:
    return x > 0


def _non_negative(x: float) -> bool:
    return x >= 0


# --- sections ---------------------------------------------------------------------------------

TOP_KEYS = (
    "name",
    "description",
    "duration_s",
    "frame_rate_hz",
    "seed",
    "camera",
    "road",
    "ego",
    "target",
    "noise",
    "world",
)
CAMERA_KEYS = (
    "image_width",
    "image_height",
    "focal_px",
    "cx_px",
    "cy_px",
    "height_m",
    "mount_angle_deg",
    "forward_m",
    "pitch_noise_deg",
    "pitch_noise_band_hz",
)
ROAD_KEYS = ("lanes", "lane_width_m", "verge_m", "start_grade_pct", "grade_change", "curve", "bump")
GRADE_KEYS = ("at_m", "grade_pct", "length_m")
CURVE_KEYS = ("start_m", "length_m", "radius_m", "transition_m")
BUMP_KEYS = ("at_m", "height_m", "length_m")
VEHICLE_KEYS = (
    "speed_kmh",
    "accel_mps2",
    "start_m",
    "lane",
    "lateral_m",
    "length_m",
    "width_m",
    "height_m",
    "wheelbase_m",
)
TARGET_KEYS = (*VEHICLE_KEYS, "id", "colour_rgb", "class")
NOISE_KEYS = (
    "jitter_px",
    "scale_sigma_pct",
    "miss_rate",
    "truncate",
    "min_visible",
    "min_height_px",
)
WORLD_KEYS = ("structure_height_m", "structure_segment_m", "post_spacing_m", "object_spacing_m")

TARGET_COLOURS_RGB = ((170, 40, 40), (40, 70, 160), (200, 200, 205), (60, 60, 60), (180, 140, 40))


def _camera(r: _Reader, data: dict[str, Any]) -> CameraSpec:
    t = r.table(data, "camera", "", CAMERA_KEYS)
    d = CameraSpec()
    rig = r.build(
        "camera",
        CameraRig,
        height_m=r.number(t, "height_m", "camera", 1.65, _positive, "> 0"),
        forward_m=r.number(t, "forward_m", "camera", 0.0),
        mount_angle_rad=math.radians(
            r.number(
                t, "mount_angle_deg", "camera", 0.0, lambda x: abs(x) < 30, "within ±30 degrees"
            )
        ),
        pitch_noise_rad=math.radians(
            r.number(
                t, "pitch_noise_deg", "camera", 0.0, lambda x: 0 <= x <= 5, "in [0, 5] degrees"
            )
        ),
        pitch_noise_band_hz=r.numbers(t, "pitch_noise_band_hz", "camera", 2, (0.5, 2.0)),
    )
    width = r.integer(
        t, "image_width", "camera", d.image_width, lambda x: 64 <= x <= 4096, "in 64..4096"
    )
    height = r.integer(
        t, "image_height", "camera", d.image_height, lambda x: 48 <= x <= 4096, "in 48..4096"
    )
    return r.build(
        "camera",
        CameraSpec,
        width,
        height,
        r.number(t, "focal_px", "camera", d.f, _positive, "> 0"),
        r.number(t, "cx_px", "camera", width / 2 if "image_width" in t else d.c_x),
        r.number(t, "cy_px", "camera", height / 2 if "image_height" in t else d.c_y),
        rig,
    )


def _vehicle(
    r: _Reader,
    t: dict[str, Any],
    where: str,
    track_id: int,
    lanes: int,
    lane_width: float,
    default_start: float | None,
    colour_rgb: tuple[int, int, int],
    cls: str,
) -> VehicleSpec:
    if "lane" in t and "lateral_m" in t:
        raise r.fail(f"{where}.lateral_m", "give either lane or lateral_m, not both")
    if "lateral_m" in t:
        lateral = r.number(t, "lateral_m", where)
    else:
        lane = r.integer(
            t,
            "lane",
            where,
            0,
            lambda x: 0 <= x < lanes,
            f"a lane of the road, 0..{lanes - 1} (0 = rightmost)",
        )
        lateral = -0.5 * lanes * lane_width + (lane + 0.5) * lane_width
    return r.build(
        where,
        VehicleSpec,
        track_id,
        lateral,
        r.number(t, "start_m", where, default_start),
        r.number(t, "speed_kmh", where, None, lambda x: 0 <= x <= 250, "in [0, 250] km/h") / 3.6,
        r.number(t, "accel_mps2", where, 0.0, lambda x: abs(x) <= 10, "within ±10 m/s²"),
        r.number(t, "length_m", where, 4.5, _positive, "> 0"),
        r.number(t, "width_m", where, 1.8, _positive, "> 0"),
        r.number(t, "height_m", where, 1.5, _positive, "> 0"),
        r.number(t, "wheelbase_m", where, 2.7, _positive, "> 0"),
        (colour_rgb[2] / 255.0, colour_rgb[1] / 255.0, colour_rgb[0] / 255.0),
        cls,
    )


def _road_extent(
    ego: VehicleSpec, targets: list[VehicleSpec], duration_s: float
) -> tuple[float, float]:
    starts = [ego.start_m, *(t.start_m for t in targets)]
    ends = [v.start_m + float(v.travelled_m(duration_s)) for v in (ego, *targets)]
    return min(starts) - ROAD_MARGIN_BEHIND_M, max(ends) + ROAD_MARGIN_AHEAD_M


def parse_scenario(
    data: dict[str, Any], path: str, text: str = "", default_name: str = "scenario"
) -> Scenario:
    """Build a :class:`Scenario` from parsed TOML ``data`` (``path``/``text`` for messages)."""
    r = _Reader(path, field_lines(text))
    r.check_keys(data, "", TOP_KEYS)
    name = r.string(data, "name", "", default_name)
    if not re.fullmatch(r"[A-Za-z0-9_.\-]+", name):
        raise r.fail("name", f"must be letters, digits, '_', '-' or '.', got {name!r}")
    description = r.string(data, "description", "", "")
    duration = r.number(data, "duration_s", "", 12.0, lambda x: 0 < x <= 600, "in (0, 600] s")
    rate = r.number(data, "frame_rate_hz", "", 10.0, lambda x: 1 <= x <= 100, "in [1, 100] Hz")
    seed = r.integer(data, "seed", "", 0, lambda x: 0 <= x < 2**32, "in 0 .. 2^32 − 1")
    camera = _camera(r, data)

    road_t = r.table(data, "road", "", ROAD_KEYS)
    lanes = r.integer(road_t, "lanes", "road", 2, lambda x: 1 <= x <= 6, "in 1..6")
    lane_width = r.number(road_t, "lane_width_m", "road", 3.5, lambda x: 2 <= x <= 6, "in [2, 6] m")
    changes = tuple(
        r.build(
            f"road.grade_change[{i}]",
            GradeChange,
            r.number(g, "at_m", f"road.grade_change[{i}]"),
            r.number(
                g,
                "grade_pct",
                f"road.grade_change[{i}]",
                None,
                lambda x: abs(x) <= 40,
                "within ±40 %",
            ),
            r.number(g, "length_m", f"road.grade_change[{i}]", 40.0, _positive, "> 0 m"),
        )
        for i, g in enumerate(r.array_of_tables(road_t, "grade_change", "road", GRADE_KEYS))
    )
    curves = tuple(
        r.build(
            f"road.curve[{i}]",
            HorizontalCurve,
            r.number(c, "start_m", f"road.curve[{i}]"),
            r.number(c, "length_m", f"road.curve[{i}]", None, _non_negative, "≥ 0 m"),
            r.number(
                c,
                "radius_m",
                f"road.curve[{i}]",
                None,
                lambda x: abs(x) >= 30,
                "at least 30 m in magnitude (positive turns left)",
            ),
            r.number(c, "transition_m", f"road.curve[{i}]", 20.0, _non_negative, "≥ 0 m"),
        )
        for i, c in enumerate(r.array_of_tables(road_t, "curve", "road", CURVE_KEYS))
    )
    bumps = tuple(
        r.build(
            f"road.bump[{i}]",
            SpeedBump,
            r.number(b, "at_m", f"road.bump[{i}]"),
            r.number(
                b, "height_m", f"road.bump[{i}]", 0.08, lambda x: 0 < x <= 0.3, "in (0, 0.3] m"
            ),
            r.number(b, "length_m", f"road.bump[{i}]", 3.7, lambda x: x > 0.2, "> 0.2 m"),
        )
        for i, b in enumerate(r.array_of_tables(road_t, "bump", "road", BUMP_KEYS))
    )

    if "ego" not in data:
        raise r.fail("ego", "required table [ego] is missing")
    ego_t = r.table(data, "ego", "", VEHICLE_KEYS)
    ego = _vehicle(r, ego_t, "ego", -1, lanes, lane_width, 0.0, (90, 90, 90), "Car")
    targets_t = r.array_of_tables(data, "target", "", TARGET_KEYS)
    if not targets_t:
        raise r.fail("target", "at least one [[target]] is required")
    targets = []
    for i, t in enumerate(targets_t):
        where = f"target[{i}]"
        track_id = r.integer(t, "id", where, i + 1, lambda x: 0 <= x < 2**31, "≥ 0")
        colour = r.numbers(
            t, "colour_rgb", where, 3, TARGET_COLOURS_RGB[i % len(TARGET_COLOURS_RGB)]
        )
        if not all(0 <= c <= 255 for c in colour):
            raise r.fail(f"{where}.colour_rgb", f"values must be in 0..255, got {colour}")
        cls = r.string(t, "class", where, "Car")
        targets.append(
            _vehicle(
                r,
                t,
                where,
                track_id,
                lanes,
                lane_width,
                None,
                (int(colour[0]), int(colour[1]), int(colour[2])),
                cls,
            )
        )
    ids = [t.track_id for t in targets]
    for i, tid in enumerate(ids):
        if tid in ids[:i]:
            raise r.fail(f"target[{i}].id", f"track id {tid} is used twice")

    s_min, s_max = _road_extent(ego, targets, duration)
    road = r.build(
        "road",
        RoadSpec,
        r.number(road_t, "start_grade_pct", "road", 0.0, lambda x: abs(x) <= 40, "within ±40 %"),
        changes,
        curves,
        bumps,
        lane_width,
        lanes,
        r.number(road_t, "verge_m", "road", 6.0, lambda x: 1 <= x <= 30, "in [1, 30] m"),
        s_min,
        s_max,
    )

    n_t = r.table(data, "noise", "", NOISE_KEYS)
    noise = r.build(
        "noise",
        BoxNoiseSpec,
        r.number(n_t, "jitter_px", "noise", 1.0, _non_negative, "≥ 0"),
        r.number(n_t, "scale_sigma_pct", "noise", 2.0, lambda x: 0 <= x <= 50, "in [0, 50] %")
        / 100.0,
        r.number(n_t, "miss_rate", "noise", 0.03, lambda x: 0 <= x <= 1, "in [0, 1]"),
        r.boolean(n_t, "truncate", "noise", True),
        r.number(n_t, "min_visible", "noise", 0.3, lambda x: 0 <= x <= 1, "in [0, 1]"),
        r.number(n_t, "min_height_px", "noise", 12.0, _non_negative, "≥ 0"),
    )
    w_t = r.table(data, "world", "", WORLD_KEYS)
    dw = WorldSpec()
    world = r.build(
        "world",
        WorldSpec,
        r.numbers(w_t, "structure_height_m", "world", 2, dw.structure_height_m),
        r.numbers(w_t, "structure_segment_m", "world", 2, dw.structure_segment_m),
        r.number(w_t, "post_spacing_m", "world", dw.post_spacing_m),
        r.number(w_t, "object_spacing_m", "world", dw.object_spacing_m),
    )
    return r.build(
        "",
        Scenario,
        name,
        description,
        road,
        camera,
        ego,
        tuple(targets),
        noise,
        world,
        duration,
        rate,
        seed,
        path,
    )


def load_scenario_text(text: str, path: str, default_name: str = "scenario") -> Scenario:
    """Parse and validate the TOML ``text`` of a scenario (``path`` names it in messages)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        raise InputFileError(
            path, f"not valid TOML: {exc}", line=int(m.group(1)) if m else None
        ) from None
    return parse_scenario(data, path, text, default_name)


def _builtin_dir() -> Traversable:
    return resources.files(BUILTIN_PACKAGE).joinpath(BUILTIN_FOLDER)


def builtin_names() -> list[str]:
    """Names of the built-in scenarios (the suite first, then any others shipped)."""
    files = sorted(p.name[:-5] for p in _builtin_dir().iterdir() if p.name.endswith(".toml"))
    return [n for n in SUITE if n in files] + [n for n in files if n not in SUITE]


def builtin_text(name: str) -> str:
    """TOML text of the built-in scenario ``name``."""
    if name not in builtin_names():
        raise MissingInputError(
            f"no built-in scenario '{name}' (built-in: {', '.join(builtin_names())})"
        )
    return (_builtin_dir() / f"{name}.toml").read_text(encoding="utf-8")


def load_scenario(name_or_path: str | Path) -> Scenario:
    """A built-in scenario by name, or a scenario TOML file by path.

    Raises:
        MissingInputError: neither a file nor a built-in name.
        InputFileError: the file is not valid (message names file, line and field).
    """
    p = Path(name_or_path)
    if p.is_file():
        if p.stat().st_size > MAX_SCENARIO_BYTES:
            raise InputFileError(p, f"larger than {MAX_SCENARIO_BYTES} bytes: not a scenario")
        return load_scenario_text(read_text(p, "scenario file"), str(p), p.stem)
    name = str(name_or_path)
    if name in builtin_names():
        return load_scenario_text(builtin_text(name), f"builtin:{name}", name)
    if p.suffix.lower() == ".toml" or "/" in name or "\\" in name:
        raise MissingInputError(f"scenario file not found: {p}")
    raise MissingInputError(
        f"'{name}' is neither a scenario file nor a built-in scenario (built-in: "
        f"{', '.join(builtin_names())})"
    )


@dataclass(frozen=True)
class ScenarioInfo:
    """Name and one-line description of a scenario, for listings."""

    name: str
    description: str


def describe_builtins() -> list[ScenarioInfo]:
    """The built-in scenarios with their descriptions."""
    out = []
    for n in builtin_names():
        s = load_scenario(n)
        out.append(ScenarioInfo(n, s.description.strip().splitlines()[0] if s.description else ""))
    return out
