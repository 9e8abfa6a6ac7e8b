"""Simple synthetic traffic for ``ours``: 3D boxes moving on a flat road, projected exactly.

For the unit tests and the speed benchmark (the rendered hill scenarios of
:mod:`slopedist.synthetic` are the realistic counterpart). Vehicles are Cars whose
dimensions scatter around the class prior; the camera is at rest at height ``true_height_m``
with mount angle ``true_mount_rad``, so the horizon is the row ``c_y + f·tan θ0``.

Convention: camera x right, y down, z forward; metres, seconds, radians, pixels.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.estimators import CLASS_PRIORS, project_box
from slopedist.io.detections.boxes import BoxTable

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SimulatedTraffic:
    """Boxes and truth of a simulated sequence.

    Attributes:
        boxes: every visible box (class ``Car``; track ids = vehicle index, or −1 when
            ``with_ids`` was False).
        timestamps_s: ``(n_frames,)`` frame times.
        z_m: ``(N,)`` true centre distance of each box (KITTI's z).
        vehicle: ``(N,)`` index of the vehicle of each box.
        speed_mps: ``(N,)`` true relative speed Ż of each box.
        dims_hwl: ``(n_vehicles, 3)`` true dimensions.
        types: ``(n_vehicles,)`` true class of each vehicle (``Car``, ``Van``, ...).
    """

    boxes: BoxTable
    timestamps_s: FloatArray
    z_m: FloatArray
    vehicle: NDArray[np.int64]
    speed_mps: FloatArray
    dims_hwl: FloatArray
    types: NDArray[np.object_]


@dataclass(frozen=True)
class TrafficSettings:
    """How :func:`simulate_traffic` scatters its vehicles.

    Attributes:
        true_height_m, true_mount_rad: the true camera height (m) and mount angle (rad) the
            boxes are projected with (None: the camera's own), to test a wrong calibration.
        frame_period_s: time between frames, seconds.
        z_range_m: initial longitudinal distances, metres.
        speed_range_mps: relative speeds, m/s (negative: closing in).
        lateral_m: lateral offsets lie in ``±lateral_m``, metres.
        box_noise_px: white noise added to every box edge, pixels.
        with_ids: give the boxes their vehicle's track id (else −1).
        size_spread: vehicle sizes scatter by this many times the Car prior's spread.
        vehicle_types: class name → probability (classes of :data:`CLASS_PRIORS`): each
            vehicle's class is drawn and its dimensions scatter around that class's prior
            (None: every vehicle a Car).
        label_types: label the boxes with their true class; else every box is ``Car``, as a
            class-blind detector calls vans and trucks.
    """

    true_height_m: float | None = None
    true_mount_rad: float | None = None
    frame_period_s: float = 0.1
    z_range_m: tuple[float, float] = (8.0, 70.0)
    speed_range_mps: tuple[float, float] = (-10.0, 6.0)
    lateral_m: float = 10.0
    box_noise_px: float = 0.0
    with_ids: bool = True
    size_spread: float = 1.0
    vehicle_types: dict[str, float] | None = None
    label_types: bool = False


def simulate_traffic(
    camera: Camera,
    n_vehicles: int,
    n_frames: int,
    seed: int = 0,
    settings: TrafficSettings | None = None,
    **overrides: Any,
) -> SimulatedTraffic:
    """Vehicles driving along the camera's axis at constant relative speeds.

    Each vehicle keeps its lane (lateral offset) and heading (aligned, ±2°); it is visible
    while 4 m ≤ Z ≤ 90 m. Dimensions scatter around the Car prior by ``size_spread`` times the
    prior's spread (:class:`TrafficSettings`; ``overrides`` replace single settings, e.g.
    ``box_noise_px=0.5``).
    """
    cfg = dataclasses.replace(settings or TrafficSettings(), **overrides)
    rng = np.random.default_rng(seed)
    h = camera.height_m if cfg.true_height_m is None else cfg.true_height_m
    theta0 = camera.mount_angle_rad if cfg.true_mount_rad is None else cfg.true_mount_rad
    v = camera.c_y + camera.f * math.tan(theta0)
    p = CLASS_PRIORS["Car"]
    dims = np.stack(
        [
            p.height_m + cfg.size_spread * p.height_sigma_m * rng.standard_normal(n_vehicles),
            p.width_m + cfg.size_spread * p.width_sigma_m * rng.standard_normal(n_vehicles),
            p.length_m + cfg.size_spread * p.length_sigma_m * rng.standard_normal(n_vehicles),
        ],
        axis=1,
    )
    z0 = rng.uniform(*cfg.z_range_m, n_vehicles)
    speed = rng.uniform(*cfg.speed_range_mps, n_vehicles)
    lane = rng.uniform(-cfg.lateral_m, cfg.lateral_m, n_vehicles)
    yaw = np.radians(rng.uniform(-2.0, 2.0, n_vehicles))
    types = np.full(n_vehicles, "Car", dtype=object)
    if cfg.vehicle_types:
        types, dims = _draw_types(rng, cfg.vehicle_types, n_vehicles, cfg.size_spread)
    t = np.arange(n_frames) * cfg.frame_period_s
    frames, boxes, zs, veh, spd = [], [], [], [], []
    for k, tk in enumerate(t):
        z = z0 + speed * tk
        vis = (z >= 4.0) & (z <= 90.0)
        if not np.any(vis):
            continue
        b = project_box(camera.f, camera.c_x, v, h, lane[vis], z[vis], yaw[vis], dims[vis])
        if cfg.box_noise_px > 0:
            b = b + rng.normal(0.0, cfg.box_noise_px, b.shape)
        frames.append(np.full(int(vis.sum()), k))
        boxes.append(b)
        zs.append(z[vis])
        veh.append(np.flatnonzero(vis))
        spd.append(speed[vis])
    frame = np.concatenate(frames) if frames else np.zeros(0, np.int64)
    vehicle = np.concatenate(veh) if veh else np.zeros(0, np.int64)
    table = BoxTable.build(
        frame,
        np.concatenate(boxes) if boxes else np.zeros((0, 4)),
        vehicle if cfg.with_ids else np.full(len(vehicle), -1),
        classes=types[vehicle] if cfg.label_types else np.full(len(vehicle), "Car", dtype=object),
    )
    return SimulatedTraffic(
        table,
        np.asarray(t, dtype=float),
        np.concatenate(zs) if zs else np.zeros(0),
        vehicle,
        np.concatenate(spd) if spd else np.zeros(0),
        dims,
        types,
    )


def _draw_types(
    rng: np.random.Generator, probability: dict[str, float], n: int, size_spread: float
) -> tuple[NDArray[np.object_], FloatArray]:
    """Each vehicle's class (drawn by ``probability``) and dimensions ``(n, 3)`` (H, W, L, m)
    scattered around its class prior by ``size_spread`` times the prior's spread."""
    names = list(probability)
    p = np.array([probability[k] for k in names], dtype=float)
    types = np.array(names, dtype=object)[rng.choice(len(names), n, p=p / p.sum())]
    priors = [CLASS_PRIORS[str(t)] for t in types]
    mean = np.array([[q.height_m, q.width_m, q.length_m] for q in priors]).reshape(n, 3)
    sigma = np.array(
        [[q.height_sigma_m, q.width_sigma_m, q.length_sigma_m] for q in priors]
    ).reshape(n, 3)
    dims = mean + size_spread * sigma * rng.standard_normal((n, 3))
    return types, np.maximum(dims, 0.3 * mean)
