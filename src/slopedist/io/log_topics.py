"""The other topics of a drive log: the camera's ``sensor_msgs/CameraInfo`` (its intrinsics) and
time series beside the images (IMU / odometry / pose orientations, ego speeds).

Read with :mod:`slopedist.io.rosbag`'s reader (the optional extra ``rosbag``). Stamps are the
messages' header stamps in nanoseconds.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import ConfigurationError, InputFileError
from slopedist.io.calibration import FISHEYE_MODELS, _trim
from slopedist.io.intrinsics import Intrinsics
from slopedist.io.rosbag import (
    CAMERA_INFO_TYPE,
    connections_of,
    deserialize,
    iter_messages,
    open_log,
    stamp_ns,
    stamp_text,
)


def camera_info_topic(image_topic: str) -> str:
    """The ``camera_info`` topic next to an image topic (``/cam/image_raw`` →
    ``/cam/camera_info``; ``/cam/image_raw/compressed`` → ``/cam/camera_info``)."""
    parts = image_topic.rstrip("/").split("/")
    if parts[-1] == "compressed":
        parts = parts[:-1]
    return "/".join([*parts[:-1], "camera_info"])


CAMERA_INFO_RTOL = 1e-6
"""Relative difference of a ``camera_info`` value (K, distortion) from the first message's
beyond which the calibration has changed during the log."""

CAMERA_INFO_DIST_ATOL = 1e-12
"""Absolute difference of a distortion coefficient beyond which it has changed: a coefficient
of 0 has no relative difference, and one written as 0 or 1e-17 is the same lens."""


def read_camera_info(path: str | Path, topic: str, rectified: bool = False) -> Intrinsics:
    """The intrinsics of the ``sensor_msgs/CameraInfo`` messages on ``topic``
    (:func:`intrinsics_from_info`), checked as a calibration file's are (focal length,
    principal point, lens model: :meth:`Intrinsics.check_camera`). Every message must give the
    first one's calibration (a run has one calibration).

    Raises:
        ConfigurationError: no such topic.
        InputFileError: no message, no usable calibration in it, or a later message with another
            calibration (naming the log, topic, message index and stamp).
    """
    path = Path(path)
    first: Intrinsics | None = None
    with open_log(path) as reader:
        conns = connections_of(reader, topic, (CAMERA_INFO_TYPE,), path)
        for index, (conn, _, raw) in enumerate(iter_messages(reader, conns, path)):
            msg = deserialize(reader, raw, conn.msgtype, path, topic)
            try:
                intrinsics = intrinsics_from_info(msg, rectified)
                if first is None:
                    intrinsics.check_camera()
            except (AttributeError, TypeError, ValueError, ConfigurationError) as exc:
                where = "" if first is None else f"message {index}: "
                raise InputFileError(
                    path, f"{where}not a usable CameraInfo: {exc}", field=topic
                ) from None
            if first is None:
                first = intrinsics
            elif not _same_calibration(first, intrinsics):
                stamp = stamp_ns(msg)
                raise InputFileError(
                    path,
                    f"message {index} (stamp {stamp_text(stamp)}) changes the "
                    f"calibration: {_calibration_text(intrinsics)}, the first message has "
                    f"{_calibration_text(first)}; a run has one calibration (split the log, or "
                    "give the right one with --calib)",
                    field=topic,
                )
    if first is None:
        raise InputFileError(path, f"topic {topic} has no messages")
    return first


def _same_calibration(a: Intrinsics, b: Intrinsics) -> bool:
    return (
        a.image_size == b.image_size
        and a.fisheye == b.fisheye
        and a.dist.shape == b.dist.shape
        and np.allclose(a.K, b.K, rtol=CAMERA_INFO_RTOL, atol=0.0)
        and np.allclose(a.dist, b.dist, rtol=CAMERA_INFO_RTOL, atol=CAMERA_INFO_DIST_ATOL)
    )


def _calibration_text(intrinsics: Intrinsics) -> str:
    K = intrinsics.K
    size = intrinsics.image_size
    text = f"fx {K[0, 0]:g}, fy {K[1, 1]:g}, cx {K[0, 2]:g}, cy {K[1, 2]:g}"
    if intrinsics.dist.size:
        text += f", distortion {', '.join(f'{d:g}' for d in intrinsics.dist)}"
    return text + (f", {size[0]}×{size[1]} px" if size is not None else "")


def intrinsics_from_info(msg: Any, rectified: bool) -> Intrinsics:
    """:class:`~slopedist.io.intrinsics.Intrinsics` of a CameraInfo message (ROS 1 ``K``/``D``/
    ``P`` or ROS 2 ``k``/``d``/``p``), with the message's image size.

    Images of the rectified stream (``rectified``, e.g. ``image_rect``) and cameras without
    distortion use ``P``'s left 3×3 (``K`` when ``P`` is zero) and no distortion; the raw stream
    of a distorted camera uses ``K`` and ``D`` (``equidistant`` → the fisheye model), through
    which slopedist maps the boxes (:mod:`slopedist.io.intrinsics`).
    """
    K = np.asarray(getattr(msg, "k", getattr(msg, "K", None)), dtype=float).reshape(3, 3)
    P = np.asarray(getattr(msg, "p", getattr(msg, "P", None)), dtype=float).reshape(3, 4)
    D = np.asarray(getattr(msg, "d", getattr(msg, "D", ())), dtype=float).reshape(-1)
    width, height = int(msg.width), int(msg.height)
    size = (width, height) if width > 0 and height > 0 else None
    if rectified or not np.any(D != 0):
        return Intrinsics(P[:, :3] if P[0, 0] > 0 else K, image_size=size)
    fisheye = str(msg.distortion_model).strip().lower() in FISHEYE_MODELS
    return Intrinsics(K, _trim(D, fisheye), fisheye, size)


IMU_TYPE = "sensor_msgs/msg/Imu"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped")
ORIENTATION_TYPES = (IMU_TYPE, ODOMETRY_TYPE, *POSE_TYPES)


def _orientation(msg: Any) -> list[float]:
    """x y z w of an Imu, Odometry or pose message (an IMU without orientation is refused)."""
    cov = getattr(msg, "orientation_covariance", None)
    if cov is not None and float(cov[0]) == -1.0:
        raise ValueError("the IMU reports no orientation (covariance[0] = -1)")
    if hasattr(msg, "orientation"):  # Imu
        q = msg.orientation
    else:  # Odometry, PoseWithCovarianceStamped, PoseStamped
        q = (msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose).orientation
    return [float(q.x), float(q.y), float(q.z), float(q.w)]


def _speed(msg: Any) -> list[float]:
    """The norm of the linear velocity of an Odometry or TwistStamped message, m/s."""
    twist = msg.twist.twist if hasattr(msg.twist, "twist") else msg.twist
    v = twist.linear
    return [float(np.linalg.norm([v.x, v.y, v.z]))]


def _read_series(
    path: str | Path, topic: str, types: tuple[str, ...], values: Callable[[Any], list[float]]
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Header stamps (ns, ``(N,)``) and ``values(message)`` (``(N, M)``) of every message of
    ``topic``, which must carry one of ``types``."""
    path = Path(path)
    stamps: list[int] = []
    rows: list[list[float]] = []
    with open_log(path) as reader:
        conns = connections_of(reader, topic, types, path)
        for conn, _, raw in iter_messages(reader, conns, path):
            msg = deserialize(reader, raw, conn.msgtype, path, topic)
            try:
                row = values(msg)
                stamp = stamp_ns(msg)
                if not all(np.isfinite(row)):
                    values_text = ", ".join(map(str, row))
                    raise ValueError(
                        f"stamp {stamp_text(stamp)}: a NaN or infinite value ({values_text})"
                    )
            except (AttributeError, TypeError, ValueError) as exc:
                raise InputFileError(path, f"message {len(stamps)}: {exc}", field=topic) from None
            rows.append(row)
            stamps.append(stamp)
    if not stamps:
        raise InputFileError(path, "no messages", field=topic)
    return np.asarray(stamps, dtype=np.int64), np.asarray(rows, dtype=float)


