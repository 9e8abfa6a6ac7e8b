"""The estimator interface: one frame's boxes and ego gradient in, one estimate per box out.

Convention: boxes ``(left, top, right, bottom)`` pixels; θ (ego road gradient) in radians;
distances in metres along the camera's z axis (longitudinal, as KITTI's label z).

Per-item states: every box gets an :class:`EstimateStatus`. ``ok`` is a promise (a trustworthy
distance); ``upper_bound`` keeps a distance the true one does not exceed (a box cut by the
bottom of the image, for the ground-contact methods: the true contact row is lower); ``missing``
has no distance. Both non-``ok`` states carry a reason (:class:`MissingReason`). The states that
depend on the box alone (outside the image, degenerate, not a vehicle, the ``cut`` flag) are
settled for every method by :func:`settle_states`, after the method ran.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from enum import Enum
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.core.suggest import did_you_mean
from slopedist.io.detections.boxes import (
    DEFAULT_VEHICLE_CLASSES,
    BoxTable,
    border_cuts,
    cut_labels,
    frame_pixel_boxes,
    table_box_problems,
    vehicle_mask,
)
from slopedist.io.frames import implied_image_sizes


class EstimateStatus(str, Enum):
    """What a method can say about one box (the ``status`` column of the records)."""

    OK = "ok"
    """A distance to trust."""
    UPPER_BOUND = "upper_bound"
    """The true distance is at most the one given (reason says why); not scored as ``ok``."""
    MISSING = "missing"
    """No distance (reason says why)."""


ROW_ERROR_PX = 1.0
"""The error, in image rows, against which a distance's resolution is judged: a detector places
a box's edges, and the odometry the vanishing line, to about a pixel (half a pixel of
quantisation each side, plus localisation)."""

MAX_ROW_SHARE = 0.5
"""The largest share of a distance that a :data:`ROW_ERROR_PX` error may change for the distance
to be ``ok`` — the same half as ``ours``' ``max_relative_sigma``."""

MIN_RESOLVED_PX = ROW_ERROR_PX / MAX_ROW_SHARE
"""The least image extent (pixels) that resolves a distance: 2 px. Every monocular distance from
a box is ``f·L/n`` for some length ``L`` and some ``n`` pixels (eq. 1: the camera height and the
gap ``u − v`` between the box bottom and the vanishing line; a size cue: a vehicle's height and
the box height), so a row of error changes it by ``d/n``, more than :data:`MAX_ROW_SHARE` of
it when ``n`` < 2 px. With KITTI's camera (f·h ≈ 1190 px·m) a 2 px gap is about 600 m, far
beyond any detector's range and the evaluation's 80 m cap (its label boxes are ≥ ~10 px tall);
:func:`unresolved_distances` applies it to every method."""


class MissingReason(str, Enum):
    """Why a distance is missing, or (``cut_bottom``) only a bound."""

    BELOW_HORIZON = "below_horizon"
    """The box bottom is at or above the vanishing line (u ≤ v): eq. 1 is undefined."""
    NEAR_HORIZON = "near_horizon"
    """The box bottom is less than :data:`MIN_RESOLVED_PX` below the vanishing line: eq. 1
    gives a distance far beyond what the row can tell (a pixel of the row moves it by more
    than half); evaluations count it at the cap, as ``below_horizon``."""
    NO_ROTATION = "no_rotation"
    """No camera rotation for this frame (odometry not initialised or lost), or one whose ego
    gradient no road gives (:data:`slopedist.streaming.step.MAX_EGO_GRADIENT_RAD`: a glitch)."""
    ODOMETRY_JUMP = "odometry_jump"
    """The frame's camera rotation jumps away from the frames before it faster than a car can
    pitch (:class:`slopedist.odometry.jumps.PitchJumpGuard`: a visual-odometry or pose-file
    glitch); its θ is not trusted, as a frame without a rotation (``no_rotation``)."""
    NON_FINITE_BOX = "non_finite_box"
    INVERTED_BOX = "inverted_box"
    NO_DEPTH = "no_depth"
    """A depth map had no valid value at the sampled pixels."""
    NO_SCALE = "no_scale"
    """Median scaling of a scale-less depth map had no reference yet (first frames)."""
    BEYOND_RESOLUTION = "beyond_resolution"
    """The image does not resolve the distance (:func:`unresolved_distances`, every method): the
    box is less than :data:`MIN_RESOLVED_PX` tall, or the distance is so far that a vehicle's
    ground contact there lies less than :data:`MIN_RESOLVED_PX` below the vanishing line
    (beyond ``f·h/2``, about 600 m for KITTI's camera) — a row of error would move it by more
    than half. Far by either token: evaluations count it at the cap, as ``below_horizon``."""
    DEGENERATE_BOX = "degenerate_box"
    """Zero or sub-pixel width or height, or absurd coordinates."""
    OUTSIDE_IMAGE = "outside_image"
    """The box does not overlap the image."""
    NOT_A_VEHICLE = "not_a_vehicle"
    """The class is not one of the vehicle classes (e.g. ``Pedestrian``, ``DontCare``)."""
    INVALID_DISTANCE = "invalid_distance"
    """The method gave no finite positive distance for a box it did not rule out."""
    CUT_BOTTOM = "cut_bottom"
    """The box is cut by the bottom of the image: a ground-contact distance is an upper bound
    (status ``upper_bound``)."""
    TOO_UNCERTAIN = "too_uncertain"
    """The method's own 1σ (``sigma_m``) is more than a set share of the distance (``ours``:
    option ``max_relative_sigma``): a number no one could act on (a box of a few pixels, cues
    that contradict each other); the cue columns keep what the box says."""


