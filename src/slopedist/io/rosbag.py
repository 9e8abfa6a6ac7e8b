"""Drive logs as frame sources: ROS 1 bags, ROS 2 bags (sqlite3 or MCAP storage), bare ``.mcap``.

Read with the pure-Python ``rosbags`` package (optional extra ``rosbag``; no ROS installation).

Convention: images are BGR ``H×W×3`` uint8; frame times are the image messages' header stamps,
in seconds after the first image's stamp (:attr:`LogFrameSource.t0_ns` keeps that origin in
nanoseconds, for other topics of the same log).

Frame numbering: frame ``k`` is the ``k``-th slot of the nominal frame period ``T`` (the
``fps`` given, or the median of the first stamp differences). A stamp step of more than
:data:`GAP_FACTOR` × ``T`` is a gap: the skipped slots are yielded as frames of status
``missing`` (as a gap in a numbered image folder), so the indices of the frames after it stay
those of a recording without drops. A stamp that does not increase (out of order or repeated)
gives a frame of status ``unreadable`` whose detail names both stamps; it keeps the next index.

Image encodings: ``sensor_msgs/Image`` in ``bgr8``, ``rgb8``, ``bgra8``, ``rgba8``, ``mono8``,
``mono16`` (high byte kept) and ``bayer_{rggb,bggr,gbrg,grbg}8`` (OpenCV demosaicing);
``sensor_msgs/CompressedImage`` in any format ``cv2.imdecode`` reads (JPEG, PNG). Other
encodings give ``unreadable`` frames naming the encoding.
"""

from __future__ import annotations

import sqlite3
import statistics
import struct
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import (
    ConfigurationError,
    InputFileError,
    MissingInputError,
    OptionalDependencyError,
)
from slopedist.io.frames import Frame, FrameStatus
from slopedist.io.mcap_log import LostMessage, McapError, McapLog

IMAGE_TYPE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE_TYPE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"
IMAGE_TYPES = (IMAGE_TYPE, COMPRESSED_IMAGE_TYPE)

GAP_FACTOR = 1.5
"""A stamp step longer than this many nominal frame periods is a gap (missing frames)."""

PERIOD_SAMPLES = 9
"""Stamp differences whose median is the nominal frame period when no ``fps`` is given."""

LOG_SUFFIXES = (".bag", ".mcap", ".db3")
"""File endings read as logs (a folder with a ``metadata.yaml`` is a ROS 2 bag)."""

_BAYER = {
    "bayer_rggb8": cv2.COLOR_BayerBG2BGR,
    "bayer_bggr8": cv2.COLOR_BayerRG2BGR,
    "bayer_gbrg8": cv2.COLOR_BayerGR2BGR,
    "bayer_grbg8": cv2.COLOR_BayerGB2BGR,
}
# ROS names a Bayer pattern by the first row's first two pixels, OpenCV by the second row's
# second and third (cv_bridge's table), hence RGGB → OpenCV's "BG".
_CHANNELS = {"bgr8": 3, "rgb8": 3, "bgra8": 4, "rgba8": 4, "mono8": 1, "8uc1": 1, "8uc3": 3}
_TO_BGR = {
    "rgb8": cv2.COLOR_RGB2BGR,
    "bgra8": cv2.COLOR_BGRA2BGR,
    "rgba8": cv2.COLOR_RGBA2BGR,
    "mono8": cv2.COLOR_GRAY2BGR,
    "8uc1": cv2.COLOR_GRAY2BGR,
}


ROS2_STORAGE_SUFFIXES = (".mcap", ".db3")
"""File endings of a ROS 2 bag folder's storage files."""

REPAIR_HINTS = {
    ".mcap": "a truncated MCAP (its recorder stopped without closing it?) is repaired with: "
    "mcap recover {path} -o repaired.mcap",
    ".bag": "a ROS 1 bag without its index (its recorder stopped without closing it?) is "
    "repaired with: rosbag reindex {path}",
}
"""How to repair a log that does not open, by its file ending."""


