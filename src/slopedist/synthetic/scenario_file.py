"""The scenario file: its TOML layout, and parsing it into a checked
:class:`~slopedist.synthetic.scene.Scenario`.

A scenario is a small TOML file; copy a built-in one (``slopedist simulate --list`` names them,
they live in ``slopedist/synthetic/scenarios/``) and edit it. Every field is checked;
a mistake is reported as an :class:`~slopedist.core.errors.InputFileError` naming the file, the line
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
    length_m = 4.5                    # 1..30 m
    width_m = 1.8                     # 0.3..4 m
    height_m = 1.5                    # 0.5..5 m
    wheelbase_m = 2.7                 # 0.5..20 m, shorter than length_m

    [[target]]                        # zero or more (none: an empty road, no boxes)
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
from typing import Any, NamedTuple

import numpy as np

from slopedist.core.camera import (
    FOCAL_RANGE_PX,
    MAX_CAMERA_HEIGHT_M,
    focal_in_range,
    height_in_range,
)
from slopedist.core.errors import InputFileError
from slopedist.synthetic.noise import BoxNoiseSpec
from slopedist.synthetic.road import GradeChange, HorizontalCurve, RoadSpec, SpeedBump
from slopedist.synthetic.scenario_reader import (
    TableReader,
    field_lines,
    non_negative,
    positive,
)
from slopedist.synthetic.scene import CameraSpec, Scenario, WorldSpec
from slopedist.synthetic.vehicles import CameraRig, VehicleSpec

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

ROAD_MARGIN_BEHIND_M = 60.0
ROAD_MARGIN_AHEAD_M = 450.0

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


def _camera(r: TableReader, data: dict[str, Any]) -> CameraSpec:
    t = r.table(data, "camera", "", CAMERA_KEYS)
    d = CameraSpec()
    rig = r.build(
        "camera",
        CameraRig,
        height_m=r.number(
            t,
            "height_m",
            "camera",
            1.65,
            height_in_range,
            f"in (0, {MAX_CAMERA_HEIGHT_M:g}] m",
        ),
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
        r.number(
            t,
            "focal_px",
            "camera",
            d.f,
            focal_in_range,
            f"in {FOCAL_RANGE_PX[0]:g}..{FOCAL_RANGE_PX[1]:g} px",
        ),
        _principal_point(r, t, "cx_px", width / 2 if "image_width" in t else d.c_x, width),
        _principal_point(r, t, "cy_px", height / 2 if "image_height" in t else d.c_y, height),
        rig,
    )


def _principal_point(
    r: TableReader, t: dict[str, Any], key: str, default_px: float, size_px: int
) -> float:
    """The ``[camera]`` principal-point coordinate ``key`` (pixels), inside the image's
    ``size_px`` along its axis."""
    return r.number(
        t,
        key,
        "camera",
        default_px,
        lambda x: 0 <= x <= size_px,
        f"inside the image, 0..{size_px} px",
    )


def _header(r: TableReader, data: dict[str, Any], default_name: str) -> _Header:
    name = r.string(data, "name", "", default_name)
    if not re.fullmatch(r"[A-Za-z0-9_.\-]+", name):
        raise r.fail("name", f"must be letters, digits, '_', '-' or '.', got {name!r}")
    return _Header(
        name,
        r.string(data, "description", "", ""),
        r.number(data, "duration_s", "", 12.0, lambda x: 0 < x <= 600, "in (0, 600] s"),
        r.number(data, "frame_rate_hz", "", 10.0, lambda x: 1 <= x <= 100, "in [1, 100] Hz"),
        r.integer(data, "seed", "", 0, lambda x: 0 <= x < 2**32, "in 0 .. 2^32 − 1"),
    )


class _Header(NamedTuple):
    """The scenario's top-level fields."""

    name: str
    description: str
    duration_s: float
    frame_rate_hz: float
    seed: int