DISTANCE_COLUMNS = ("distance_centre_m", "distance_nearest_face_m")
"""Extra columns that restate a row's distance at another point of the vehicle (``ours``):
withheld (NaN) wherever ``distance_m`` is (a ``missing`` row), so that a consumer who selects
one of them reads no distance the method withheld; an ``upper_bound`` row's are bounds too."""

MOTION_COLUMNS = ("speed_mps", "speed_sigma_mps", "ttc_s", "ttc_sigma_s")
"""Extra columns of a row's relative speed and time to collision with their 1σ: empty in every
row that is not ``ok`` (a speed or a time to collision of a withheld distance or of a bound is
none to act on)."""

UNCERTAINTY_COLUMN = "sigma_m"
"""The extra column of a method's own 1σ (metres): kept in a ``missing`` row only when it is
the reason (``too_uncertain``), NaN in the other ``missing`` rows."""


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


VEHICLE_REFERENCES = (ReferencePoint.CENTRE, ReferencePoint.NEAREST_FACE, ReferencePoint.CONTACT)
"""The points of a vehicle a distance can be asked for (``--reference`` of ``ours``) or a
ground truth can declare (``--gt-reference``)."""


def parse_reference(text: str) -> ReferencePoint:
    """One of :data:`VEHICLE_REFERENCES` by its value (``centre``, ``nearest_face``,
    ``contact``; surrounding spaces ignored).

    Raises:
        ConfigurationError: any other text (the message lists the choices).
    """
    choices = {r.value: r for r in VEHICLE_REFERENCES}
    value = text.strip()
    if value not in choices:
        raise ConfigurationError(
            f"'{value}' is not a reference point{did_you_mean(value, choices)} (choose from "
            f"{', '.join(choices)})"
        )
    return choices[value]


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
        status: the :class:`EstimateStatus` value per box; when a method leaves it out it is
            ``ok`` where ``reason`` is empty and ``missing`` elsewhere.
        cut: the image edges that cut each box (``""``, ``"bottom"``, ``"left+bottom"``, ...;
            :func:`slopedist.io.detections.boxes.cut_labels`), set by :func:`settle_states`.
    """

    theta_rad: NDArray[np.float64]
    theta_adj_rad: NDArray[np.float64]
    delta_y_px: NDArray[np.float64]
    v_px: NDArray[np.float64]
    distance_m: NDArray[np.float64]
    reason: NDArray[np.object_]
    reference: NDArray[np.object_]
    extra: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    status: NDArray[np.object_] = field(default_factory=lambda: np.zeros(0, dtype=object))
    cut: NDArray[np.object_] = field(default_factory=lambda: np.zeros(0, dtype=object))

    def __post_init__(self) -> None:
        n = len(self)
        if len(self.status) != n:
            self.status = np.where(
                self.reason == "", EstimateStatus.OK.value, EstimateStatus.MISSING.value
            ).astype(object)
        if len(self.cut) != n:
            self.cut = np.full(n, "", dtype=object)

    def set_state(
        self, rows: NDArray[np.bool_], status: EstimateStatus, reason: MissingReason
    ) -> None:
        """Give ``rows`` a status and reason; a ``missing`` row loses its distance."""
        self.status[rows] = status.value
        self.reason[rows] = reason.value
        if status is EstimateStatus.MISSING:
            self.distance_m[rows] = np.nan

    def withhold_distances(self) -> None:
        """Empty the :data:`DISTANCE_COLUMNS` of every ``missing`` row (as its ``distance_m``)
        and its :data:`UNCERTAINTY_COLUMN` unless the reason is ``too_uncertain`` (then the σ
        says why), and the :data:`MOTION_COLUMNS` of every row that is not ``ok``. The changed
        columns are copies: arrays the method keeps stay its own."""
        missing = self.status == EstimateStatus.MISSING.value
        not_ok = self.status != EstimateStatus.OK.value
        if not not_ok.any():
            return
        self.distance_m[missing] = np.nan
        extra = dict(self.extra)
        for names, rows in ((DISTANCE_COLUMNS, missing), (MOTION_COLUMNS, not_ok)):
            for name in names:
                if name in extra:
                    extra[name] = np.array(extra[name], dtype=float)
                    extra[name][rows] = np.nan
        if UNCERTAINTY_COLUMN in extra:
            sigma = np.array(extra[UNCERTAINTY_COLUMN], dtype=float)
            sigma[missing & (self.reason != MissingReason.TOO_UNCERTAIN.value)] = np.nan
            extra[UNCERTAINTY_COLUMN] = sigma
        self.extra = extra

    def withhold_uncertain(self, max_relative_sigma: float) -> None:
        """``ok`` rows whose 1σ ``extra["sigma_m"]`` (same point, metres) exceeds
        ``max_relative_sigma`` × their distance become ``missing``, reason ``too_uncertain``
        (a NaN σ is left alone: the method states no σ for that row)."""
        sigma = self.extra.get("sigma_m")
        if sigma is None or not len(self):
            return
        with np.errstate(invalid="ignore"):
            vague = (self.status == EstimateStatus.OK.value) & (
                sigma > max_relative_sigma * np.abs(self.distance_m)
            )
        if vague.any():
            self.set_state(vague, EstimateStatus.MISSING, MissingReason.TOO_UNCERTAIN)

    def __len__(self) -> int:
        return int(self.distance_m.shape[0])

    @classmethod
    def empty(cls) -> FrameEstimates:
        """The estimates of a frame without boxes."""
        e = np.zeros(0)
        o = np.zeros(0, dtype=object)
        return cls(e, e.copy(), e.copy(), e.copy(), e.copy(), o, o.copy())


@dataclass(frozen=True)
class SelfCalibration:
    """What a self-calibrating method (``ours-selfcal``) has estimated of the camera's mount.

    Attributes:
        mount_angle_rad: estimated θ0 (radians, the camera's convention).
        mount_angle_sigma_rad: its 1σ.
        height_m: estimated camera height (m).
        height_sigma_m: its 1σ.
        horizon_offset_rad: δ, the correction added to the ego gradient θ (θ + δ).
        n_observations: targets used so far.
        n_tracks: vehicles (tracks) they came from.
        n_shape_checked: targets whose box shape was checked against their class (those
            with both size cues, before the shape test).
        n_shape_outliers: of those, the ones left out for a shape their class does not give.
        n_frames: frames given to it (those with a measured ego gradient θ only).
    """

    mount_angle_rad: float
    mount_angle_sigma_rad: float
    height_m: float
    height_sigma_m: float
    horizon_offset_rad: float
    n_observations: int
    n_tracks: int
    n_shape_checked: int = 0
    n_shape_outliers: int = 0
    n_frames: int = 0

    @property
    def shape_outlier_share(self) -> float:
        """Share of the checked targets left out for their shape (NaN when none was checked)."""
        if self.n_shape_checked == 0:
            return math.nan
        return self.n_shape_outliers / self.n_shape_checked


class Estimator:
    """Base class of distance estimators.

    Subclasses implement :meth:`estimate`; stateful ones (tracking) also :meth:`reset`.
    ``needs_rotation`` tells the pipeline whether a frame without a rotation can still be
    estimated; ``needs_depth`` whether a depth map must come with each frame;
    ``rotation_source`` which rotation source the method is defined on, if any.

    What a method can do beyond one frame's estimates it declares here, so that the layers
    above call it without knowing the method: border handling (:attr:`handles_border_cuts`),
    an offline pass (:attr:`offline`, :meth:`finish`), a self-calibration of the mount
    (:attr:`self_calibrates`, :meth:`calibration`, :meth:`calibration_jackknife`) and what
    the end of a run should tell the user (:meth:`end_warnings`).
    """

    name: ClassVar[str] = ""
    needs_rotation: ClassVar[bool] = True
    needs_depth: ClassVar[bool] = False
    rotation_source: ClassVar[str | None] = None
    """Rotation source this method must be fed (e.g. ``"oxts"`` for the IMU baseline), or None
    for whichever source the caller uses; evaluations honour it per method."""
    handles_border_cuts: ClassVar[bool] = False
    """Whether the method states itself what it can say about a box cut by the image border.
    When False, :func:`settle_states` applies the cautious rule: an ``ok`` box cut by the
    bottom becomes an ``upper_bound`` (:func:`bottom_cut_is_upper_bound`)."""

    offline: ClassVar[bool] = False
    """Whether the method revises its estimates once the whole drive has been seen
    (:meth:`finish`): an offline method, reported under its own name, never a causal one."""

    def __init__(self, camera: Camera) -> None:
        self.camera = camera

    def reset(self) -> None:
        """Forget any state carried between frames (new sequence)."""

    def estimate(self, frame: FrameInput) -> FrameEstimates:
        """Estimate a distance for every box of ``frame``."""
        raise NotImplementedError

    def finish(self) -> list[FrameEstimates]:
        """An :attr:`offline` method's final estimates of every frame :meth:`estimate` was given
        since :meth:`reset`, in order (a causal method has none to give).

        Raises:
            NotImplementedError: the method is causal.
        """
        raise NotImplementedError(f"method {self.name!r} is causal: it has no offline pass")

    @property
    def self_calibrates(self) -> bool:
        """Whether the method estimates the camera's mount angle θ0 and height h from the
        targets as it goes (it then needs frames with a measured rotation)."""
        return False

    def calibration(self) -> SelfCalibration | None:
        """The method's current estimate of the camera's mount (before any data: the
        configured mount with its prior σ), or None for a method that keeps none."""
        return None

    def calibration_jackknife(self) -> NDArray[np.float64] | None:
        """``(2, 2)`` covariance of the mount estimate (δ of θ0 in radians, h in metres) from
        the spread of its leave-one-vehicle-out estimates, or None for a method that keeps no
        mount estimate."""
        return None

    def end_warnings(self) -> list[str]:
        """What the end of a run (or of an ``estimate``) should tell the user about this
        method's run, one line each (e.g. a self-calibration that never calibrated)."""
        return []


def image_size(camera: Camera) -> tuple[int, int] | None:
    """The camera's image ``(width, height)`` in pixels, or None when unknown (then no box is
    tested against the image: no ``cut`` flag, no ``outside_image``)."""
    if camera.image_width is None or camera.image_height is None:
        return None
    return camera.image_width, camera.image_height


def largest_implied_image(camera: Camera) -> tuple[int, int]:
    """The largest image ``(width, height)`` in pixels ``camera``'s principal point fits
    (:func:`~slopedist.io.frames.implied_image_sizes`, at least 1 px each): when the image
    size is not known, a box wholly beyond it lies outside every image the camera can take."""
    (_, width), (_, height) = implied_image_sizes(camera)
    return max(math.ceil(width), 1), max(math.ceil(height), 1)


def unusable_box_reasons(
    frame: FrameInput, needs_rotation: bool, camera: Camera | None = None
) -> NDArray[np.object_]:
    """Per-box reason that rules out an estimate before any method runs (bad box, a box
    outside ``camera``'s image when its size is known, no rotation)."""
    size = image_size(camera) if camera is not None else None
    reasons = table_box_problems(frame.boxes, size)
    if needs_rotation and not np.isfinite(frame.theta_rad):
        reasons[reasons == ""] = MissingReason.NO_ROTATION.value
    return reasons


def bottom_cut_is_upper_bound(
    est: FrameEstimates, boxes: NDArray[np.float64], camera: Camera
) -> None:
    """The ground-contact rule: an ``ok`` box cut by the bottom of the image becomes
    ``upper_bound`` with reason ``cut_bottom``, its distance kept (eq. 1 reads the lowest
    visible row, above the true contact row, so ``f·h/(u − v)`` is at least the true
    distance). Side and top cuts leave the contact row in view: they stay ``ok``. ``boxes``:
    in the frame's own pixels (:func:`~slopedist.io.detections.boxes.frame_pixel_boxes`)."""
    bottom = border_cuts(boxes, image_size(camera))[:, 3]
    rows = bottom & (est.status == EstimateStatus.OK.value)
    est.set_state(rows, EstimateStatus.UPPER_BOUND, MissingReason.CUT_BOTTOM)


def unresolved_distances(
    distance_m: NDArray[np.float64], boxes: NDArray[np.float64], camera: Camera
) -> NDArray[np.bool_]:
    """Which finite positive distances (metres, camera z) the image does not resolve: a row of
    error (:data:`ROW_ERROR_PX`) would change them by more than :data:`MAX_ROW_SHARE`.

    Either the box ``(left, top, right, bottom)`` (pixels) is less than
    :data:`MIN_RESOLVED_PX` tall — its own rows are not located, whatever distance a method
    reads from them — or the distance lies beyond ``f·h / MIN_RESOLVED_PX`` (``camera``'s focal
    length f in pixels and height h in metres): there a vehicle's ground contact is less than
    :data:`MIN_RESOLVED_PX` below the vanishing line, and a vehicle about as tall as the camera
    is high spans as few rows, so no cue of the box resolves the distance. For eq. 1 the second
    test is the ``near_horizon`` gap rule itself (``f·h/d = u − v``); it holds the other
    methods (``ours``' size cue, a depth map) to the same bound. NaN or non-positive
    distances are not flagged (other rules handle them).
    """
    d = np.asarray(distance_m, dtype=float)
    height_px = boxes[:, 3] - boxes[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        founded = np.isfinite(d) & (d > 0)
        gap_px = camera.f * camera.height_m / d
        return founded & ((gap_px < MIN_RESOLVED_PX) | (height_px < MIN_RESOLVED_PX))


def settle_states(
    est: FrameEstimates,
    boxes: BoxTable,
    camera: Camera,
    vehicle_classes: Iterable[str] = DEFAULT_VEHICLE_CLASSES,
    bottom_cut_bound: bool = False,
) -> FrameEstimates:
    """The states no method may overrule, applied after any method (returned; the method's
    arrays are copied, not changed).

    - ``cut``: the image edges that cut each usable box (``camera``'s image size; none known,
      no flag);
    - a box that is non-finite, inverted, degenerate or outside the image is ``missing`` with
      that reason, whatever the method said (without an image size: outside the largest image
      the camera's principal point fits, :func:`largest_implied_image`);
    - a box whose class is not in ``vehicle_classes`` is ``missing`` with reason
      ``not_a_vehicle`` (the row is kept, so every input box has one record; methods that
      track may still use it, e.g. as an occluder);
    - with ``bottom_cut_bound`` (a method that does not handle border cuts itself), an
      ``ok`` box cut by the bottom of the image becomes ``upper_bound``, reason ``cut_bottom``;
    - an ``ok`` distance the image does not resolve (:func:`unresolved_distances`: a box
      under 2 px tall, or a distance beyond ``f·h/2``) is ``missing``, reason
      ``beyond_resolution``;
    - an ``ok`` or ``upper_bound`` row without a finite positive distance is ``missing``
      (``ok`` is a promise);
    - a ``missing`` row has no distance in any column (:meth:`FrameEstimates.withhold_distances`).
    """
    size = image_size(camera)
    problems = table_box_problems(boxes, size)
    if size is None:  # no image size: a box beyond every image the camera fits is outside
        beyond = table_box_problems(boxes, largest_implied_image(camera)) == "outside_image"
        problems[(problems == "") & beyond] = MissingReason.OUTSIDE_IMAGE.value
    bad = problems != ""
    est.distance_m = np.array(est.distance_m, dtype=float)  # the method's arrays stay its own
    est.reason, est.status = est.reason.copy(), est.status.copy()
    pixel_boxes = frame_pixel_boxes(boxes)
    est.cut = cut_labels(border_cuts(pixel_boxes, size))
    est.cut[bad] = ""
    est.status[bad] = EstimateStatus.MISSING.value
    est.reason[bad] = problems[bad]
    est.distance_m[bad] = np.nan
    other = ~bad & ~vehicle_mask(boxes.cls, vehicle_classes)
    est.set_state(other, EstimateStatus.MISSING, MissingReason.NOT_A_VEHICLE)
    if bottom_cut_bound:
        bottom_cut_is_upper_bound(est, pixel_boxes, camera)
    unresolved = (est.status == EstimateStatus.OK.value) & unresolved_distances(
        est.distance_m, pixel_boxes, camera
    )
    est.set_state(unresolved, EstimateStatus.MISSING, MissingReason.BEYOND_RESOLUTION)
    d = est.distance_m
    with np.errstate(invalid="ignore"):
        unfounded = (est.status != EstimateStatus.MISSING.value) & ~(np.isfinite(d) & (d > 0))
    est.status[unfounded] = EstimateStatus.MISSING.value
    est.reason[unfounded & (est.reason == "")] = MissingReason.INVALID_DISTANCE.value
    d[unfounded | (est.status == EstimateStatus.MISSING.value)] = np.nan
    est.withhold_distances()
    return est
