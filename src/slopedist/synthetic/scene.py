"""A synthetic driving scene: the scenario's definition and its exact per-frame ground truth.

Convention:
    World frame of :mod:`~slopedist.synthetic.road` (X forward at ``s = 0``, Y left,
    Z up). Camera frame x right, y down, z forward; ``R_world_cam`` camera-to-world. Poses written
    for users are relative to the first camera frame (KITTI ``poses.txt`` convention). Boxes
    ``(left, top, right, bottom)`` in pixels, pixel ``(row i, column j)`` centred on image
    coordinates ``(y = i, x = j)``. Angles in radians, distances in metres, times in seconds.

Ground truth per frame and target (:class:`SceneTruth`):

- ``z_m``: camera z of the bottom centre of the target's 3D box, i.e. KITTI's label ``z``
  (the longitudinal distance every table scores against); ``x_m``, ``y_m`` the other two
  coordinates of that point (KITTI's label location);
- ``z_centre_m``: camera z of the 3D box centre (equals ``z_m`` for a box level with the camera,
  differs by ``height/2 · sin(relative pitch)`` otherwise);
- ``z_rear_m``: camera z of the middle of the rear face's bottom edge, the ground-contact point
  eq. 1 actually measures (``≈ z_m − length/2``);
- ``distance_m``: Euclidean distance from the camera centre to the bottom centre;
- ``box``: the exact 2D box, the projection of the 8 corners clipped to the image, and
  ``box_unclipped``; ``truncation`` = share of the unclipped box's area outside the image;
- ego and target road grades (dz/ds under their centres) and vehicle pitches.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.synthetic.noise import BoxNoiseSpec
from slopedist.synthetic.road import Road, RoadSpec
from slopedist.synthetic.vehicles import (
    CameraRig,
    VehicleSpec,
    box_corners_world,
    camera_poses,
    pitch_noise,
    vehicle_poses,
)

FloatArray = NDArray[np.float64]

NEAR_PLANE_M = 0.5
"""A target with a corner closer than this to the camera plane is not in view, metres."""

KITTI_IMAGE_SIZE = (1242, 375)
KITTI_P2_F = 721.5377
KITTI_P2_CX = 609.5593
KITTI_P2_CY = 172.854


@dataclass(frozen=True)
class CameraSpec:
    """Intrinsics (pixels) and mount of the synthetic camera (defaults: KITTI's camera 2)."""

    image_width: int = KITTI_IMAGE_SIZE[0]
    image_height: int = KITTI_IMAGE_SIZE[1]
    f: float = KITTI_P2_F
    c_x: float = KITTI_P2_CX
    c_y: float = KITTI_P2_CY
    rig: CameraRig = field(default_factory=CameraRig)

    def __post_init__(self) -> None:
        if not (64 <= self.image_width <= 4096 and 48 <= self.image_height <= 4096):
            raise ConfigurationError(
                f"image size must be within 64×48 .. 4096×4096, got "
                f"{self.image_width}×{self.image_height}"
            )
        if not (math.isfinite(self.f) and self.f > 0):
            raise ConfigurationError(f"focal length must be > 0 pixels, got {self.f}")
        self.camera()  # the estimators' checks (focal range, principal point, height) now

    def camera(self) -> Camera:
        """The :class:`~slopedist.core.camera.Camera` an estimator should be given."""
        return Camera(
            self.f,
            self.c_x,
            self.c_y,
            self.rig.height_m,
            self.rig.mount_angle_rad,
            self.image_width,
            self.image_height,
        )

    @property
    def K(self) -> FloatArray:
        """3×3 intrinsic matrix."""
        return np.array([[self.f, 0.0, self.c_x], [0.0, self.f, self.c_y], [0.0, 0.0, 1.0]])


MAX_STRUCTURE_HEIGHT_M = 25.0
MAX_STRUCTURE_SEGMENT_M = 40.0
"""Bounds of the roadside structures (their texture frames stay inside the renderer's tiles)."""


@dataclass(frozen=True)
class WorldSpec:
    """Roadside content of the renderer's world (seeded by the scenario's seed).

    Attributes:
        structure_height_m: (min, max) height of the roadside structure segments, metres.
        structure_segment_m: (min, max) length of those segments along the road, metres.
        post_spacing_m: spacing of the delineator posts on both edges, metres.
        object_spacing_m: mean spacing of roadside objects (bushes, cabinets, signs), metres.
    """

    structure_height_m: tuple[float, float] = (3.0, 14.0)
    structure_segment_m: tuple[float, float] = (6.0, 16.0)
    post_spacing_m: float = 20.0
    object_spacing_m: float = 8.0

    def __post_init__(self) -> None:
        for name in ("structure_height_m", "structure_segment_m"):
            lo, hi = getattr(self, name)
            if not 0 < lo <= hi:
                raise ConfigurationError(f"world {name} must satisfy 0 < min ≤ max")
        # the renderer's wall textures cover heights up to about 40 m above a segment's start
        if self.structure_height_m[1] > MAX_STRUCTURE_HEIGHT_M:
            raise ConfigurationError(
                f"world structure_height_m must be at most {MAX_STRUCTURE_HEIGHT_M:g} m"
            )
        if self.structure_segment_m[1] > MAX_STRUCTURE_SEGMENT_M:
            raise ConfigurationError(
                f"world structure_segment_m must be at most {MAX_STRUCTURE_SEGMENT_M:g} m"
            )
        if self.post_spacing_m < 2 or self.object_spacing_m < 2:
            raise ConfigurationError("world post_spacing_m and object_spacing_m must be ≥ 2 m")


@dataclass(frozen=True)
class Scenario:
    """A complete synthetic driving scenario (see :mod:`slopedist.synthetic.scenarios`
    for the TOML layout).

    Attributes:
        name: short name (file name of the built-in TOML).
        description: what the scenario shows.
        road: the road.
        camera: camera intrinsics and mount.
        ego: the ego vehicle (carries the camera).
        targets: the other vehicles (their boxes are the detections).
        noise: detector noise applied to the exact boxes.
        world: roadside content.
        duration_s: length, seconds; frame_rate_hz: frames per second.
        seed: seed of everything random (world, pitch noise, box noise, image noise).
        source: where the scenario came from (file path or ``builtin:<name>``), for messages.
    """

    name: str
    description: str
    road: RoadSpec
    camera: CameraSpec
    ego: VehicleSpec
    targets: tuple[VehicleSpec, ...]
    noise: BoxNoiseSpec = field(default_factory=BoxNoiseSpec)
    world: WorldSpec = field(default_factory=WorldSpec)
    duration_s: float = 12.0
    frame_rate_hz: float = 10.0
    seed: int = 0
    source: str = ""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.duration_s) and 0 < self.duration_s <= 600):
            raise ConfigurationError(f"duration_s must be in (0, 600] s, got {self.duration_s}")
        if not (math.isfinite(self.frame_rate_hz) and 1 <= self.frame_rate_hz <= 100):
            raise ConfigurationError(
                f"frame_rate_hz must be in [1, 100] Hz, got {self.frame_rate_hz}"
            )
        ids = [t.track_id for t in self.targets]
        if len(set(ids)) != len(ids):
            raise ConfigurationError(f"target track ids must be unique, got {ids}")

    @property
    def n_frames(self) -> int:
        """Number of frames (``duration × rate``, rounded)."""
        return round(self.duration_s * self.frame_rate_hz)

    @property
    def timestamps_s(self) -> FloatArray:
        """Frame timestamps, seconds (frame k at ``k / rate``)."""
        return np.arange(self.n_frames) / self.frame_rate_hz

    def build_road(self) -> Road:
        """The tabulated road."""
        return Road(self.road)