class _RoadFeatures(NamedTuple):
    """What the ``[road]`` table says before the road's extent is known."""

    lanes: int
    lane_width_m: float
    grade_changes: tuple[GradeChange, ...]
    curves: tuple[HorizontalCurve, ...]
    bumps: tuple[SpeedBump, ...]


def _grade_change(r: TableReader, g: dict[str, Any], where: str) -> GradeChange:
    return r.build(
        where,
        GradeChange,
        r.number(g, "at_m", where),
        r.number(g, "grade_pct", where, None, lambda x: abs(x) <= 40, "within ±40 %"),
        r.number(g, "length_m", where, 40.0, positive, "> 0 m"),
    )


def _curve(r: TableReader, c: dict[str, Any], where: str) -> HorizontalCurve:
    return r.build(
        where,
        HorizontalCurve,
        r.number(c, "start_m", where),
        r.number(c, "length_m", where, None, non_negative, "≥ 0 m"),
        r.number(
            c,
            "radius_m",
            where,
            None,
            lambda x: abs(x) >= 30,
            "at least 30 m in magnitude (positive turns left)",
        ),
        r.number(c, "transition_m", where, 20.0, non_negative, "≥ 0 m"),
    )


def _bump(r: TableReader, b: dict[str, Any], where: str) -> SpeedBump:
    return r.build(
        where,
        SpeedBump,
        r.number(b, "at_m", where),
        r.number(b, "height_m", where, 0.08, lambda x: 0 < x <= 0.3, "in (0, 0.3] m"),
        r.number(b, "length_m", where, 3.7, lambda x: x > 0.2, "> 0.2 m"),
    )


def _road_features(r: TableReader, road_t: dict[str, Any]) -> _RoadFeatures:
    lanes = r.integer(road_t, "lanes", "road", 2, lambda x: 1 <= x <= 6, "in 1..6")
    lane_width = r.number(road_t, "lane_width_m", "road", 3.5, lambda x: 2 <= x <= 6, "in [2, 6] m")
    changes = tuple(
        _grade_change(r, g, f"road.grade_change[{i}]")
        for i, g in enumerate(r.array_of_tables(road_t, "grade_change", "road", GRADE_KEYS))
    )
    curves = tuple(
        _curve(r, c, f"road.curve[{i}]")
        for i, c in enumerate(r.array_of_tables(road_t, "curve", "road", CURVE_KEYS))
    )
    bumps = tuple(
        _bump(r, b, f"road.bump[{i}]")
        for i, b in enumerate(r.array_of_tables(road_t, "bump", "road", BUMP_KEYS))
    )
    return _RoadFeatures(lanes, lane_width, changes, curves, bumps)


def _road(
    r: TableReader, road_t: dict[str, Any], features: _RoadFeatures, extent: tuple[float, float]
) -> RoadSpec:
    return r.build(
        "road",
        RoadSpec,
        r.number(road_t, "start_grade_pct", "road", 0.0, lambda x: abs(x) <= 40, "within ±40 %"),
        features.grade_changes,
        features.curves,
        features.bumps,
        features.lane_width_m,
        features.lanes,
        r.number(road_t, "verge_m", "road", 6.0, lambda x: 1 <= x <= 30, "in [1, 30] m"),
        *extent,
    )


class _VehicleIdentity(NamedTuple):
    """What a vehicle's table does not say: its track id, default start (None: required),
    colour (RGB 0..255) and class."""

    track_id: int
    default_start_m: float | None
    colour_rgb: tuple[int, int, int]
    cls: str


VEHICLE_DIMENSIONS_M = (
    ("length_m", 4.5),
    ("width_m", 1.8),
    ("height_m", 1.5),
    ("wheelbase_m", 2.7),
)
"""A vehicle's dimensions in a scenario file, in the order :class:`VehicleSpec` takes them,
with their defaults (metres)."""

VEHICLE_DIMENSION_RANGES_M = {
    "length_m": (1.0, 30.0),
    "width_m": (0.3, 4.0),
    "height_m": (0.5, 5.0),
    "wheelbase_m": (0.5, 20.0),
}
"""The dimensions a road vehicle has, metres (a bicycle to a road train): a dimension outside
them (``wheelbase_m = 1e-300``) is not a vehicle, and the world would lose it (its pitch on a
grade change divides by the wheelbase)."""