def is_log_path(path: str | Path) -> bool:
    """True for a ``.bag`` / ``.mcap`` / ``.db3`` file or a ROS 2 bag folder (``metadata.yaml``)."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix.lower() in LOG_SUFFIXES


def storage_files(folder: Path) -> list[Path]:
    """The ROS 2 storage files (``.mcap``, ``.db3``; not hidden) in ``folder``: a folder with
    such files but no ``metadata.yaml`` is a ROS 2 bag its recorder did not close."""
    return sorted(
        p
        for p in folder.iterdir()
        if p.suffix.lower() in ROS2_STORAGE_SUFFIXES and not p.name.startswith(".")
    )


def _anyreader() -> Any:
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise OptionalDependencyError(
            "rosbags", "rosbag", "reading ROS bags and MCAP logs"
        ) from exc
    return AnyReader, get_typestore(Stores.ROS2_HUMBLE)


@contextmanager
def open_log(path: str | Path) -> Iterator[Any]:
    """An open ``rosbags.highlevel.AnyReader`` on ``path`` (message types from the log, ROS 2
    Humble's when the log carries none).

    Raises:
        MissingInputError: no such file or folder.
        InputFileError: not a readable ROS 1 / ROS 2 log.
    """
    path = Path(path)
    if not path.exists():
        raise MissingInputError(f"log not found: {path}")
    if path.is_dir() and not (path / "metadata.yaml").is_file():
        files = storage_files(path)
        if not files:
            raise InputFileError(
                path,
                "not a log: a folder with neither a ROS 2 bag's metadata.yaml nor a storage "
                "file (.db3, .mcap); give a ROS 1 .bag, a .mcap / .db3 file or a ROS 2 bag folder",
            )
        raise InputFileError(
            path,
            "a ROS 2 bag folder without metadata.yaml (its recorder stopped without closing "
            f"it?): give a storage file itself ({files[0] if files else 'NAME.db3'}), or "
            f"rebuild metadata.yaml with: ros2 bag reindex {path}",
        )
    mcap = mcap_storage(path)
    if mcap is not None:
        with _open_mcap(path, mcap) as log:
            yield log
        return
    any_reader, typestore = _anyreader()
    try:
        reader = any_reader([path], default_typestore=typestore)
        reader.open()
    except log_errors() as exc:
        hint = REPAIR_HINTS.get(path.suffix.lower(), "").format(path=path)
        raise InputFileError(
            path,
            f"not a readable ROS 1 / ROS 2 log: {str(exc).rstrip('.')}"
            + (f"; {hint}" if hint else ""),
        ) from None
    try:
        yield reader
    finally:
        reader.close()


def mcap_storage(path: Path) -> Path | None:
    """The MCAP file read for ``path``: itself (a ``.mcap`` file), or the one storage file of
    a ROS 2 bag folder when that is an MCAP file; None for other logs (ROS 1, sqlite3, a bag
    of several files), which rosbags reads."""
    if path.is_file():
        return path if path.suffix.lower() == ".mcap" else None
    files = storage_files(path) if path.is_dir() else []
    if len(files) == 1 and files[0].suffix.lower() == ".mcap":
        return files[0]
    return None


@contextmanager
def _open_mcap(path: Path, storage: Path) -> Iterator[McapLog]:
    """An open :class:`~slopedist.io.mcap_log.McapLog` of ``storage`` (the file of the log
    ``path``), read as far as it is whole.

    Raises:
        InputFileError: not an MCAP file, or no channel of it is readable.
    """
    _anyreader()  # the message types come from rosbags: say so when it is missing
    log = McapLog(storage)
    try:
        log.open()
    except (McapError, OSError, struct.error) as exc:
        log.close()
        raise InputFileError(path, f"not a readable ROS 2 log: {exc}") from None
    try:
        if not log.connections:
            hint = REPAIR_HINTS[".mcap"].format(path=storage)
            raise InputFileError(
                path, f"not a readable ROS 2 log: {log.end or 'it has no channel'}; {hint}"
            )
        yield log
    finally:
        log.close()


def log_errors() -> tuple[type[BaseException], ...]:
    """What ``rosbags`` and its storage back ends raise on a damaged log (corrupt or truncated
    file, a message that does not deserialise); rosbags checks some of its formats with
    ``assert``, hence ``AssertionError``."""
    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as Reader1Error
    from rosbags.rosbag2 import ReaderError as Reader2Error

    errors: list[type[BaseException]] = [
        AnyReaderError,
        Reader1Error,
        Reader2Error,
        KeyError,
        ValueError,
        IndexError,
        EOFError,
        AssertionError,
        OverflowError,
        struct.error,
        sqlite3.Error,
    ]
    try:
        import apsw  # rosbags' sqlite3 back end

        errors.append(apsw.Error)
    except ImportError:
        pass
    return tuple(errors)


def iter_messages(
    reader: Any, connections: list[Any], path: Path, lost: bool = False
) -> Iterator[tuple[Any, int, Any]]:
    """``(connection, log time ns, raw bytes)`` of ``connections`` in log-time order (an MCAP
    file's in file order, see :mod:`slopedist.io.mcap_log`); with ``lost``, also the messages
    of a damaged part of an MCAP log, with a :class:`~slopedist.io.mcap_log.LostMessage` for
    bytes (without, they are left out: the log has warned of them).

    Raises:
        InputFileError: the log is damaged (naming the file and how many messages were read).
    """
    messages = reader.messages(connections=connections)
    errors = log_errors()
    count = 0
    while True:
        try:
            item = next(messages)
        except StopIteration:
            return
        except errors as exc:
            raise InputFileError(path, f"log damaged after {count} messages: {exc}") from None
        if isinstance(item[2], LostMessage) and not lost:
            continue
        count += 1
        yield item


def connections_of(reader: Any, topic: str, types: tuple[str, ...], path: Path) -> list[Any]:
    """The connections of ``topic``, which must carry one of ``types``.

    Raises:
        ConfigurationError: no such topic (the message lists the topics there are), or another
            message type.
    """
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        have = ", ".join(sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections}))
        raise ConfigurationError(f"{path} has no topic {topic}; its topics: {have or 'none'}")
    bad = sorted({c.msgtype for c in conns if c.msgtype not in types})
    if bad:
        raise ConfigurationError(
            f"topic {topic} in {path} carries {', '.join(bad)}; expected {' or '.join(types)}"
        )
    return conns


def deserialize(reader: Any, raw: Any, msgtype: str, path: Path, topic: str) -> Any:
    """One message; a message that does not deserialise → :class:`InputFileError`."""
    try:
        return reader.deserialize(raw, msgtype)
    except log_errors() as exc:
        raise InputFileError(path, f"message does not deserialise: {exc}", field=topic) from None


def stamp_ns(msg: Any) -> int:
    """Header stamp of a message, integer nanoseconds."""
    stamp = msg.header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def decode_image(msg: Any) -> tuple[NDArray[np.uint8] | None, str]:
    """``(BGR image, "")`` from a ``sensor_msgs`` Image or CompressedImage, or ``(None, why)``."""
    if hasattr(msg, "format"):  # CompressedImage
        buf = np.frombuffer(memoryview(msg.data), dtype=np.uint8)
        image = cv2.imdecode(buf, cv2.IMREAD_COLOR) if buf.size else None
        if image is None:
            return None, f"compressed image ({msg.format or 'no format'}) does not decode"
        return np.asarray(image, dtype=np.uint8), ""
    return _raw_image(msg)


def _raw_image(msg: Any) -> tuple[NDArray[np.uint8] | None, str]:
    enc = str(msg.encoding).lower()
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.frombuffer(memoryview(msg.data), dtype=np.uint8)
    if enc == "mono16" or enc == "16uc1":
        if data.size < h * step or step < 2 * w:
            return None, f"{enc} image of {w}×{h} px has {data.size} bytes (step {step})"
        rows = data[: h * step].reshape(h, step)[:, : 2 * w]
        words = rows.view(">u2" if msg.is_bigendian else "<u2")
        return np.asarray(cv2.cvtColor((words >> 8).astype(np.uint8), cv2.COLOR_GRAY2BGR)), ""
    channels = 1 if enc in _BAYER else _CHANNELS.get(enc)
    if channels is None:
        return None, f"image encoding '{msg.encoding}' is not supported"
    if data.size < h * step or step < channels * w:
        return None, f"{enc} image of {w}×{h} px has {data.size} bytes (step {step})"
    rows = data[: h * step].reshape(h, step)[:, : channels * w]
    image = rows.reshape(h, w, channels) if channels > 1 else rows
    if enc in _BAYER:
        return np.asarray(cv2.cvtColor(np.ascontiguousarray(image), _BAYER[enc])), ""
    if enc in _TO_BGR:
        return np.asarray(cv2.cvtColor(np.ascontiguousarray(image), _TO_BGR[enc])), ""
    return np.ascontiguousarray(image), ""


def stamp_text(stamp: int) -> str:
    """A header stamp (ns) as seconds with all nine decimals, as in messages (exact: a float
    of a stamp since 1970 keeps no nanoseconds)."""
    return f"{stamp // 10**9}.{stamp % 10**9:09d} s"


class _Slots:
    """Frame index of each stamp: slots of the nominal period, gaps and non-increasing stamps."""

    def __init__(self, period_ns: float | None) -> None:
        self.period_ns = period_ns
        self.diffs: list[int] = []
        self.last_ns: int | None = None
        self.index = -1

    def period(self) -> float | None:
        if self.period_ns is not None:
            return self.period_ns
        return statistics.median(self.diffs) if self.diffs else None

    def place(self, t_ns: int) -> tuple[int, int, str]:
        """``(first skipped index, index of this frame, problem)`` for the stamp ``t_ns``."""
        first_skipped = self.index + 1
        if self.last_ns is None:
            self.last_ns, self.index = t_ns, 0
            return 0, 0, ""
        step = t_ns - self.last_ns
        if step <= 0:
            self.index += 1
            return (
                self.index,
                self.index,
                (
                    f"header stamp {stamp_text(t_ns)} does not increase (the frame before has "
                    f"{stamp_text(self.last_ns)})"
                ),
            )
        period = self.period()
        slots = 1
        if period is not None and step > GAP_FACTOR * period:
            slots = max(round(step / period), 1)
        elif len(self.diffs) < PERIOD_SAMPLES:
            self.diffs.append(step)
        self.index += slots
        self.last_ns = t_ns
        return first_skipped, self.index, ""


class LogFrameSource:
    """Frames of one image topic of a drive log (see the module docstring).

    Args:
        path: ``.bag`` file (ROS 1), ROS 2 bag folder, ``.db3`` or ``.mcap`` file.
        image_topic: topic of ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage``.
        fps: nominal frames per second (None: from the median of the first stamp steps).

    Raises:
        MissingInputError / InputFileError: see :func:`open_log`; also a topic without messages.
        ConfigurationError: no such topic, or not an image topic.
    """

    def __init__(self, path: str | Path, image_topic: str, fps: float | None = None) -> None:
        self.path = Path(path)
        self.image_topic = image_topic
        if fps is not None and not fps > 0:
            raise ConfigurationError(f"frame rate must be > 0 frames per second, got {fps}")
        self.period_ns = None if fps is None else 1e9 / fps
        with open_log(self.path) as reader:
            conns = connections_of(reader, image_topic, IMAGE_TYPES, self.path)
            self.message_count = sum(int(c.msgcount) for c in conns)
            first = next(self._messages(reader), None)
        if first is None:
            raise InputFileError(self.path, f"topic {image_topic} has no messages")
        self.t0_ns = first[0]

    def _messages(
        self, reader: Any, spans: list[tuple[int, int, str]] | None = None
    ) -> Iterator[tuple[int, Any, str]]:
        """``(stamp ns, message or None, why not)`` of the image messages: the header stamp, or
        the log time for unstamped messages and those that do not deserialise. A message of a
        damaged part of an MCAP log (:class:`~slopedist.io.mcap_log.LostMessage`) gets its
        log time moved by the stamp offset of the message before it; a damaged part whose
        messages are not known one by one adds ``(first stamp, last stamp, why)`` to
        ``spans`` instead."""
        conns = [c for c in reader.connections if c.topic == self.image_topic]
        errors = log_errors()
        offset = 0  # header stamp − log time of the last message that had both
        for conn, log_ns, raw in iter_messages(reader, conns, self.path, lost=True):
            if isinstance(raw, LostMessage):
                why = f"in a damaged part of the log: {raw.why}"
                if raw.until_ns is None:
                    yield int(log_ns) + offset, None, why
                elif spans is not None:
                    spans.append((int(log_ns) + offset, int(raw.until_ns) + offset, why))
                continue
            try:
                msg = reader.deserialize(raw, conn.msgtype)
            except errors as exc:
                yield int(log_ns), None, f"message does not deserialise: {exc}"
                continue
            try:
                stamp = stamp_ns(msg)
            except AttributeError:
                yield int(log_ns), None, "message has no header (damaged type definition?)"
                continue
            offset = stamp - int(log_ns) if stamp else offset
            yield stamp or int(log_ns), msg, ""

    def expected_frames(self) -> int:
        """Image messages on the topic (missing slots of gaps not counted)."""
        return self.message_count

    def frame_size(self) -> tuple[int, int]:
        """``(width, height)`` of the first image that decodes.

        Raises:
            InputFileError: none decodes (naming why the first one does not).
        """
        first_why = ""
        with open_log(self.path) as reader:
            for _, msg, problem in self._messages(reader):
                image, why = decode_image(msg) if msg is not None else (None, problem)
                if image is not None:
                    return int(image.shape[1]), int(image.shape[0])
                first_why = first_why or f" (message 0: {why})"
        raise InputFileError(self.path, f"no image on {self.image_topic} decodes{first_why}")

    def seconds(self, t_ns: int) -> float:
        """Log time ``t_ns`` (nanoseconds) → frame time, seconds after the first image."""
        return (t_ns - self.t0_ns) / 1e9

    def __iter__(self) -> Iterator[Frame]:
        slots = _Slots(self.period_ns)
        size: tuple[int, int] | None = None
        spans: list[tuple[int, int, str]] = []
        with open_log(self.path) as reader:
            messages = self._messages(reader, spans)
            while True:
                try:
                    t_ns, msg, problem = next(messages)
                except StopIteration:
                    return
                except InputFileError as exc:  # damaged from here on: say so and stop
                    k = slots.index + 1
                    t = self.seconds(slots.last_ns or self.t0_ns) + (slots.period() or 0) / 1e9
                    yield Frame(
                        k, t, None, FrameStatus.UNREADABLE, f"{self.image_topic}#{k}", str(exc)
                    )
                    return
                skipped, k, order_problem = slots.place(t_ns)
                yield from self._gap(skipped, k, slots, t_ns, spans)
                frame = self._frame(k, t_ns, msg, problem or order_problem, size)
                if size is None and frame.image is not None:
                    size = (int(frame.image.shape[1]), int(frame.image.shape[0]))
                yield frame

    def _frame(
        self, k: int, t_ns: int, msg: Any, problem: str, size: tuple[int, int] | None
    ) -> Frame:
        """Frame ``k`` from its message (``problem``: why it is unusable, "" if it is not)."""
        name, t = f"{self.image_topic}#{k}", self.seconds(t_ns)
        if problem or msg is None:
            return Frame(k, t, None, FrameStatus.UNREADABLE, name, problem)
        try:
            image, why = decode_image(msg)
        except AttributeError as exc:
            image, why = None, f"message lacks an image field ({exc}); damaged type definition?"
        if image is None:
            return Frame(k, t, None, FrameStatus.UNREADABLE, name, why)
        this = (int(image.shape[1]), int(image.shape[0]))
        if size is not None and this != size:
            why = f"image is {this[0]}×{this[1]} px, the first was {size[0]}×{size[1]} px"
            return Frame(k, t, None, FrameStatus.SIZE_CHANGED, name, why)
        return Frame(k, t, image, FrameStatus.OK, name)

    def _gap(
        self, first: int, k: int, slots: _Slots, t_ns: int, spans: list[tuple[int, int, str]]
    ) -> Iterator[Frame]:
        """The frames ``first..k−1`` of a stamp gap before frame ``k`` (at ``t_ns``):
        ``missing``, or ``unreadable`` where a damaged part of the log (``spans``) lay."""
        period = slots.period() or 0.0
        for j in range(first, k):
            j_ns = round(t_ns - (k - j) * period)
            name = f"{self.image_topic}#{j}"
            why = next((w for a, b, w in spans if a - period / 2 <= j_ns <= b + period / 2), "")
            if why:
                yield Frame(j, self.seconds(j_ns), None, FrameStatus.UNREADABLE, name, why)
                continue
            yield Frame(
                j,
                self.seconds(j_ns),
                None,
                FrameStatus.MISSING,
                name,
                f"no message on {self.image_topic} for this frame (stamp gap)",
            )


@dataclass(frozen=True)
class LogTopic:
    """One topic of a log: name, message type, message count, first and last log time (ns)."""

    topic: str
    msgtype: str
    count: int
    first_ns: int
    last_ns: int

    @property
    def span_s(self) -> float:
        """Seconds from the first to the last message."""
        return (self.last_ns - self.first_ns) / 1e9

    @property
    def rate_hz(self) -> float:
        """Mean message rate, messages per second (NaN with fewer than two messages)."""
        span = self.span_s
        return (self.count - 1) / span if self.count > 1 and span > 0 else float("nan")


def log_topics(path: str | Path) -> list[LogTopic]:
    """Every topic of a log with its type, message count and log-time span (sorted by name)."""
    path = Path(path)
    with open_log(path) as reader:
        first: dict[str, int] = {}
        last: dict[str, int] = {}
        count: dict[str, int] = {}
        types = {c.topic: c.msgtype for c in reader.connections}
        for conn, t_ns, _ in iter_messages(reader, list(reader.connections), path):
            first.setdefault(conn.topic, t_ns)
            last[conn.topic] = t_ns
            count[conn.topic] = count.get(conn.topic, 0) + 1
    return [
        LogTopic(topic, types[topic], count.get(topic, 0), first.get(topic, 0), last.get(topic, 0))
        for topic in sorted(types)
    ]
