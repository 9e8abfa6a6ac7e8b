"""Any frame input of ``slopedist run``: a drive log, a video file or an image folder.

- Drive log (:func:`slopedist.io.rosbag.is_log_path`: ``.bag``, ``.mcap``, ``.db3`` or a ROS 2
  bag folder): one image topic, header stamps as frame times
  (:class:`~slopedist.io.rosbag.LogFrameSource`); its ``camera_info`` can be the calibration
  (:func:`log_calibration`), an IMU / odometry / pose topic the rotation source
  (:func:`log_rotation_source`) and an odometry / twist topic the ego speed (:func:`log_speed`).
- Video file: presentation timestamps with PyAV, OpenCV's nominal rate without it or with a
  forced ``fps`` (:func:`slopedist.io.video.open_video`).
- Image folder: :func:`~slopedist.io.frames.open_frames`.
"""

from __future__ import annotations

from pathlib import Path

from slopedist.core.camera import KITTI_CAMERA_HEIGHT_M
from slopedist.core.errors import ConfigurationError
from slopedist.io.calibration import CameraCalibration
from slopedist.io.frames import FrameSource, open_frames, read_timestamps
from slopedist.io.log_topics import (
    camera_info_topic,
    read_camera_info,
    read_orientations,
    read_speeds,
)
from slopedist.io.rosbag import (
    LogFrameSource,
    is_log_path,
    storage_files,
)
from slopedist.io.video import open_video
from slopedist.odometry.imu import SpeedTrack, TrackRotationSource, camera_rotations


def open_source(
    path: str | Path,
    fps: float | None = None,
    timestamps: str | Path | None = None,
    image_topic: str | None = None,
) -> FrameSource:
    """The frame source at ``path`` (see the module docstring).

    Args:
        path: drive log, video file or image folder.
        fps: nominal frames per second (logs: the slot period; videos: forces OpenCV's
            ``index / fps``; folders: 10 when None).
        timestamps: timestamps file for folders and videos (logs carry their own).
        image_topic: the image topic of a drive log (required for logs, refused otherwise).

    Raises:
        ConfigurationError: a log without ``image_topic``, ``image_topic`` for something else,
            or a timestamps file for a log.
        MissingInputError: nothing at ``path`` (from :func:`~slopedist.io.frames.open_frames`).
    """
    path = Path(path)
    unclosed_bag = image_topic is not None and path.is_dir() and bool(storage_files(path))
    if is_log_path(path) or unclosed_bag:
        if image_topic is None:
            raise ConfigurationError(
                f"{path} is a drive log: name its image topic with --image-topic "
                f"(list the topics with: slopedist log info {path})"
            )
        if timestamps is not None:
            raise ConfigurationError(
                "a drive log's frame times are its header stamps; --timestamps is for image "
                "folders and videos"
            )
        return LogFrameSource(path, image_topic, fps)
    if image_topic is not None:
        raise ConfigurationError(
            f"--image-topic is for drive logs (.bag, .mcap, .db3 or a ROS 2 bag folder), not {path}"
        )
    if path.is_file():
        ts = read_timestamps(timestamps) if timestamps is not None else None
        return open_video(path, fps, ts, str(timestamps or "timestamps"))
    return open_frames(path, fps, timestamps)


def log_calibration(
    source: FrameSource,
    height_m: float = KITTI_CAMERA_HEIGHT_M,
    mount_angle_rad: float = 0.0,
) -> CameraCalibration:
    """The calibration of a drive log's image topic, from the ``camera_info`` topic next to it
    (rectified intrinsics for an ``image_rect…`` topic; see
    :func:`slopedist.io.log_topics.intrinsics_from_info`); the mount in metres and radians.

    Raises:
        ConfigurationError: ``source`` is not a drive log (give a calibration file), or the log
            has no ``camera_info`` next to the image topic.
    """
    if not isinstance(source, LogFrameSource):
        raise ConfigurationError(
            f"{source.path}: a calibration file (--calib) is needed for image folders and "
            "videos (drive logs can use their camera_info topic)"
        )
    topic = camera_info_topic(source.image_topic)
    rectified = "image_rect" in source.image_topic  # image_rect, image_rect_color, …
    intrinsics = read_camera_info(source.path, topic, rectified)
    return CameraCalibration(intrinsics, intrinsics.camera(height_m, mount_angle_rad))


def log_rotation_source(source: FrameSource, topic: str) -> TrackRotationSource:
    """Camera rotations from an orientation topic of the same drive log, on the frames' time
    axis (:mod:`slopedist.odometry.imu`, KITTI's body-to-camera axes).

    Raises:
        ConfigurationError: ``source`` is not a drive log.
    """
    if not isinstance(source, LogFrameSource):
        raise ConfigurationError(f"--rotation-topic needs a drive log, not {source.path}")
    stamps_ns, quats = read_orientations(source.path, topic)
    times_s = [source.seconds(int(t)) for t in stamps_ns]
    return TrackRotationSource(camera_rotations(times_s, quats), f"{source.path}: {topic}")


def log_speed(source: FrameSource, topic: str) -> SpeedTrack:
    """Ego speed (m/s) from a velocity topic of the same drive log, on the frames' time axis.

    Raises:
        ConfigurationError: ``source`` is not a drive log.
    """
    if not isinstance(source, LogFrameSource):
        raise ConfigurationError(f"--speed-topic needs a drive log, not {source.path}")
    stamps_ns, speeds = read_speeds(source.path, topic)
    return SpeedTrack([source.seconds(int(t)) for t in stamps_ns], speeds)
