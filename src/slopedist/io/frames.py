"""Frame sources: an image folder or a video file, read lazily one frame at a time.

Convention: images are BGR ``H×W×3`` uint8 (grey files are expanded to three channels), origin
top-left; timestamps are float64 seconds. Memory holds one frame at a time, whatever the length.

Frame numbering:

- Image folder: the numbered image files are the frames, their number the frame index; stray
  and hidden files are skipped and reported, never renumbering the folder; a folder without
  numbered files is numbered 0, 1, ... in sorted name order (the full rule:
  :mod:`slopedist.io.framefiles`). A gap in the numbering yields frames of status ``missing``.
- Video file: frames are numbered 0, 1, ... in decoding order.

Timestamps: ``index / fps`` (``fps`` 10 by default for folders, the container's frame rate for
videos), or line ``index`` of a timestamps file (:func:`read_timestamps`).

A frame that cannot be used is yielded with a :class:`FrameStatus` other than ``ok`` and no image,
so a long run records it and goes on.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime
from enum import Enum
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.core.errors import (
    ConfigurationError,
    DataMismatchError,
    InputFileError,
    MissingInputError,
)
from slopedist.core.limits import DEFAULT_MAX_PIXELS, MAX_FRAME_INTERVAL_S
from slopedist.core.paths import utf8_name
from slopedist.core.textfiles import numbered_lines
from slopedist.io.framefiles import list_frame_files
from slopedist.io.images import header_image_size, image_size_problem, read_colour

DEFAULT_FPS = 10.0
"""Frame rate assumed for image folders without a timestamps file (KITTI's 10 Hz)."""

MAX_PRINCIPAL_POINT_OFFSET = (0.15, 0.25)
"""Largest accepted distance of the principal point from the image centre, as a fraction of the
image width (for c_x) and of its height (for c_y); beyond it the calibration is taken to belong
to other (resized or cropped) frames. Lenses put it within a few per cent of the centre; the
rows are allowed more, for frames cropped at the bottom (the bonnet). A centred calibration of
frames 1.33 or 1.5 times as large, or 0.67 times, puts c_x 17–25 % of the width off."""

FIELD_OF_VIEW_RANGE_DEG = (3.0, 170.0)
"""Accepted horizontal field of view ``2·atan(width / 2f)``, degrees: outside it the focal
length does not belong to images of that width (a calibration of other, resized frames)."""

_KITTI_TIME = re.compile(r"^(\d{4}-\d{2}-\d{2}[ T]\d{2}:\d{2}:\d{2})(\.\d+)?$")


class FrameStatus(str, Enum):
    """Whether a frame's pixels could be used."""

    OK = "ok"
    MISSING = "missing"
    """No file for this index (a gap in a numbered image folder)."""
    UNREADABLE = "unreadable"
    """The file exists but does not decode as an image (or the video stopped decoding)."""
    SIZE_CHANGED = "size_changed"
    """The image size differs from the first frame's."""


@dataclass(frozen=True)
class Frame:
    """One frame of a source.

    Attributes:
        index: frame index (see the module docstring), the ``frame`` of box files.
        timestamp_s: seconds.
        image: BGR ``H×W×3`` uint8, or None when ``status`` is not ``ok``.
        status: :class:`FrameStatus`.
        source: file name (folders) or ``"<video name>#<index>"`` (videos), for messages.
        detail: why the frame is not ``ok`` ("" when it is).
    """

    index: int
    timestamp_s: float
    image: NDArray[np.uint8] | None
    status: FrameStatus
    source: str
    detail: str = ""

    @property
    def ok(self) -> bool:
        return self.status is FrameStatus.OK


class FrameSource(Protocol):
    """What the runner needs of a frame source."""

    path: Path

    def __iter__(self) -> Iterator[Frame]: ...

    def expected_frames(self) -> int | None:
        """Number of frames the source will yield, if known in advance (progress bars)."""
        ...

    def frame_size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels of the first readable frame."""
        ...


def read_timestamps(path: str | Path) -> NDArray[np.float64]:
    """Timestamps file → seconds, one per frame (line k, counting non-empty lines from 0, is
    frame k).

    A line is either a number of seconds or a KITTI raw date-time
    (``2011-09-26 13:02:25.964389445``; turned into seconds after the first line). Lines starting
    with ``#`` are ignored. Timestamps must increase strictly, and consecutive ones be at most
    ``MAX_FRAME_INTERVAL_S`` apart at the median (else they are not seconds).

    Raises:
        MissingInputError: no such file.
        InputFileError: a line that is neither form, a timestamp that does not increase
            (naming the line), or a median step over ``MAX_FRAME_INTERVAL_S``.
    """
    path = Path(path)
    values: list[float] = []
    t0: datetime | None = None
    prev_line = 0
    for lineno, line in numbered_lines(path, "timestamps file"):
        value = _parse_time(line, t0)
        if value is None:
            raise InputFileError(
                path,
                f"'{line}' is neither seconds nor a date-time 'YYYY-MM-DD hh:mm:ss.f'",
                line=lineno,
                field="timestamp",
            )
        if isinstance(value, datetime):
            t0 = t0 or value
            seconds = (value - t0).total_seconds()
        else:
            seconds = value
        if values and not seconds > values[-1]:
            raise InputFileError(
                path,
                f"timestamp {seconds} s does not increase (line {prev_line} has {values[-1]} s)",
                line=lineno,
                field="timestamp",
            )
        values.append(seconds)
        prev_line = lineno
    if not values:
        raise InputFileError(path, "no timestamps in file")
    times = np.asarray(values, dtype=float)
    _check_frame_period(path, times)
    return times


def _check_frame_period(path: Path, times_s: NDArray[np.float64]) -> None:
    """Refuse timestamps whose median step exceeds ``MAX_FRAME_INTERVAL_S`` (seconds): a file
    in milliseconds or microseconds, read as seconds, would make every frame a gap in the drive
    (no odometry, no speed) while the run still reported it as ok."""
    if len(times_s) < 2:
        return
    step = float(np.median(np.diff(times_s)))
    if step > MAX_FRAME_INTERVAL_S:
        raise InputFileError(
            path,
            f"consecutive timestamps are {step:g} s apart (median), frames more than "
            f"{MAX_FRAME_INTERVAL_S:g} s apart are not a video: timestamps in milliseconds, "
            "microseconds or nanoseconds? The file is in seconds",
            field="timestamp",
        )


def _parse_time(text: str, t0: datetime | None) -> float | datetime | None:
    try:
        value = float(text)
    except ValueError:
        pass
    else:
        return value if math.isfinite(value) else None
    m = _KITTI_TIME.match(text)
    if not m:
        return None
    try:
        whole = datetime.strptime(m.group(1).replace("T", " "), "%Y-%m-%d %H:%M:%S")
    except ValueError:
        return None
    frac = float(m.group(2) or 0.0)
    # microsecond precision is enough at video frame rates; the nanoseconds are rounded
    return whole.replace(microsecond=min(round(frac * 1e6), 999_999))


def with_frame_size(camera: Camera, frames: FrameSource, calibration: str = "") -> Camera:
    """``camera`` knowing the image size for the border test of every box: the frames' size,
    unless the calibration states its own (then the two must agree).

    Raises:
        DataMismatchError: the camera cannot belong to the frames (:func:`check_calibration`),
            naming ``calibration`` (where the camera comes from) and the frames.
    """
    width, height = frames.frame_size()
    where = f"{calibration} and the frames of {frames.path}" if calibration else str(frames.path)
    check_calibration(camera, width, height, where)
    if camera.image_width is not None and camera.image_height is not None:
        return camera
    return camera.with_image_size(width, height)


def implied_image_sizes(camera: Camera) -> tuple[tuple[float, float], tuple[float, float]]:
    """``((least, largest width), (least, largest height))`` in pixels of the images whose
    centre ``camera``'s principal point can lie off by :data:`MAX_PRINCIPAL_POINT_OFFSET`
    (the images :func:`check_calibration` accepts for it): ``c / (0.5 ± offset)``. Empty
    (largest below 1 px) for a principal point at or left of / above the image origin."""
    (off_x, off_y) = MAX_PRINCIPAL_POINT_OFFSET
    return (
        (camera.c_x / (0.5 + off_x), camera.c_x / (0.5 - off_x)),
        (camera.c_y / (0.5 + off_y), camera.c_y / (0.5 - off_y)),
    )


def check_implied_image(camera: Camera) -> None:
    """Fail when no image fits ``camera`` (its size unknown): a principal point that lies in
    no image of a whole number of pixels near whose centre it can be
    (:func:`implied_image_sizes`; ``c_y`` = 0, −1 or 1e-320: no such image), or a focal
    length that gives every image the principal point allows a horizontal field of view
    outside :data:`FIELD_OF_VIEW_RANGE_DEG`.

    Raises:
        ConfigurationError: naming the value and, where it helps, the sizes it allows.
    """
    widths, heights = implied_image_sizes(camera)
    (off_x, off_y) = MAX_PRINCIPAL_POINT_OFFSET
    for name, c, (low, high), off, edge, side in (
        ("c_x", camera.c_x, widths, off_x, "left", "width"),
        ("c_y", camera.c_y, heights, off_y, "top", "height"),
    ):
        if math.floor(high) >= max(1, math.ceil(low)):
            continue
        if c <= 0:
            what = f"is on or beyond the {edge} edge of any image"
        else:
            what = f"fits only images under a pixel in {side}"
        raise ConfigurationError(
            f"principal point {name} = {c:g} px {what} (without an image size, --image-size "
            f"WxH, the images are those the principal point lies near the centre of: within "
            f"{off:.0%} of their {side}); is the calibration broken?"
        )
    fovs = [math.degrees(2.0 * math.atan(w / (2.0 * camera.f))) for w in widths]
    lo, hi = FIELD_OF_VIEW_RANGE_DEG
    if fovs[1] < lo or fovs[0] > hi:
        raise ConfigurationError(
            f"focal length f = {camera.f:g} px fits no image of principal point c_x = "
            f"{camera.c_x:g} px: the {widths[0]:.0f}..{widths[1]:.0f} px wide images it allows "
            f"would see {fovs[0]:.3g}..{fovs[1]:.3g}°, outside {lo:g}..{hi:g}°"
        )


def check_box_frames(box_frames: NDArray[np.int64], frames: FrameSource) -> None:
    """Fail when the box frame indices ``box_frames`` are those of ``frames`` counted from one
    more: every box after the first frame and boxes one past the last (frame numbers counted
    from 1 against files or a video counted from 0). Each box would meet the frame before its
    own; only an image folder, whose indices are exact, is checked.

    Raises:
        DataMismatchError: naming both ranges.
    """
    if not isinstance(frames, ImageFolderSource) or not len(box_frames):
        return
    low, high = int(np.min(box_frames)), int(np.max(box_frames))
    if low > frames.first and high == frames.last + 1:
        raise DataMismatchError(
            f"the boxes refer to frames {low}..{high} but {frames.path} has frames "
            f"{frames.first}..{frames.last}: are the boxes' frames counted from 1? Number them as "
            "the frame files are numbered (each box would meet the frame before its own)"
        )


def resolution_hint(camera: Camera, width: int, height: int) -> str:
    """The likely cause of a principal point that does not fit ``width × height`` px images:
    a calibration made at another resolution, about ``2·c_x × 2·c_y`` px (a calibration's
    principal point lies near its images' centre); empty when that is no image or is the
    frames' own size."""
    implied = (round(2.0 * camera.c_x), round(2.0 * camera.c_y))
    if min(implied) < 1 or implied == (width, height):
        return ""
    return (
        "the calibration is probably for another resolution (about "
        f"{implied[0]}×{implied[1]} px = 2·c_x × 2·c_y); give the calibration for these "
        "frames, or resize the frames to it"
    )


def check_calibration(camera: Camera, width: int, height: int, where: str = "frames") -> None:
    """Fail when ``camera`` cannot belong to images of ``width × height`` pixels.

    Checks the image size the camera knows (if any), that the principal point lies inside the
    image and that it is within :data:`MAX_PRINCIPAL_POINT_OFFSET` of the image centre, and
    that the focal length gives a horizontal field of view within
    :data:`FIELD_OF_VIEW_RANGE_DEG`.

    Raises:
        DataMismatchError: naming the sizes, the offending value and, for a principal point,
            the likely cause (:func:`resolution_hint`).
    """
    if (
        camera.image_width is not None
        and camera.image_height is not None
        and ((camera.image_width, camera.image_height) != (width, height))
    ):
        raise DataMismatchError(
            f"{where}: images are {width}×{height} px but the calibration is for "
            f"{camera.image_width}×{camera.image_height} px"
        )
    hint = resolution_hint(camera, width, height)
    for name, c, size, offset in (
        ("c_x", camera.c_x, width, MAX_PRINCIPAL_POINT_OFFSET[0]),
        ("c_y", camera.c_y, height, MAX_PRINCIPAL_POINT_OFFSET[1]),
    ):
        if not 0.0 <= c <= size:
            raise DataMismatchError(
                f"{where}: the calibration's principal point {name} = {c:.1f} px lies outside "
                f"the {width}×{height} px images; "
                f"{hint or 'does the calibration belong to these frames?'}"
            )
        if abs(c - size / 2) > offset * size:
            raise DataMismatchError(
                f"{where}: the calibration's principal point {name} = {c:.1f} px is far from the "
                f"centre ({size / 2:.1f} px) of the {width}×{height} px images; "
                f"{hint or 'were the frames resized or cropped after calibration?'}"
            )
    fov = math.degrees(2.0 * math.atan(width / (2.0 * camera.f)))
    lo, hi = FIELD_OF_VIEW_RANGE_DEG
    if not lo <= fov <= hi:
        raise DataMismatchError(
            f"{where}: the calibration's focal length f = {camera.f:g} px gives the "
            f"{width} px wide images a field of view of {fov:.1f}°, outside {lo:g}..{hi:g}°; "
            "does the calibration belong to these frames?"
        )


class _Timing:
    """Timestamp of a frame index from a frame rate or a timestamps array."""

    def __init__(
        self, fps: float, timestamps_s: NDArray[np.float64] | None, timestamps_name: str
    ) -> None:
        if not (math.isfinite(fps) and fps > 0):
            raise ConfigurationError(f"frame rate must be > 0 frames per second, got {fps}")
        self.fps = fps
        self.timestamps_s = timestamps_s
        self.timestamps_name = timestamps_name

    def __call__(self, index: int) -> float:
        if self.timestamps_s is None:
            return index / self.fps
        if index >= len(self.timestamps_s):
            raise DataMismatchError(
                f"{self.timestamps_name} has {len(self.timestamps_s)} timestamps, but there is a "
                f"frame {index}"
            )
        return float(self.timestamps_s[index])


class _SizeCheck:
    """Marks frames whose size differs from the first readable frame's."""

    def __init__(self) -> None:
        self.size: tuple[int, int] | None = None

    def __call__(self, image: np.ndarray) -> str:
        size = (int(image.shape[1]), int(image.shape[0]))
        if self.size is None:
            self.size = size
            return ""
        if size != self.size:
            return (
                f"image is {size[0]}×{size[1]} px, the first frame was "
                f"{self.size[0]}×{self.size[1]} px"
            )
        return ""


def _as_bgr(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    if image.ndim == 2:
        return np.asarray(cv2.cvtColor(image, cv2.COLOR_GRAY2BGR))
    if image.shape[2] == 4:
        return np.asarray(cv2.cvtColor(image, cv2.COLOR_BGRA2BGR))
    return image


class ImageFolderSource:
    """Frames from the image files of a folder (see the module docstring for numbering).

    Args:
        path: the folder.
        fps: frames per second used for timestamps when no timestamps file is given
            (:data:`DEFAULT_FPS` when None).
        timestamps_s: one timestamp per frame index, seconds (e.g. from :func:`read_timestamps`).
        timestamps_name: where the timestamps came from, for messages.
        max_pixels: frames whose header claims more pixels are not decoded (status
            ``unreadable``; :meth:`frame_size` raises).

    Attributes:
        skipped: ``(file name, reason)`` of the image files that are not frames (see
            :func:`~slopedist.io.framefiles.list_frame_files`).

    Raises:
        MissingInputError: the folder does not exist or holds no image files.
        InputFileError: two files with the same frame number, or a huge gap.
        DataMismatchError: fewer timestamps than frames.
    """

    def __init__(
        self,
        path: str | Path,
        fps: float | None = None,
        timestamps_s: NDArray[np.float64] | None = None,
        timestamps_name: str = "timestamps",
        max_pixels: int = DEFAULT_MAX_PIXELS,
    ) -> None:
        self.path = Path(path)
        listing = list_frame_files(self.path)
        self.files = listing.files
        self.numbered = listing.numbered
        self.skipped = listing.skipped
        self.max_pixels = max_pixels
        self.timing = _Timing(DEFAULT_FPS if fps is None else fps, timestamps_s, timestamps_name)
        self.first = min(self.files)
        self.last = max(self.files)
        if timestamps_s is not None and len(timestamps_s) <= self.last:
            raise DataMismatchError(
                f"{timestamps_name} has {len(timestamps_s)} timestamps, but {self.path} has "
                f"frames up to {self.last}"
            )

    def expected_frames(self) -> int:
        return self.last - self.first + 1

    def frame_size(self) -> tuple[int, int]:
        """Size of the first readable frame, from its header when it is a PNG or JPEG.

        Raises:
            InputFileError: that frame is over ``max_pixels`` or damaged, or no file decodes.
        """
        for k in sorted(self.files):
            path = self.files[k]
            problem = image_size_problem(path, self.max_pixels)
            if problem:
                raise InputFileError(path, f"not decoded: {problem}")
            size = header_image_size(path)
            if size is not None:
                return size
            with utf8_name(path) as name:
                image = cv2.imread(name, cv2.IMREAD_UNCHANGED)
            if image is not None:
                return int(image.shape[1]), int(image.shape[0])
        raise InputFileError(self.path, "none of the image files could be read")

    def __iter__(self) -> Iterator[Frame]:
        size_check = _SizeCheck()
        for k in range(self.first, self.last + 1):
            t = self.timing(k)
            path = self.files.get(k)
            if path is None:
                yield Frame(
                    k,
                    t,
                    None,
                    FrameStatus.MISSING,
                    f"frame {k}",
                    f"no image file numbered {k} in {self.path}",
                )
                continue
            problem = image_size_problem(path, self.max_pixels)
            image = None if problem else read_colour(path)
            if image is None:
                yield Frame(
                    k,
                    t,
                    None,
                    FrameStatus.UNREADABLE,
                    path.name,
                    f"{path}: not decoded: {problem}"
                    if problem
                    else f"{path} could not be decoded as an image",
                )
                continue
            problem = size_check(image)
            if problem:
                yield Frame(k, t, None, FrameStatus.SIZE_CHANGED, path.name, f"{path}: {problem}")
                continue
            yield Frame(k, t, _as_bgr(np.asarray(image)), FrameStatus.OK, path.name)


class VideoSource:
    """Frames decoded from a video file with OpenCV (``cv2.VideoCapture``).

    Args:
        path: the video file.
        fps: frames per second for timestamps; None uses the container's frame rate (or
            :data:`DEFAULT_FPS` when the container reports none).
        timestamps_s: one timestamp per frame, seconds; overrides ``fps``.
        max_pixels: largest frame accepted, pixels (the container's announced size is checked
            before any frame is decoded).

    Raises:
        MissingInputError: no such file.
        InputFileError: the file cannot be opened as a video, or its frames are over
            ``max_pixels``.
    """

    def __init__(
        self,
        path: str | Path,
        fps: float | None = None,
        timestamps_s: NDArray[np.float64] | None = None,
        timestamps_name: str = "timestamps",
        max_pixels: int = DEFAULT_MAX_PIXELS,
    ) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise MissingInputError(f"video file not found: {self.path}")
        cap = self._open()
        try:
            self.container_fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
            count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
            width = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH) or 0)
            height = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT) or 0)
        finally:
            cap.release()
        if width * height > max_pixels:
            raise InputFileError(
                self.path,
                f"its frames are {width}×{height} px, over the limit of {max_pixels / 1e6:g} Mpx",
            )
        self.frame_count = count if count > 0 else None
        if fps is None:
            fps = (
                self.container_fps
                if (math.isfinite(self.container_fps) and self.container_fps > 0)
                else DEFAULT_FPS
            )
        self.timing = _Timing(fps, timestamps_s, timestamps_name)

    def _open(self) -> cv2.VideoCapture:
        with utf8_name(self.path) as name:  # (OpenCV keeps the file it opened)
            cap = cv2.VideoCapture(name)
        if not cap.isOpened():
            cap.release()
            raise InputFileError(
                self.path,
                "cannot be opened as a video (not a video file, or a codec OpenCV "
                "lacks); give a video file or a folder of PNG/JPG frames",
            )
        return cap

    def expected_frames(self) -> int | None:
        return self.frame_count

    def frame_size(self) -> tuple[int, int]:
        cap = self._open()
        try:
            ok, image = cap.read()
        finally:
            cap.release()
        if not ok or image is None:
            raise InputFileError(self.path, "the video has no decodable frame")
        return int(image.shape[1]), int(image.shape[0])

    def __iter__(self) -> Iterator[Frame]:
        cap = self._open()
        size_check = _SizeCheck()
        try:
            k = 0
            while True:
                ok, image = cap.read()
                name = f"{self.path.name}#{k}"
                if not ok or image is None:
                    if self.frame_count is not None and k < self.frame_count:
                        yield Frame(
                            k,
                            self.timing(k),
                            None,
                            FrameStatus.UNREADABLE,
                            name,
                            f"decoding stopped at frame {k} of the {self.frame_count} "
                            "the container announces",
                        )
                    return
                t = self.timing(k)
                problem = size_check(image)
                if problem:
                    yield Frame(k, t, None, FrameStatus.SIZE_CHANGED, name, problem)
                else:
                    yield Frame(k, t, _as_bgr(np.asarray(image)), FrameStatus.OK, name)
                k += 1
        finally:
            cap.release()


