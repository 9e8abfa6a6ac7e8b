"""Vehicles driving on a :class:`~slopedist.synthetic.road.Road`, and the ego camera.

Convention:
    World frame as in :mod:`slopedist.synthetic.road` (X forward at ``s = 0``, Y left,
    Z up, metres). A vehicle's frame ``V`` has x forward, y left, z up; its origin is the
    *bottom centre* of its 3D box. The box rests on the road under its axles: the rear and front
    axle contact points are the road-surface points half a wheelbase behind and ahead of the
    vehicle's plan position ``s`` in its lane, the box's bottom face passes through both, and
    the vehicle is pitched with the chord between them (no roll). Camera frame ``C``: x right,
    y down, z forward. Rotations ``R_world_x`` map frame-x coordinates to world coordinates.

The camera sits ``height_m`` above the ego's bottom face (the road under it, on a level road),
``forward_m`` ahead of the box centre, pitched up by the mount angle θ0 (the sign of
:class:`slopedist.core.camera.Camera`: positive θ0 = optical axis pitched up, horizon below ``c_y``)
plus a seeded suspension pitch noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.core.errors import ConfigurationError
from slopedist.synthetic.road import Road

FloatArray = NDArray[np.float64]

WORLD_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class VehicleSpec:
    """A vehicle: where it starts, how it drives, and its size.

    Attributes:
        track_id: identity (also the box track id of targets; the ego's is unused).
        lateral_m: lateral offset of its path from the centreline, metres (positive left).
        start_m: plan distance ``s`` of the vehicle's centre at t = 0, metres.
        speed_mps: speed along the road at t = 0, m/s.
        accel_mps2: constant acceleration, m/s² (the vehicle stops rather than reverses).
        length_m, width_m, height_m: box size, metres.
        wheelbase_m: distance between the axles, metres (centred in the box).
        colour_bgr: body colour for the renderer, BGR in [0, 1].
        cls: class name written to box files.
    """

    track_id: int
    lateral_m: float
    start_m: float
    speed_mps: float
    accel_mps2: float = 0.0
    length_m: float = 4.5
    width_m: float = 1.8
    height_m: float = 1.5
    wheelbase_m: float = 2.7
    colour_bgr: tuple[float, float, float] = (0.16, 0.16, 0.67)
    cls: str = "Car"

    def __post_init__(self) -> None:
        for name in (
            "lateral_m",
            "start_m",
            "speed_mps",
            "accel_mps2",
            "length_m",
            "width_m",
            "height_m",
            "wheelbase_m",
        ):
            if not math.isfinite(getattr(self, name)):
                raise ConfigurationError(f"vehicle {self.track_id}: {name} must be finite")
        if self.speed_mps < 0:
            raise ConfigurationError(f"vehicle {self.track_id}: speed_mps must be ≥ 0")
        for name in ("length_m", "width_m", "height_m", "wheelbase_m"):
            if getattr(self, name) <= 0:
                raise ConfigurationError(f"vehicle {self.track_id}: {name} must be > 0")
        if self.wheelbase_m >= self.length_m:
            raise ConfigurationError(
                f"vehicle {self.track_id}: wheelbase_m ({self.wheelbase_m}) must be shorter "
                f"than length_m ({self.length_m})"
            )

    def travelled_m(self, t_s: ArrayLike) -> FloatArray:
        """Distance driven along the road after ``t_s`` seconds, metres."""
        t = np.asarray(t_s, dtype=float)
        v0, a = self.speed_mps, self.accel_mps2
        if a < 0:
            t = np.minimum(t, v0 / -a)
        return np.asarray(v0 * t + 0.5 * a * t**2, dtype=float)

    def plan_position(self, road: Road, t_s: ArrayLike) -> FloatArray:
        """Plan distance ``s`` of the vehicle's centre at times ``t_s``, metres."""
        return road.s_at_driven_distance(road.driven_distance(self.start_m) + self.travelled_m(t_s))


@dataclass(frozen=True)
class VehiclePoses:
    """Poses of one vehicle over frames.

    Attributes:
        s: ``(T,)`` plan distance of its centre, metres.
        origin_world: ``(T, 3)`` bottom centre of its box, world frame, metres.
        R_world_vehicle: ``(T, 3, 3)`` columns = forward, left, up axes in the world frame.
        pitch_rad: ``(T,)`` angle of the forward axis above the horizontal (nose up > 0).
        grade: ``(T,)`` road grade dz/ds under its centre (tangent).
    """

    s: FloatArray
    origin_world: FloatArray
    R_world_vehicle: FloatArray
    pitch_rad: FloatArray
    grade: FloatArray


def vehicle_poses(road: Road, s: ArrayLike, lateral_m: float, wheelbase_m: float) -> VehiclePoses:
    """Pose of a vehicle resting on the road with its centre at plan distances ``s``."""
    s = np.asarray(s, dtype=float)
    w = np.full(s.shape, lateral_m)
    rear = road.point(s - 0.5 * wheelbase_m, w)
    front = road.point(s + 0.5 * wheelbase_m, w)
    fwd = front - rear
    fwd /= np.linalg.norm(fwd, axis=-1, keepdims=True)
    left = np.cross(WORLD_UP, fwd)
    left /= np.linalg.norm(left, axis=-1, keepdims=True)
    up = np.cross(fwd, left)
    R = np.stack([fwd, left, up], axis=-1)
    pitch = np.arcsin(np.clip(fwd[..., 2], -1.0, 1.0))
    return VehiclePoses(s, 0.5 * (rear + front), R, pitch, road.grade_at(s))


BOX_CORNERS_UNIT = np.array(
    [[x, y, z] for z in (0.0, 1.0) for x in (-0.5, 0.5) for y in (-0.5, 0.5)]
)
"""Corners of a unit box in the vehicle frame, as fractions of (length, width, height);
bottom face first (z = 0), then top; within a face (rear-right, rear-left, front-right,
front-left)."""


def box_corners_world(
    poses: VehiclePoses, length_m: float, width_m: float, height_m: float
) -> FloatArray:
    """The 8 corners ``(T, 8, 3)`` of the vehicle's box in the world frame (order of
    :data:`BOX_CORNERS_UNIT`)."""
    local = BOX_CORNERS_UNIT * np.array([length_m, width_m, height_m])
    return poses.origin_world[:, None, :] + np.einsum("tij,kj->tki", poses.R_world_vehicle, local)


@dataclass(frozen=True)
class CameraRig:
    """How the camera is mounted on the ego vehicle.

    Attributes:
        height_m: height above the ego's bottom face (the road, on a level road), metres.
        forward_m: longitudinal offset from the ego's box centre, metres (forward > 0).
        mount_angle_rad: θ0, optical axis pitched up by this angle (radians).
        pitch_noise_rad: RMS of the suspension pitch noise, radians (0 = none).
        pitch_noise_band_hz: (low, high) frequency band of that noise, Hz.
    """

    height_m: float = 1.65
    forward_m: float = 0.0
    mount_angle_rad: float = 0.0
    pitch_noise_rad: float = 0.0
    pitch_noise_band_hz: tuple[float, float] = (0.5, 2.0)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.height_m) and self.height_m > 0):
            raise ConfigurationError(f"camera height_m must be > 0, got {self.height_m}")
        if not (math.isfinite(self.pitch_noise_rad) and self.pitch_noise_rad >= 0):
            raise ConfigurationError("camera pitch noise must be ≥ 0")
        lo, hi = self.pitch_noise_band_hz
        if not 0 < lo <= hi:
            raise ConfigurationError(
                f"pitch noise band must satisfy 0 < low ≤ high, got ({lo}, {hi})"
            )