def read_orientations(
    path: str | Path, topic: str
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Header stamps (ns, ``(N,)``) and orientation quaternions (``(N, 4)``, x y z w, body-to-
    world) of ``topic``: ``sensor_msgs/Imu``, ``nav_msgs/Odometry`` or a ``geometry_msgs`` pose.

    Raises:
        ConfigurationError: no such topic or another type.
        InputFileError: no messages, or a message without an orientation (an IMU that reports
            none: covariance[0] = −1, the ``sensor_msgs/Imu`` convention) or with a NaN or
            infinite component (naming the message's index and stamp).
    """
    return _read_series(path, topic, ORIENTATION_TYPES, _orientation)


SPEED_TYPES = (ODOMETRY_TYPE, "geometry_msgs/msg/TwistStamped")


def read_speeds(path: str | Path, topic: str) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Header stamps (ns, ``(N,)``) and ego speeds (m/s, ``(N,)``: the norm of the linear
    velocity) of a ``nav_msgs/Odometry`` or ``geometry_msgs/TwistStamped`` topic.

    Raises:
        ConfigurationError: no such topic or another type.
        InputFileError: no messages, or a message without a usable velocity (NaN or infinite
            components: naming the message's index and stamp).
    """
    stamps, speeds = _read_series(path, topic, SPEED_TYPES, _speed)
    return stamps, speeds[:, 0]
