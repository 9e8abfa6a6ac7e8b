"""The estimator interface: one frame's boxes and ego gradient in, one estimate per box out.

Convention: boxes ``(left, top, right, bottom)`` pixels; θ (ego road gradient) in radians;
distances in metres along the camera's z axis (longitudinal, as KITTI's label z).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from slopedist.camera import Camera
from slopedist.detections.boxes import BoxTable, box_problems


class MissingReason(str, Enum):
    """Why a distance could not be estimated."""

    BELOW_HORIZON = "below_horizon"
    """The box bottom is at or above the vanishing line (u ≤ v): eq. 1 is undefined."""
    NO_ROTATION = "no_rotation"
    """No camera rotation for this frame (odometry not initialised or lost)."""
    NON_FINITE_BOX = "non_finite_box"
    INVERTED_BOX = "inverted_box"
    NO_DEPTH = "no_depth"
    """A depth map had no valid value at the sampled pixels."""
    NO_SCALE = "no_scale"
    """Median scaling of a scale-less depth map had no reference yet (first frames)."""


class ReferencePoint(str, Enum):
    """Which point of the target a distance refers to."""

    CONTACT = "contact"
    """The ground-contact point under the box bottom (eq. 1)."""
    CENTRE = "centre"
    """The vehicle's centre, as KITTI labels define z."""
    NEAREST_FACE = "nearest_face"
    """The nearest face of the vehicle (its rear, for a car ahead)."""
    BOX_CENTRE_PIXEL = "box_centre_pixel"
    """Depth at the pixel of the box centre (depth-map baselines)."""


@dataclass(frozen=True)
class FrameInput:
    """Everything an estimator sees of one frame.

    Attributes:
        frame_index: 0-based frame number.
        timestamp_s: seconds.
        theta_rad: ego road gradient θ of eq. 4, radians; NaN when no rotation is available.
        boxes: this frame's boxes (a :class:`BoxTable` with one frame).
        image: the frame's pixels when the caller has them (``H×W`` or ``H×W×3`` uint8).
        depth_m: a dense depth map in metres for this frame, when a depth source provides one.
        R_world_cam: the frame's camera-to-world rotation ``(3, 3)`` when known (estimators
            that track targets use it to compensate the camera's own rotation between frames).
    """

    frame_index: int
    timestamp_s: float
    theta_rad: float
    boxes: BoxTable
    image: NDArray[np.uint8] | None = None
    depth_m: NDArray[np.float32] | None = None
    R_world_cam: NDArray[np.float64] | None = None


@dataclass
class FrameEstimates:
    """Per-box results of one frame, as parallel arrays of length N.

    Attributes:
        theta_rad: ego road gradient used, radians.
        theta_adj_rad: per-target gradient after any adjustment (eq. 7 for ``paper``), radians.
        delta_y_px: Δy of eq. 6, pixels (NaN where not computed).
        v_px: vanishing-line row used for each target, pixels.
        distance_m: estimated distance, metres; NaN where missing.
        reason: ``""`` or a :class:`MissingReason` value per box.
        reference: the :class:`ReferencePoint` value the distance refers to, per box.
        extra: method-specific columns (e.g. ``sigma_m``, ``speed_mps``, ``ttc_s``).
    """

    theta_rad: NDArray[np.float64]
    theta_adj_rad: NDArray[np.float64]
    delta_y_px: NDArray[np.float64]
    v_px: NDArray[np.float64]
    distance_m: NDArray[np.float64]
    reason: NDArray[np.object_]
    reference: NDArray[np.object_]
    extra: dict[str, NDArray[np.float64]] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.distance_m.shape[0])

    @classmethod
    def empty(cls) -> FrameEstimates:
        """The estimates of a frame without boxes."""
        e = np.zeros(0)
        o = np.zeros(0, dtype=object)
        return cls(e, e.copy(), e.copy(), e.copy(), e.copy(), o, o.copy())


class Estimator:
    """Base class of distance estimators.

    Subclasses implement :meth:`estimate`; stateful ones (tracking) also :meth:`reset`.
    ``needs_rotation`` tells the pipeline whether a frame without a rotation can still be
    estimated; ``needs_depth`` whether a depth map must come with each frame;
    ``rotation_source`` which rotation source the method is defined on, if any.
    """

    name: ClassVar[str] = ""
    needs_rotation: ClassVar[bool] = True
    needs_depth: ClassVar[bool] = False
    rotation_source: ClassVar[str | None] = None
    """Rotation source this method must be fed (e.g. ``"oxts"`` for the IMU baseline), or None
    for whichever source the caller uses; evaluations honour it per method."""

    def __init__(self, camera: Camera) -> None:
        self.camera = camera

    def reset(self) -> None:
        """Forget any state carried between frames (new sequence)."""

    def estimate(self, frame: FrameInput) -> FrameEstimates:
        """Estimate a distance for every box of ``frame``."""
        raise NotImplementedError


def unusable_box_reasons(frame: FrameInput, needs_rotation: bool) -> NDArray[np.object_]:
    """Per-box reason that rules out an estimate before any method runs (bad box, no rotation)."""
    reasons = box_problems(frame.boxes.boxes)
    if needs_rotation and not np.isfinite(frame.theta_rad):
        reasons[reasons == ""] = MissingReason.NO_ROTATION.value
    return reasons