def _dimension(r: TableReader, t: dict[str, Any], where: str, name: str, default: float) -> float:
    low, high = VEHICLE_DIMENSION_RANGES_M[name]
    return r.number(
        t, name, where, default, lambda x: low <= x <= high, f"in [{low:g}, {high:g}] m"
    )


def _vehicle(
    r: TableReader,
    t: dict[str, Any],
    where: str,
    lanes: int,
    lane_width: float,
    identity: _VehicleIdentity,
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
    colour_rgb = identity.colour_rgb
    return r.build(
        where,
        VehicleSpec,
        identity.track_id,
        lateral,
        r.number(t, "start_m", where, identity.default_start_m),
        r.number(t, "speed_kmh", where, None, lambda x: 0 <= x <= 250, "in [0, 250] km/h") / 3.6,
        r.number(t, "accel_mps2", where, 0.0, lambda x: abs(x) <= 10, "within ±10 m/s²"),
        *(_dimension(r, t, where, name, default) for name, default in VEHICLE_DIMENSIONS_M),
        (colour_rgb[2] / 255.0, colour_rgb[1] / 255.0, colour_rgb[0] / 255.0),
        identity.cls,
    )


def _ego(r: TableReader, data: dict[str, Any], road: _RoadFeatures) -> VehicleSpec:
    if "ego" not in data:
        raise r.fail("ego", "required table [ego] is missing")
    ego_t = r.table(data, "ego", "", VEHICLE_KEYS)
    identity = _VehicleIdentity(-1, 0.0, (90, 90, 90), "Car")
    return _vehicle(r, ego_t, "ego", road.lanes, road.lane_width_m, identity)


def _target(r: TableReader, t: dict[str, Any], i: int, road: _RoadFeatures) -> VehicleSpec:
    where = f"target[{i}]"
    track_id = r.integer(t, "id", where, i + 1, lambda x: 0 <= x < 2**31, "≥ 0")
    colour = r.numbers(t, "colour_rgb", where, 3, TARGET_COLOURS_RGB[i % len(TARGET_COLOURS_RGB)])
    if not all(0 <= c <= 255 for c in colour):
        raise r.fail(f"{where}.colour_rgb", f"values must be in 0..255, got {colour}")
    cls = r.string(t, "class", where, "Car")
    rgb = (int(colour[0]), int(colour[1]), int(colour[2]))
    identity = _VehicleIdentity(track_id, None, rgb, cls)
    return _vehicle(r, t, where, road.lanes, road.lane_width_m, identity)


def _targets(r: TableReader, data: dict[str, Any], road: _RoadFeatures) -> list[VehicleSpec]:
    targets_t = r.array_of_tables(data, "target", "", TARGET_KEYS)
    targets = [_target(r, t, i, road) for i, t in enumerate(targets_t)]
    ids = [t.track_id for t in targets]
    for i, tid in enumerate(ids):
        if tid in ids[:i]:
            raise r.fail(f"target[{i}].id", f"track id {tid} is used twice")
    return targets


def _check_no_overlap(
    r: TableReader, ego: VehicleSpec, targets: list[VehicleSpec], head: _Header
) -> None:
    """Refuse a target whose box overlaps the ego's, or another target's, in plan (along the
    road and across it) at any frame: the camera would sit inside a car, or two cars would
    drive through each other."""
    t = np.arange(round(head.duration_s * head.frame_rate_hz)) / head.frame_rate_hz
    vehicles = [("the ego", ego), *((f"target[{i}]", v) for i, v in enumerate(targets))]
    s = [v.start_m + np.asarray(v.travelled_m(t), dtype=float) for _, v in vehicles]
    first: tuple[int, int, int] | None = None  # (frame, i, j) of the earliest overlap
    for j in range(1, len(vehicles)):
        b = vehicles[j][1]
        for i in range(j):
            a = vehicles[i][1]
            if abs(a.lateral_m - b.lateral_m) >= (a.width_m + b.width_m) / 2:
                continue
            hit = np.flatnonzero(np.abs(s[i] - s[j]) < (a.length_m + b.length_m) / 2)
            if hit.size and (first is None or int(hit[0]) < first[0]):
                first = (int(hit[0]), i, j)
    if first is not None:
        k, i, j = first
        a, b = vehicles[i][1], vehicles[j][1]
        raise r.fail(
            f"target[{j - 1}].start_m",
            f"this target overlaps {vehicles[i][0]} at t = {t[k]:g} s (centres "
            f"{abs(s[i][k] - s[j][k]):.1f} m apart along the road, "
            f"{abs(a.lateral_m - b.lateral_m):.1f} m across): "
            "place it further ahead or behind, or in another lane",
        )


def _road_extent(
    ego: VehicleSpec, targets: list[VehicleSpec], duration_s: float
) -> tuple[float, float]:
    starts = [ego.start_m, *(t.start_m for t in targets)]
    ends = [v.start_m + float(v.travelled_m(duration_s)) for v in (ego, *targets)]
    return min(starts) - ROAD_MARGIN_BEHIND_M, max(ends) + ROAD_MARGIN_AHEAD_M


def _noise(r: TableReader, data: dict[str, Any]) -> BoxNoiseSpec:
    n_t = r.table(data, "noise", "", NOISE_KEYS)
    return r.build(
        "noise",
        BoxNoiseSpec,
        r.number(n_t, "jitter_px", "noise", 1.0, non_negative, "≥ 0"),
        r.number(n_t, "scale_sigma_pct", "noise", 2.0, lambda x: 0 <= x <= 50, "in [0, 50] %")
        / 100.0,
        r.number(n_t, "miss_rate", "noise", 0.03, lambda x: 0 <= x <= 1, "in [0, 1]"),
        r.boolean(n_t, "truncate", "noise", True),
        r.number(n_t, "min_visible", "noise", 0.3, lambda x: 0 <= x <= 1, "in [0, 1]"),
        r.number(n_t, "min_height_px", "noise", 12.0, non_negative, "≥ 0"),
    )


def _world(r: TableReader, data: dict[str, Any]) -> WorldSpec:
    w_t = r.table(data, "world", "", WORLD_KEYS)
    dw = WorldSpec()
    return r.build(
        "world",
        WorldSpec,
        r.numbers(w_t, "structure_height_m", "world", 2, dw.structure_height_m),
        r.numbers(w_t, "structure_segment_m", "world", 2, dw.structure_segment_m),
        r.number(w_t, "post_spacing_m", "world", dw.post_spacing_m),
        r.number(w_t, "object_spacing_m", "world", dw.object_spacing_m),
    )


def parse_scenario(
    data: dict[str, Any], path: str, text: str = "", default_name: str = "scenario"
) -> Scenario:
    """Build a :class:`Scenario` from parsed TOML ``data`` (``path``/``text`` for messages)."""
    r = TableReader(path, field_lines(text))
    r.check_keys(data, "", TOP_KEYS)
    head = _header(r, data, default_name)
    camera = _camera(r, data)
    road_t = r.table(data, "road", "", ROAD_KEYS)
    features = _road_features(r, road_t)
    ego = _ego(r, data, features)
    targets = _targets(r, data, features)
    _check_no_overlap(r, ego, targets, head)
    road = _road(r, road_t, features, _road_extent(ego, targets, head.duration_s))
    noise = _noise(r, data)
    world = _world(r, data)
    return r.build(
        "",
        Scenario,
        head.name,
        head.description,
        road,
        camera,
        ego,
        tuple(targets),
        noise,
        world,
        head.duration_s,
        head.frame_rate_hz,
        head.seed,
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
    except (ValueError, RecursionError) as exc:  # e.g. an integer of 200,000 digits
        raise InputFileError(path, f"not valid TOML: {exc}") from None
    return parse_scenario(data, path, text, default_name)
