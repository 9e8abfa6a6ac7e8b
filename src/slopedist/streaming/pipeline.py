"""The streaming pipeline: a calibration, a method and a rotation source in; per frame, the
image and its boxes in, one result per box out.

:class:`Pipeline` is the one streaming object: ``slopedist run`` and ``batch``
(:mod:`slopedist.streaming.loop`, which adds where frames come from and where results go),
``slopedist estimate`` and Python code all go through it. Per frame it runs the visual
odometry on the grey image (the frame's boxes masked out of its features), turns the rotation
into the ego gradient θ over the look-back and the boxes into per-target estimates
(:class:`~slopedist.streaming.step.FrameStep`), and says for each box what can be said
(:class:`Target`: a distance, an upper bound or a reason why not).

Convention: images BGR ``H×W×3`` (or grey ``H×W``) uint8 as OpenCV reads them; boxes left,
top, right, bottom in the image's pixels; timestamps in seconds; distances in metres along the
camera's axis; θ in degrees in the results, radians inside.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from types import TracebackType
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import KITTI_CAMERA_HEIGHT_M, Camera
from slopedist.core.errors import ConfigurationError, DataMismatchError
from slopedist.core.suggest import unknown_choice
from slopedist.estimators import DEFAULT_METHOD, Estimator, make_estimator
from slopedist.estimators.base import (
    EstimateStatus,
    FrameEstimates,
    ReferencePoint,
    SelfCalibration,
    parse_reference,
)
from slopedist.estimators.references import DEFAULT_REFERENCE
from slopedist.io.calibration import CameraCalibration, read_calibration
from slopedist.io.detections.adapters import as_box_table
from slopedist.io.detections.boxes import (
    DEFAULT_VEHICLE_CLASSES,
    FRAME_BOX_COLUMN,
    BoxTable,
    frame_pixel_boxes,
)
from slopedist.io.detections.readers import read_box_file
from slopedist.io.frames import DEFAULT_FPS, check_calibration, open_frames
from slopedist.io.intrinsics import Intrinsics, in_frame_pixels
from slopedist.odometry import make_odometry
from slopedist.odometry.base import LOOKBACK_S, RotationOdometry, RotationTrack
from slopedist.odometry.point_map import PointMap
from slopedist.streaming.frame_times import long_step_warning
from slopedist.streaming.step import (
    FrameStep,
    RecordColumns,
    frame_records,
    parse_columns,
    user_track_ids,
)

ODOMETRY_CHOICES = ("builtin", "orbslam3", "none")
"""Rotation sources on the frames (``--odometry``; ``none`` = no rotations, for methods that do
not use them, or rotations given with each frame)."""


def build_odometry(
    name: str,
    camera: Camera,
    vocab: Path | None = None,
    lookback_s: float = LOOKBACK_S,
    point_map: PointMap | None = None,
) -> RotationOdometry:
    """The rotation source ``name`` (``builtin`` or ``orbslam3``) for ``camera``.

    The built-in backend estimates rotations directly over ``lookback_s`` seconds (the
    look-back of the gradient) and maps its tracked points into the ideal ``camera`` with
    ``point_map`` (lens distortion, fx ≠ fy); ORB-SLAM3 tracks a map and has neither setting.
    """
    if vocab is not None and name != "orbslam3":
        raise ConfigurationError("--vocab is only used with --odometry orbslam3")
    if name == "orbslam3":
        return make_odometry(name, camera, vocabulary=vocab)
    if point_map is not None:
        return make_odometry(name, camera, lookback_s=lookback_s, point_map=point_map)
    return make_odometry(name, camera, lookback_s=lookback_s)


@dataclass(frozen=True)
class Target:
    """What the pipeline says about one box of a frame.

    Attributes:
        track_id: the box's track id as given, else the method's own track (``ours``), else
            -1.
        cls: the box's class name.
        box: ``(left, top, right, bottom)`` in the image's own pixels, as given.
        score: the detector's score (NaN when none was given).
        distance_m: distance to the vehicle, metres along the camera's axis, at
            :attr:`reference`; NaN when :attr:`status` is ``missing``.
        sigma_m: the method's 1σ of the distance, metres (NaN where it states none).
        reference: the point of the vehicle the distance refers to (``centre``,
            ``nearest_face``, ``contact``, ...).
        status: ``ok`` (a distance to act on), ``upper_bound`` (the true distance is at most
            :attr:`distance_m`: a box cut by the bottom of the image) or ``missing``.
        reason: why the status is not ``ok`` (``cut_bottom``, ``below_horizon``,
            ``not_a_vehicle``, ...); empty for ``ok``.
        cut: the image borders the box touches (``bottom``, ``left+bottom``, ...; empty when
            none).
        speed_mps: the target's speed relative to the camera, m/s (positive: moving away;
            NaN when the method tracks none or the row is not ``ok``).
        ttc_s: time to collision, seconds (NaN when not closing in or unknown).
    """

    track_id: int
    cls: str
    box: tuple[float, float, float, float]
    score: float
    distance_m: float
    sigma_m: float
    reference: str
    status: EstimateStatus
    reason: str
    cut: str
    speed_mps: float
    ttc_s: float

    @property
    def ok(self) -> bool:
        """Whether the distance is one to act on (status ``ok``)."""
        return self.status is EstimateStatus.OK


@dataclass(frozen=True)
class OdometryOutput:
    """What the rotation source said about one frame (defaults: no pixels or no odometry).

    Attributes:
        R_world_cam: camera-to-world rotation ``(3, 3)``, or None.
        segment: the odometry's segment (restarts; θ never looks back across one).
        state: the odometry's state (``ok``, ``lost``, ...; empty without odometry or pixels).
        inliers: correspondences behind the rotation.
        ms: the odometry's time on the frame, milliseconds (NaN when it did not run).
    """

    R_world_cam: NDArray[np.float64] | None = None
    segment: int = 0
    state: str = ""
    inliers: int = 0
    ms: float = math.nan


@dataclass(frozen=True)
class FrameResult:
    """One frame's results: :attr:`targets` (one per box, in the order given), the ego road
    gradient and the records ``records.csv`` has (:meth:`to_records`).

    Attributes:
        frame: the frame's index.
        t: its timestamp, seconds.
        theta_rad: the ego road gradient θ (eq. 4), radians; NaN without a rotation
            (:attr:`theta_deg`: in degrees).
        method: the method's name.
        boxes: the frame's boxes as the method saw them (in the ideal camera).
        estimates: the method's per-box arrays (radians, metres, pixels).
        odometry: what the rotation source said about the frame.
        odometry_jump: the frame's rotation jumped (an odometry glitch, not trusted).
        estimation_ms: time of the frame step (θ and the method), milliseconds.
    """

    frame: int
    t: float
    theta_rad: float
    method: str
    boxes: BoxTable
    estimates: FrameEstimates
    odometry: OdometryOutput = OdometryOutput()
    odometry_jump: bool = False
    estimation_ms: float = math.nan

    @property
    def theta_deg(self) -> float:
        """The ego road gradient θ, degrees (NaN without a rotation)."""
        return math.degrees(self.theta_rad)

    @functools.cached_property
    def targets(self) -> tuple[Target, ...]:
        """One :class:`Target` per box."""
        return _targets(self.boxes, self.estimates)

    def to_records(self, columns: str | RecordColumns = "default") -> list[dict[str, Any]]:
        """The frame's rows of ``records.csv`` (the same columns and values ``slopedist run``
        writes): ``columns`` ``"default"`` (what a user acts on) or ``"all"`` (with the
        method's diagnostics, as ``--columns all``).

        Raises:
            ConfigurationError: another ``columns``.
        """
        return frame_records(
            self.boxes, self.t, self.estimates, self.method, parse_columns(columns)
        )


def _column(est: FrameEstimates, name: str) -> NDArray[np.float64]:
    """Extra column ``name`` of ``est`` (NaN where the method has none)."""
    return np.asarray(est.extra.get(name, np.full(len(est), np.nan)), dtype=float)


def _targets(boxes: BoxTable, est: FrameEstimates) -> tuple[Target, ...]:
    """The :class:`Target` of every box of a frame."""
    pixels = frame_pixel_boxes(boxes)
    sigma, speed, ttc = (_column(est, c) for c in ("sigma_m", "speed_mps", "ttc_s"))
    ids = user_track_ids(boxes, est)
    return tuple(
        Target(
            track_id=int(ids[i]),
            cls=str(boxes.cls[i]),
            box=(
                float(pixels[i, 0]),
                float(pixels[i, 1]),
                float(pixels[i, 2]),
                float(pixels[i, 3]),
            ),
            score=float(boxes.score[i]),
            distance_m=float(est.distance_m[i]),
            sigma_m=float(sigma[i]),
            reference=str(est.reference[i]),
            status=EstimateStatus(est.status[i]),
            reason=str(est.reason[i]),
            cut=str(est.cut[i]),
            speed_mps=float(speed[i]),
            ttc_s=float(ttc[i]),
        )
        for i in range(len(boxes))
    )


@dataclass(frozen=True)
class FinishResult:
    """What the end of a stream gives (:meth:`Pipeline.finish`).

    Attributes:
        frames: an offline method's final results of every frame with boxes (its pass over the
            whole drive revises the causal ones :meth:`Pipeline.update` gave); empty for a
            causal method, whose results are final as they come.
        calibration: a self-calibrating method's estimate of the camera's mount, else None.
        warnings: what the user should know about the run, one line each.
    """

    frames: tuple[FrameResult, ...] = ()
    calibration: SelfCalibration | None = None
    warnings: tuple[str, ...] = ()

    def to_records(self, columns: str | RecordColumns = "default") -> list[dict[str, Any]]:
        """The rows of ``records.csv`` of :attr:`frames`, in order (``columns`` as
        :meth:`FrameResult.to_records`)."""
        return [row for frame in self.frames for row in frame.to_records(columns)]


def pipeline_calibration(
    calib: str | Path | Camera | Intrinsics | CameraCalibration,
    height_m: float | None = None,
    mount_angle_deg: float | None = None,
    image_size: tuple[int, int] | None = None,
) -> CameraCalibration:
    """The calibration of ``calib`` (a file of any form ``--calib`` reads, a
    :class:`~slopedist.core.camera.Camera`, :class:`~slopedist.io.intrinsics.Intrinsics` or a
    read calibration), with the mount given (metres, degrees; None: the camera's own, else
    KITTI's 1.65 m and 0°) and the image size (pixels) when known.

    Raises:
        ConfigurationError: a mount out of range, or an image size the calibration refuses.
        InputFileError: an unreadable or implausible calibration file.
    """
    mount_rad = None if mount_angle_deg is None else math.radians(mount_angle_deg)
    if isinstance(calib, CameraCalibration):
        intrinsics, camera = calib.intrinsics, calib.camera
    elif isinstance(calib, Camera):
        camera = calib
        w, h = calib.image_width, calib.image_height
        size = None if w is None or h is None else (w, h)
        intrinsics = Intrinsics.from_values(calib.f, calib.f, calib.c_x, calib.c_y, image_size=size)
    else:
        height = KITTI_CAMERA_HEIGHT_M if height_m is None else height_m
        return read_calibration(calib, height, mount_rad or 0.0, image_size=image_size)
    camera = camera.with_mount(height_m=height_m, mount_angle_rad=mount_rad)
    return read_calibration(
        intrinsics, camera.height_m, camera.mount_angle_rad, image_size=image_size
    )


class Pipeline:
    """Distances to the vehicles of a video stream, frame by frame.

    Args:
        calib: the camera: a calibration file of any form ``slopedist run --calib`` reads
            (KITTI calib, 3×3 K text, OpenCV or ROS YAML), or a
            :class:`~slopedist.core.camera.Camera`.
        method: the distance method (``ours``, ``paper``, ``flat``, ...; :class:`slopedist.Method`).
        odometry: the rotation source on the frames: ``builtin`` visual odometry, ``orbslam3``,
            or ``none`` (no rotations, or rotations given to :meth:`update`).
        height_m: the camera's height above the road, metres (None: the camera's, else 1.65).
        mount_angle_deg: its mount angle θ0, degrees (None: the camera's, else 0).
        reference: the point of the vehicle every method's distances are moved to
            (``nearest_face``, ``centre``, ``contact``;
            :data:`~slopedist.estimators.references.DEFAULT_REFERENCE`, the gap to the
            vehicle's nearest face, as ``slopedist run``); None: each method's own point.
        vehicle_classes: class names scored as vehicles (others: ``missing``,
            ``not_a_vehicle``).
        fps: the frame rate that gives a frame's time when :meth:`update` gets none.
        lookback_s: the look-back of the ego gradient, seconds.
        image_size: ``(width, height)`` pixels, for a stream without images; else the first
            image's size is taken (a calibration for another size is refused).
        class_map: detector class index → class name for boxes with class indices (None:
            COCO's vehicle classes, those of ultralytics' and most exported models).
        **method_options: the method's own options (``ours``: its option names, e.g.
            ``size_learning=True``).

    Example:
        >>> import numpy as np
        >>> pipe = Pipeline(Camera(f=721.5, c_x=609.6, c_y=172.9), method="flat")
        >>> image = np.zeros((375, 1242, 3), np.uint8)
        >>> result = pipe.update(image, [(560, 190, 660, 260)])
        >>> round(result.targets[0].distance_m, 1), result.targets[0].status.value
        (13.7, 'ok')

    Raises:
        ConfigurationError: an unknown method, odometry or option; a method the rotation
            source cannot feed.
        InputFileError: an unreadable calibration file.
    """

    def __init__(  # noqa: PLR0913 (the options of slopedist run, by name)
        self,
        calib: str | Path | Camera | Intrinsics | CameraCalibration,
        *,
        method: str = DEFAULT_METHOD,
        odometry: str = "builtin",
        height_m: float | None = None,
        mount_angle_deg: float | None = None,
        reference: str | ReferencePoint | None = DEFAULT_REFERENCE,
        vehicle_classes: Iterable[str] = DEFAULT_VEHICLE_CLASSES,
        fps: float = DEFAULT_FPS,
        lookback_s: float = LOOKBACK_S,
        image_size: tuple[int, int] | None = None,
        class_map: Mapping[int, str] | None = None,
        **method_options: Any,
    ) -> None:
        if odometry not in ODOMETRY_CHOICES:
            raise ConfigurationError(unknown_choice("odometry", odometry, ODOMETRY_CHOICES))
        calibration = pipeline_calibration(calib, height_m, mount_angle_deg, image_size)
        options = dict(method_options)
        estimator = make_estimator(method, calibration.camera, **options)  # the options checked
        _check_rotation_source(estimator, odometry)

        def parts(camera: Camera) -> tuple[Estimator, RotationOdometry | None]:
            est = (
                estimator
                if camera == estimator.camera
                else make_estimator(method, camera, **options)
            )
            if odometry == "none":
                return est, None
            return est, build_odometry(odometry, camera, None, lookback_s, calibration.point_map)

        self._setup(calibration.camera, lookback_s, vehicle_classes, fps, class_map)
        self.reference = _reference_point(reference)
        self._intrinsics = None if calibration.intrinsics.is_ideal else calibration.intrinsics
        self._parts: Callable[[Camera], tuple[Estimator, RotationOdometry | None]] | None = parts
        if calibration.camera.image_width is not None:
            self._start(calibration.camera)

    @classmethod
    def from_parts(
        cls,
        estimator: Estimator,
        odometry: RotationOdometry | None = None,
        *,
        lookback_s: float = LOOKBACK_S,
        vehicle_classes: Iterable[str] = DEFAULT_VEHICLE_CLASSES,
        fps: float = DEFAULT_FPS,
        reference: str | ReferencePoint | None = DEFAULT_REFERENCE,
    ) -> Pipeline:
        """A pipeline of a built method and rotation source (``slopedist run`` builds them
        from its options and the frames); :meth:`process` takes boxes already in the method's
        ideal camera; ``reference`` as in the class. Internal."""
        pipe = cls.__new__(cls)
        pipe._setup(estimator.camera, lookback_s, vehicle_classes, fps, None)
        pipe.reference = _reference_point(reference)
        pipe._intrinsics = None
        pipe._parts = None
        pipe._begin(estimator, odometry)
        return pipe

    def _setup(
        self,
        camera: Camera,
        lookback_s: float,
        vehicle_classes: Iterable[str],
        fps: float,
        class_map: Mapping[int, str] | None,
    ) -> None:
        if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
            raise ConfigurationError(f"fps must be a number of frames per second > 0, got {fps!r}")
        self.camera = camera
        self.fps = float(fps)
        self.lookback_s = lookback_s
        self.vehicle_classes = vehicle_classes
        self.class_map = class_map
        self._image_size: tuple[int, int] | None = None
        self._step: FrameStep | None = None
        self._odometry: RotationOdometry | None = None
        self._next_frame = 0
        self._segment = 0
        self._last_t: float | None = None
        self._steps_s: list[float] = []
        self._rotations_seen = False
        self._held: list[FrameResult] = []
        self._closed = False

    def _start(self, camera: Camera) -> None:
        """Build the method and the rotation source for ``camera`` (it knows the image size)."""
        assert self._parts is not None
        self._begin(*self._parts(camera))

    def _begin(self, estimator: Estimator, odometry: RotationOdometry | None) -> None:
        self.camera = estimator.camera
        self._step = FrameStep(estimator, self.lookback_s, self.vehicle_classes, self.reference)
        self._odometry = odometry

    @property
    def estimator(self) -> Estimator:
        """The distance method (built once the image size is known)."""
        return self._started().estimator

    @property
    def method(self) -> str:
        """The method's name."""
        return self._started().estimator.name

    def _started(self) -> FrameStep:
        if self._step is None:
            raise ConfigurationError(
                "the pipeline has not seen an image yet: it takes the image size from the "
                "first one (or give image_size=(width, height))"
            )
        return self._step

    # -- frames --------------------------------------------------------------------------

    def update(
        self,
        image: NDArray[np.uint8] | None,
        boxes: Any,
        t: float | None = None,
        *,
        frame: int | None = None,
        R_world_cam: NDArray[np.float64] | None = None,
        depth_m: NDArray[np.float32] | None = None,
    ) -> FrameResult:
        """The results of the next frame.

        Args:
            image: the frame, ``H×W×3`` BGR or ``H×W`` grey uint8 (as OpenCV reads it); None
                when the rotation source is not built-in (or the frame could not be read).
            boxes: its boxes in the image's pixels, in any form
                :func:`~slopedist.io.detections.adapters.as_box_table` takes: an ``(N, 4)``
                array of left, top, right, bottom, ``(N, 5)`` with a score, ``(N, 6)`` with a
                class index, a list of tuples, a :class:`~slopedist.io.detections.boxes.
                BoxTable`, an ultralytics ``Results`` or a supervision ``Detections``.
            t: its timestamp, seconds (None: the frame's index / ``fps``); timestamps must
                increase.
            frame: its index (None: one more than the last frame's).
            R_world_cam: its camera-to-world rotation ``(3, 3)`` when it comes from elsewhere
                (an IMU, a pose file; with ``odometry="none"``).
            depth_m: its depth map in metres, for the ``depthmap`` method.

        Example:
            >>> pipe = Pipeline(Camera(f=721.5, c_x=609.6, c_y=172.9), method="flat",
            ...                 odometry="none", image_size=(1242, 375))
            >>> cut = pipe.update(None, [(560, 300, 700, 375)]).targets[0]  # at the bottom
            >>> cut.status.value, cut.reason, cut.cut
            ('upper_bound', 'cut_bottom', 'bottom')

        Raises:
            DataMismatchError: an image of another size than the first (or than the
                calibration's), boxes of no known form, a timestamp that does not increase.
            ConfigurationError: no image size known (no image and no ``image_size``), or a
                rotation given to a pipeline with its own odometry.
        """
        k = self._next_frame if frame is None else int(frame)
        t_s = k / self.fps if t is None else t
        image = self._take_image(image)
        table = as_box_table(boxes, k, self.class_map)
        if self._intrinsics is not None and FRAME_BOX_COLUMN not in table.extra:
            table = self._intrinsics.rectify_table(table)
        return self.process(k, t_s, image, table, R_world_cam, depth_m)

    def run(
        self,
        frames: str | Path,
        boxes: str | Path | BoxTable | Callable[[NDArray[np.uint8]], Any],
        *,
        fps: float | None = None,
        timestamps: str | Path | None = None,
    ) -> Iterator[FrameResult]:
        """:meth:`update` with every frame of an image folder or a video (its own timestamps:
        ``fps`` or a timestamps file, as ``slopedist run`` takes them), one result per frame.

        Args:
            frames: image folder or video file (:func:`~slopedist.io.frames.open_frames`).
            boxes: a box file (any layout ``slopedist run --boxes`` reads), a
                :class:`~slopedist.io.detections.boxes.BoxTable` of every frame (by frame
                index), or a detector: called with each image, it returns the boxes in any form
                :meth:`update` takes.
            fps: frames per second (None: 10 for a folder, a video's own rate).
            timestamps: a timestamps file, one line per frame.

        Example::

            for result in Pipeline("calib.txt").run("drive.mp4", "boxes.csv"):
                print(result.frame, [t.distance_m for t in result.targets if t.ok])
        """
        detect = boxes if callable(boxes) else None
        table = None if detect is not None else boxes
        if isinstance(table, (str, Path)):
            table = read_box_file(table)
        by_frame = table.frame_lookup() if isinstance(table, BoxTable) else None
        no_boxes = BoxTable.empty()
        for frame in open_frames(frames, fps, timestamps):
            if (
                frame.image is None
                and self._last_t is not None
                and frame.timestamp_s <= self._last_t
            ):
                continue  # an unreadable frame out of time order: no frame to step
            if detect is not None:
                found = detect(frame.image) if frame.image is not None else no_boxes
            else:
                found = by_frame.get(frame.index, no_boxes) if by_frame is not None else no_boxes
            yield self.update(frame.image, found, frame.timestamp_s, frame=frame.index)

    def _take_image(self, image: NDArray[np.uint8] | None) -> NDArray[np.uint8] | None:
        """``image`` checked (uint8, grey or three channels, the stream's size); the first one
        sizes the camera and starts the method."""
        if image is None:
            if self._step is None:
                self._started()  # raises: no size to test the boxes against the border
            return None
        arr = np.asarray(image)
        if arr.dtype != np.uint8 or not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] == 3)):
            raise DataMismatchError(
                f"image must be H×W×3 (BGR) or H×W uint8, got {arr.dtype} of shape {arr.shape}"
            )
        height, width = arr.shape[:2]
        if self._image_size is None:
            check_calibration(self.camera, width, height, "Pipeline images")
            self._image_size = (width, height)
            if self._step is None:
                self._start(self.camera.with_image_size(width, height))
        elif self._image_size != (width, height):
            raise DataMismatchError(
                f"image of {width}×{height} px in a stream of {self._image_size[0]}×"
                f"{self._image_size[1]} px images"
            )
        return arr

    def process(
        self,
        frame_index: int,
        timestamp_s: float,
        image: NDArray[np.uint8] | None,
        boxes: BoxTable,
        R_world_cam: NDArray[np.float64] | None = None,
        depth_m: NDArray[np.float32] | None = None,
    ) -> FrameResult:
        """:meth:`update` of a frame whose boxes are a :class:`BoxTable` in the method's ideal
        camera (what the run loop gives); ``image`` is not checked. Internal."""
        if self._closed:
            raise ConfigurationError("the pipeline is closed")
        step = self._started()
        odo = self._rotation(image, timestamp_s, boxes, R_world_cam)
        t0 = time.perf_counter()
        res = step.step(
            frame_index, timestamp_s, odo.R_world_cam, boxes, image, depth_m, odo.segment
        )
        ms = (time.perf_counter() - t0) * 1e3
        self._note_time(timestamp_s, odo.R_world_cam is not None)
        self._next_frame = frame_index + 1
        out = FrameResult(
            frame_index,
            float(timestamp_s),
            res.theta_rad,
            step.estimator.name,
            boxes,
            res.estimates,
            odo,
            res.odometry_jump,
            ms,
        )
        if step.estimator.offline and len(boxes):
            self._held.append(out)
        return out

    def _rotation(
        self,
        image: NDArray[np.uint8] | None,
        timestamp_s: float,
        boxes: BoxTable,
        R_world_cam: NDArray[np.float64] | None,
    ) -> OdometryOutput:
        """The frame's rotation: given, or the odometry's on the grey image (boxes, in the
        frame's own pixels, masked out)."""
        if R_world_cam is not None and self._odometry is not None:
            raise ConfigurationError(
                "a rotation was given to a pipeline with its own odometry: use odometry='none'"
            )
        if image is None or self._odometry is None:
            return OdometryOutput(R_world_cam, self._segment)
        gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        t0 = time.perf_counter()
        res = self._odometry.process(
            np.asarray(gray, dtype=np.uint8), timestamp_s, in_frame_pixels(boxes).boxes
        )
        # a backend that waits on purpose (ORB-SLAM3's real-time pacing) reports its own time
        ms = getattr(self._odometry, "last_track_ms", (time.perf_counter() - t0) * 1e3)
        self._segment = int(getattr(res, "segment", 0))
        return OdometryOutput(
            res.R_world_cam, self._segment, res.state.value, int(res.inliers), float(ms)
        )

    def _note_time(self, timestamp_s: float, rotation: bool) -> None:
        """Keep the step from the last frame (for :func:`long_step_warning`)."""
        if self._last_t is not None:
            self._steps_s.append(timestamp_s - self._last_t)
        self._last_t = timestamp_s
        self._rotations_seen |= rotation or self._odometry is not None

    # -- the end ---------------------------------------------------------------------------

    @property
    def segment(self) -> int:
        """The odometry's current segment (its restarts so far)."""
        return self._segment

    @property
    def offline(self) -> bool:
        """Whether the method revises its results at the end (:meth:`finish`)."""
        return self._started().estimator.offline

    def finish(self) -> FinishResult:
        """The end of the stream: an offline method's final results of every frame, a
        self-calibration's estimate and the warnings (see :class:`FinishResult`).

        Example:
            >>> pipe = Pipeline(Camera(f=721.5, c_x=609.6, c_y=172.9), method="flat",
            ...                 odometry="none", image_size=(1242, 375))
            >>> pipe.finish().frames
            ()
        """
        step = self._started()
        est = step.estimator
        frames: tuple[FrameResult, ...] = ()
        if est.offline:
            revised = step.finish()
            frames = tuple(
                replace(r, estimates=e) for r, e in zip(self._held, revised, strict=True)
            )
        warnings = list(est.end_warnings())
        steps = long_step_warning(self._steps_s, self.lookback_s)
        if steps is not None and self._rotations_seen:
            warnings.append(steps)
        return FinishResult(
            frames, est.calibration() if est.self_calibrates else None, tuple(warnings)
        )

    def close(self) -> None:
        """Release the rotation source (ORB-SLAM3's threads); the pipeline takes no more
        frames."""
        close = getattr(self._odometry, "close", None)
        if close is not None:
            close()
        self._closed = True

    def __enter__(self) -> Pipeline:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def _reference_point(reference: str | ReferencePoint | None) -> ReferencePoint | None:
    """``reference`` as a :class:`~slopedist.estimators.base.ReferencePoint` (None stays None).

    Raises:
        ConfigurationError: a name that is no vehicle reference point.
    """
    if reference is None:
        return None
    return parse_reference(str(getattr(reference, "value", reference)))


def stream_rotations(
    pipe: Pipeline, track: RotationTrack, boxes: BoxTable
) -> Iterator[FrameResult]:
    """Every frame of ``track`` (its rotations and times) with its boxes (already in the
    method's camera; box frame indices index the track) through ``pipe``, in order: what
    ``slopedist estimate`` streams."""
    by_frame = boxes.frame_lookup()
    no_boxes = BoxTable.empty()
    for k in range(len(track)):
        R = track.R_world_cam[k] if track.valid[k] else None
        t = float(track.timestamps_s[k])
        yield pipe.process(k, t, None, by_frame.get(k, no_boxes), R)


def _check_rotation_source(estimator: Estimator, odometry: str) -> None:
    """Refuse a method defined on another rotation source (IMU) fed the visual odometry."""
    source = estimator.rotation_source
    if source is not None and odometry != "none":
        raise ConfigurationError(
            f"method '{estimator.name}' is defined on '{source}' rotations: use "
            "odometry='none' and give each frame's R_world_cam"
        )