@dataclass(frozen=True)
class SceneTruth:
    """Exact ground truth of every frame (T frames, M targets); see the module docstring.

    Attributes:
        timestamps_s: ``(T,)``.
        R_world_cam: ``(T, 3, 3)`` camera-to-world rotations (world frame of the road).
        centre_world: ``(T, 3)`` camera centres, world frame, metres.
        ego_s, ego_grade, ego_pitch_rad, camera_pitch_rad: ``(T,)`` ego plan position (m),
            road grade under the ego (tangent), ego body pitch and camera pitch above the
            horizontal (radians, nose up > 0).
        track_ids: ``(M,)`` target track ids.
        target_s, target_grade, target_pitch_rad: ``(T, M)``.
        corners_world: ``(T, M, 8, 3)`` box corners, world frame.
        corners_cam: ``(T, M, 8, 3)`` box corners, camera frame.
        x_m, y_m, z_m, z_centre_m, z_rear_m, distance_m: ``(T, M)`` metres.
        box_unclipped, box: ``(T, M, 4)`` pixels; truncation ``(T, M)`` in [0, 1].
        in_view: ``(T, M)`` bool: every corner ahead of the near plane and the box in the image.
    """

    timestamps_s: FloatArray
    R_world_cam: FloatArray
    centre_world: FloatArray
    ego_s: FloatArray
    ego_grade: FloatArray
    ego_pitch_rad: FloatArray
    camera_pitch_rad: FloatArray
    track_ids: NDArray[np.int64]
    target_s: FloatArray
    target_grade: FloatArray
    target_pitch_rad: FloatArray
    corners_world: FloatArray
    corners_cam: FloatArray
    x_m: FloatArray
    y_m: FloatArray
    z_m: FloatArray
    z_centre_m: FloatArray
    z_rear_m: FloatArray
    distance_m: FloatArray
    box_unclipped: FloatArray
    box: FloatArray
    truncation: FloatArray
    in_view: NDArray[np.bool_]

    @property
    def n_frames(self) -> int:
        return int(self.timestamps_s.shape[0])

    def poses_cam0(self) -> FloatArray:
        """Camera-to-world poses ``(T, 3, 4)`` relative to the first camera frame (KITTI
        ``poses.txt``): ``T_c0_ck = T_w_c0⁻¹ · T_w_ck``."""
        R0 = self.R_world_cam[0]
        R = np.einsum("ji,tjk->tik", R0, self.R_world_cam)
        t = np.einsum("ji,tj->ti", R0, self.centre_world - self.centre_world[0])
        return np.concatenate([R, t[:, :, None]], axis=2)


