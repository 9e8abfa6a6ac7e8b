"""Writing drive logs (ROS 1 bag, ROS 2 bag with sqlite3 or MCAP storage) from frames.

For tests, benchmarks and for turning an image folder into a log that other ROS tools read:
images as ``sensor_msgs/Image`` (``bgr8``) or ``sensor_msgs/CompressedImage`` (JPEG), a
``sensor_msgs/CameraInfo`` per frame and optionally a ``sensor_msgs/Imu`` orientation and a
``nav_msgs/Odometry`` speed per frame.
Header stamps are ``start_ns`` plus the frame's time; the log time of a message is its stamp.

Convention: images BGR ``H×W×3`` uint8; orientations body-to-world quaternions x y z w in the
body frame x forward, y left, z up (see :mod:`slopedist.odometry.imu`).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError, InputFileError, OptionalDependencyError


class LogFormat(str, Enum):
    """Container of a written log."""

    ROS1 = "ros1"
    """ROS 1 bag file (``.bag``)."""
    ROS2_SQLITE3 = "ros2-sqlite3"
    """ROS 2 bag folder with sqlite3 storage."""
    ROS2_MCAP = "ros2-mcap"
    """ROS 2 bag folder with MCAP storage."""


class ImageEncoding(str, Enum):
    """How images are stored."""

    RAW = "raw"
    """``sensor_msgs/Image``, ``bgr8``."""
    JPEG = "jpeg"
    """``sensor_msgs/CompressedImage``, JPEG (quality :data:`JPEG_QUALITY`)."""
    PNG = "png"
    """``sensor_msgs/CompressedImage``, PNG (lossless)."""


JPEG_QUALITY = 95


@dataclass(frozen=True)
class LogFrame:
    """One frame to write: time after the start (ns), BGR image, optional orientation (an IMU
    message) and ego speed (m/s, forward; a ``nav_msgs/Odometry`` message)."""

    t_ns: int
    image: NDArray[np.uint8]
    orientation_xyzw: tuple[float, float, float, float] | None = None
    speed_mps: float | None = None


@dataclass(frozen=True)
class LogTopics:
    """Topic names of a written log."""

    image: str = "/camera/image_raw"
    camera_info: str = "/camera/camera_info"
    imu: str = "/imu/data"
    odometry: str = "/odom"


class _Messages:
    """Message builders of one typestore."""

    def __init__(self, ros1: bool) -> None:
        try:
            from rosbags.typesys import Stores, get_typestore
        except ImportError as exc:
            raise OptionalDependencyError("rosbags", "rosbag", "writing ROS logs") from exc
        self.ros1 = ros1
        self.store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        self.T = self.store.types

    def header(self, t_ns: int, seq: int, frame_id: str) -> Any:
        stamp = self.T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
        if self.ros1:
            return self.T["std_msgs/msg/Header"](seq=seq, stamp=stamp, frame_id=frame_id)
        return self.T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    def image(self, header: Any, image: NDArray[np.uint8], encoding: ImageEncoding) -> Any:
        if encoding is ImageEncoding.RAW:
            h, w = image.shape[:2]
            return self.T["sensor_msgs/msg/Image"](
                header=header,
                height=h,
                width=w,
                encoding="bgr8",
                is_bigendian=0,
                step=3 * w,
                data=np.ascontiguousarray(image).reshape(-1),
            )
        ext, params = (
            (".jpg", [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
            if encoding is ImageEncoding.JPEG
            else (".png", [])
        )
        ok, buf = cv2.imencode(ext, image, params)
        if not ok:
            raise InputFileError("<image>", f"could not encode a frame as {ext}")
        return self.T["sensor_msgs/msg/CompressedImage"](
            header=header, format=encoding.value, data=np.asarray(buf, dtype=np.uint8).reshape(-1)
        )

    def camera_info(self, header: Any, camera: Camera, width: int, height: int) -> Any:
        K = camera.K
        P = np.hstack([K, np.zeros((3, 1))])
        names = ("D", "K", "R", "P") if self.ros1 else ("d", "k", "r", "p")
        roi = self.T["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        )
        fields = dict(
            zip(
                names,
                (np.zeros(5), K.reshape(-1), np.eye(3).reshape(-1), P.reshape(-1)),
            )
        )
        return self.T["sensor_msgs/msg/CameraInfo"](
            header=header,
            height=height,
            width=width,
            distortion_model="plumb_bob",
            binning_x=0,
            binning_y=0,
            roi=roi,
            **fields,
        )

    def imu(self, header: Any, q: tuple[float, float, float, float]) -> Any:
        V = self.T["geometry_msgs/msg/Vector3"]
        return self.T["sensor_msgs/msg/Imu"](
            header=header,
            orientation=self.T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
            orientation_covariance=np.zeros(9),
            angular_velocity=V(x=0.0, y=0.0, z=0.0),
            angular_velocity_covariance=np.full(9, -1.0),
            linear_acceleration=V(x=0.0, y=0.0, z=9.81),
            linear_acceleration_covariance=np.full(9, -1.0),
        )

    def odometry(self, header: Any, speed_mps: float) -> Any:
        V = self.T["geometry_msgs/msg/Vector3"]
        pose = self.T["geometry_msgs/msg/Pose"](
            position=self.T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
            orientation=self.T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        )
        twist = self.T["geometry_msgs/msg/Twist"](
            linear=V(x=speed_mps, y=0.0, z=0.0), angular=V(x=0.0, y=0.0, z=0.0)
        )
        return self.T["nav_msgs/msg/Odometry"](
            header=header,
            child_frame_id="base_link",
            pose=self.T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=self.T["geometry_msgs/msg/TwistWithCovariance"](
                twist=twist, covariance=np.zeros(36)
            ),
        )

    def serialize(self, msg: Any) -> bytes:
        if self.ros1:
            return bytes(self.store.serialize_ros1(msg, msg.__msgtype__))
        return bytes(self.store.serialize_cdr(msg, msg.__msgtype__))


def _open_writer(path: Path, fmt: LogFormat) -> Any:
    if fmt is LogFormat.ROS1:
        from rosbags.rosbag1 import Writer as Writer1

        return Writer1(path)
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if fmt is LogFormat.ROS2_MCAP else StoragePlugin.SQLITE3
    return Writer(path, version=9, storage_plugin=plugin)


def write_log(
    path: str | Path,
    frames: Iterable[LogFrame],
    camera: Camera,
    fmt: LogFormat = LogFormat.ROS2_MCAP,
    encoding: ImageEncoding = ImageEncoding.RAW,
    *,
    start_ns: int = 1_317_000_000 * 10**9,
    topics: LogTopics = LogTopics(),
    frame_id: str = "camera",
) -> Path:
    """Write ``frames`` (with ``camera`` as camera_info, and an IMU message per frame that has an
    orientation) to a new log at ``path`` (a ``.bag`` file for ROS 1, a folder for ROS 2).

    Raises:
        ConfigurationError: ``path`` exists already.
    """
    path = Path(path)
    if path.exists():
        raise ConfigurationError(f"{path} exists already; not overwriting a log")
    msgs = _Messages(fmt is LogFormat.ROS1)
    with _open_writer(path, fmt) as writer:
        conns: dict[str, Any] = {}

        def put(topic: str, msg: Any, t_ns: int) -> None:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msg.__msgtype__, typestore=msgs.store)
            writer.write(conns[topic], t_ns, msgs.serialize(msg))

        for seq, frame in enumerate(frames):
            t = start_ns + int(frame.t_ns)
            header = msgs.header(t, seq, frame_id)
            h, w = frame.image.shape[:2]
            img = msgs.image(header, frame.image, encoding)
            put(topics.image, img, t)
            put(topics.camera_info, msgs.camera_info(header, camera, w, h), t)
            if frame.orientation_xyzw is not None:
                put(topics.imu, msgs.imu(msgs.header(t, seq, "imu"), frame.orientation_xyzw), t)
            if frame.speed_mps is not None:
                header = msgs.header(t, seq, "odom")
                put(topics.odometry, msgs.odometry(header, frame.speed_mps), t)
    return path