def open_frames(
    path: str | Path,
    fps: float | None = None,
    timestamps: str | Path | None = None,
    max_pixels: int = DEFAULT_MAX_PIXELS,
) -> ImageFolderSource | VideoSource:
    """A folder of images or a video file, chosen by what ``path`` is.

    Args:
        path: image folder or video file.
        fps: frames per second (None: 10 for folders, the container's rate for videos).
        timestamps: optional timestamps file (:func:`read_timestamps`); overrides ``fps``.
        max_pixels: largest frame decoded, pixels.

    Example:
        >>> import pathlib, tempfile
        >>> folder = pathlib.Path(tempfile.mkdtemp())
        >>> for k in range(3):
        ...     _ = cv2.imwrite(str(folder / f"{k:06d}.png"), np.zeros((4, 6, 3), np.uint8))
        >>> [(f.index, f.timestamp_s, f.image.shape) for f in open_frames(folder, fps=5)]
        [(0, 0.0, (4, 6, 3)), (1, 0.2, (4, 6, 3)), (2, 0.4, (4, 6, 3))]
    """
    path = Path(path)
    ts = read_timestamps(timestamps) if timestamps is not None else None
    name = str(timestamps) if timestamps is not None else "timestamps"
    if path.is_dir():
        return ImageFolderSource(path, fps, ts, name, max_pixels)
    if path.is_file():
        return VideoSource(path, fps, ts, name, max_pixels)
    raise MissingInputError(f"frames not found: {path} (expected an image folder or a video file)")