def pitch_noise(
    t_s: ArrayLike, rms_rad: float, band_hz: tuple[float, float], seed: int, n_waves: int = 4
) -> FloatArray:
    """Smooth suspension pitch noise: a sum of ``n_waves`` sinusoids of random frequency in
    ``band_hz`` and random phase, scaled to RMS ``rms_rad`` (radians). Deterministic in ``seed``."""
    t = np.asarray(t_s, dtype=float)
    if rms_rad == 0:
        return np.zeros_like(t)
    rng = np.random.default_rng(seed)
    freqs = rng.uniform(band_hz[0], band_hz[1], n_waves)
    phases = rng.uniform(0.0, 2.0 * np.pi, n_waves)
    amp = rms_rad * math.sqrt(2.0 / n_waves)
    return np.asarray(
        amp * np.sin(2.0 * np.pi * freqs[None, :] * t[..., None] + phases).sum(axis=-1)
    )


def camera_poses(
    ego: VehiclePoses, rig: CameraRig, pitch_offset_rad: ArrayLike = 0.0
) -> tuple[FloatArray, FloatArray]:
    """Camera-to-world rotations ``(T, 3, 3)`` and camera centres ``(T, 3)`` (world frame).

    The camera is pitched up about the ego's left axis by θ0 + ``pitch_offset_rad``.
    """
    fwd = ego.R_world_vehicle[..., 0]
    left = ego.R_world_vehicle[..., 1]
    up = ego.R_world_vehicle[..., 2]
    a = rig.mount_angle_rad + np.asarray(pitch_offset_rad, dtype=float)
    ca, sa = np.cos(a)[..., None], np.sin(a)[..., None]
    z_cam = ca * fwd + sa * up
    y_cam = sa * fwd - ca * up
    x_cam = -left
    R = np.stack([x_cam, y_cam, z_cam], axis=-1)
    centre = ego.origin_world + rig.height_m * up + rig.forward_m * fwd
    return R, centre