def _project(points_cam: FloatArray, K: FloatArray) -> FloatArray:
    """Pixel coordinates ``(..., 2)`` of camera-frame points ``(..., 3)`` (z > 0)."""
    z = points_cam[..., 2:3]
    return (points_cam[..., :2] * np.array([K[0, 0], K[1, 1]])) / z + np.array([K[0, 2], K[1, 2]])


def simulate_truth(scenario: Scenario, road: Road | None = None) -> SceneTruth:
    """Drive the scenario and compute the exact ground truth of every frame."""
    road = road or scenario.build_road()
    t = scenario.timestamps_s
    ego = vehicle_poses(
        road, scenario.ego.plan_position(road, t), scenario.ego.lateral_m, scenario.ego.wheelbase_m
    )
    rig = scenario.camera.rig
    noise = pitch_noise(t, rig.pitch_noise_rad, rig.pitch_noise_band_hz, scenario.seed + 7)
    R_wc, C_w = camera_poses(ego, rig, noise)
    K = scenario.camera.K
    W, H = scenario.camera.image_width, scenario.camera.image_height
    M = len(scenario.targets)
    T = len(t)
    shape = (T, M)
    s_t, grade_t, pitch_t = (np.zeros(shape) for _ in range(3))
    corners_w = np.zeros((T, M, 8, 3))
    for m, spec in enumerate(scenario.targets):
        poses = vehicle_poses(road, spec.plan_position(road, t), spec.lateral_m, spec.wheelbase_m)
        s_t[:, m], grade_t[:, m], pitch_t[:, m] = poses.s, poses.grade, poses.pitch_rad
        corners_w[:, m] = box_corners_world(poses, spec.length_m, spec.width_m, spec.height_m)
    # world → camera for every frame: X_c = R_wcᵀ (X_w − C)
    corners_c = np.einsum("tji,tmkj->tmki", R_wc, corners_w - C_w[:, None, None, :])
    bottom_c = corners_c[:, :, :4].mean(axis=2)
    centre_c = corners_c.mean(axis=2)
    rear_c = corners_c[:, :, :2].mean(axis=2)  # bottom face, rear edge
    ahead = np.all(corners_c[..., 2] > NEAR_PLANE_M, axis=2)
    safe = np.where(ahead[..., None, None], corners_c, np.array([0.0, 0.0, 1.0]))
    px = _project(safe, K)
    unclipped = np.concatenate([px.min(axis=2), px.max(axis=2)], axis=-1)
    unclipped = np.where(ahead[..., None], unclipped, np.nan)
    lo = np.array([0.0, 0.0, 0.0, 0.0])
    hi = np.array([W - 1.0, H - 1.0, W - 1.0, H - 1.0])
    clipped = np.clip(unclipped, lo, hi)
    area_u = (unclipped[..., 2] - unclipped[..., 0]) * (unclipped[..., 3] - unclipped[..., 1])
    area_c = np.clip(clipped[..., 2] - clipped[..., 0], 0, None) * np.clip(
        clipped[..., 3] - clipped[..., 1], 0, None
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        truncation = np.where(ahead, 1.0 - area_c / area_u, np.nan)
    in_view = ahead & (area_c > 1.0)
    ego_pitch = ego.pitch_rad
    cam_fwd = R_wc[:, :, 2]
    return SceneTruth(
        timestamps_s=t,
        R_world_cam=R_wc,
        centre_world=C_w,
        ego_s=ego.s,
        ego_grade=ego.grade,
        ego_pitch_rad=ego_pitch,
        camera_pitch_rad=np.arcsin(np.clip(cam_fwd[:, 2], -1, 1)),
        track_ids=np.array([s.track_id for s in scenario.targets], dtype=np.int64),
        target_s=s_t,
        target_grade=grade_t,
        target_pitch_rad=pitch_t,
        corners_world=corners_w,
        corners_cam=corners_c,
        x_m=bottom_c[..., 0],
        y_m=bottom_c[..., 1],
        z_m=bottom_c[..., 2],
        z_centre_m=centre_c[..., 2],
        z_rear_m=rear_c[..., 2],
        distance_m=np.linalg.norm(bottom_c, axis=-1),
        box_unclipped=unclipped,
        box=np.where(in_view[..., None], clipped, np.nan),
        truncation=truncation,
        in_view=in_view,
    )
