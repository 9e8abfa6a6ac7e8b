"""Optional rotation source: monocular ORB-SLAM3 through the ``pyorbslam3`` wheel.

``pyorbslam3`` is GPL-3.0 and therefore an optional extra (``pip install 'slopedist[orbslam3]'``).
ORB-SLAM3 needs an ORB vocabulary in DBoW2 text format (``ORBvoc.txt``). slopedist never
downloads it: give its path (``vocabulary=`` / ``--vocab``) or set ``PYORBSLAM3_VOCAB``; a small
one can be trained from your own frames with :mod:`slopedist.odometry.orb_vocabulary`.

Convention: rotations are camera-to-world relative to ORB-SLAM3's first keyframe (x right,
y down, z forward). When ORB-SLAM3 loses track and starts a new map, the new map's rotations are
chained to the last rotation reported before the loss (the rotation during the gap is taken as
none), its results carry the next ``segment`` number (do not look back across it), and the frames
in between are reported ``lost``. ORB-SLAM3 sees the image unmasked (it
has no feature mask; its RANSAC and map culling reject moving vehicles).

ORB-SLAM3 maps in a thread of its own; fed faster than real time, its mapping falls behind and
tracking is lost within a second or two (seen on KITTI odometry). By default the backend therefore
paces the frames to their timestamps (``realtime=True``): a run takes at least as long as the
video.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.core.errors import InputFileError, MissingInputError, OptionalDependencyError
from slopedist.odometry.base import OdometryResult, OdometryState

VOCAB_ENV = "PYORBSLAM3_VOCAB"
"""Environment variable naming the ORB vocabulary file."""


def import_pyorbslam3() -> Any:
    """The ``pyorbslam3`` module, or :class:`OptionalDependencyError` when it is not installed."""
    try:
        import pyorbslam3
    except ImportError:
        raise OptionalDependencyError(
            "pyorbslam3", "orbslam3", "the ORB-SLAM3 odometry backend (--odometry orbslam3)"
        ) from None
    return pyorbslam3


def resolve_vocabulary(vocabulary: str | Path | None) -> Path:
    """The vocabulary file from the argument or ``$PYORBSLAM3_VOCAB``; never downloaded.

    Raises:
        MissingInputError: none given, or the file does not exist.
    """
    if vocabulary is None:
        env = os.environ.get(VOCAB_ENV)
        if not env:
            raise MissingInputError(
                "ORB-SLAM3 needs an ORB vocabulary (ORBvoc.txt, DBoW2 text format), which "
                f"slopedist does not download: pass --vocab PATH or set {VOCAB_ENV}; one can be "
                "trained from your frames with 'python -m slopedist.odometry.orb_vocabulary "
                "FRAME_DIR --out voc.txt'"
            )
        vocabulary = env
    path = Path(vocabulary)
    if not path.is_file():
        raise MissingInputError(f"ORB vocabulary not found: {path}")
    with path.open("rb") as fh:
        head = fh.readline(200).split()
    if len(head) != 4 or not all(t.isdigit() for t in head):
        raise InputFileError(
            path,
            "not a DBoW2 text vocabulary (the first line should be 'k L scoring weighting')",
            line=1,
        )
    return path


def settings_yaml(
    camera: Camera, width: int, height: int, fps: float = 10.0, n_features: int = 2000
) -> str:
    """ORB-SLAM3 settings (``File.version 1.0`` layout) for a rectified pinhole ``camera``."""
    return "\n".join(
        [
            "%YAML:1.0",
            'File.version: "1.0"',
            'Camera.type: "PinHole"',
            f"Camera1.fx: {camera.f:.6f}",
            f"Camera1.fy: {camera.f:.6f}",
            f"Camera1.cx: {camera.c_x:.6f}",
            f"Camera1.cy: {camera.c_y:.6f}",
            "Camera1.k1: 0.0",
            "Camera1.k2: 0.0",
            "Camera1.p1: 0.0",
            "Camera1.p2: 0.0",
            f"Camera.width: {int(width)}",
            f"Camera.height: {int(height)}",
            f"Camera.fps: {fps:g}",
            "Camera.RGB: 1",
            f"ORBextractor.nFeatures: {int(n_features)}",
            "ORBextractor.scaleFactor: 1.2",
            "ORBextractor.nLevels: 8",
            "ORBextractor.iniThFAST: 20",
            "ORBextractor.minThFAST: 7",
            "Viewer.KeyFrameSize: 0.1",
            "Viewer.KeyFrameLineWidth: 1.0",
            "Viewer.GraphLineWidth: 1.0",
            "Viewer.PointSize: 2.0",
            "Viewer.CameraSize: 0.15",
            "Viewer.CameraLineWidth: 2.0",
            "Viewer.ViewpointX: 0.0",
            "Viewer.ViewpointY: -10.0",
            "Viewer.ViewpointZ: -0.1",
            "Viewer.ViewpointF: 2000.0",
            "",
        ]
    )


class OrbSlam3Odometry:
    """Monocular ORB-SLAM3 as a :class:`~slopedist.odometry.base.RotationOdometry`.

    The ORB-SLAM3 system is started on the first frame (its settings need the image size) and
    loading the vocabulary takes a while for the full ``ORBvoc.txt`` (tens of seconds).

    Args:
        camera: rectified pinhole intrinsics of the frames.
        vocabulary: ORB vocabulary path (default ``$PYORBSLAM3_VOCAB``).
        fps: nominal frame rate written to the settings.
        n_features: ORB features per frame.
        realtime: wait so that frames reach ORB-SLAM3 no faster than their timestamps.

    Raises:
        OptionalDependencyError: ``pyorbslam3`` is not installed.
        MissingInputError: no vocabulary.
    """

    def __init__(
        self,
        camera: Camera,
        vocabulary: str | Path | None = None,
        fps: float = 10.0,
        n_features: int = 2000,
        realtime: bool = True,
    ) -> None:
        self._pos = import_pyorbslam3()
        self.realtime = realtime
        self._clock: tuple[float, float] | None = None  # (timestamp, wall time) of last frame
        self.last_track_ms = float("nan")
        """Time of the last ORB-SLAM3 track call, milliseconds (without the real-time wait)."""
        self.camera = camera
        self.vocabulary = resolve_vocabulary(vocabulary)
        self.fps = fps
        self.n_features = n_features
        self._slam: Any = None
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        self._size: tuple[int, int] | None = None
        self._anchor = np.eye(3)
        self._last_R: NDArray[np.float64] | None = None
        self._tracking = False
        self._segment = 0

    def _start(self, width: int, height: int) -> None:
        self._tmp = tempfile.TemporaryDirectory(prefix="slopedist-orbslam3-")
        settings = Path(self._tmp.name) / "settings.yaml"
        settings.write_text(settings_yaml(self.camera, width, height, self.fps, self.n_features))
        self._slam = self._pos.Slam(
            str(self.vocabulary), str(settings), self._pos.Sensor.MONOCULAR, use_viewer=False
        )
        self._size = (width, height)

    def process(
        self,
        image_gray: NDArray[np.uint8],
        timestamp_s: float,
        mask_boxes: NDArray[np.float64] | None = None,
    ) -> OdometryResult:
        """Track one frame; ``mask_boxes`` is not used (see the module docstring)."""
        h, w = image_gray.shape[:2]
        if self._slam is None:
            self._start(w, h)
        if self.realtime:
            if self._clock is not None:
                wait = (timestamp_s - self._clock[0]) - (time.perf_counter() - self._clock[1])
                if 0 < wait < 1.0:
                    time.sleep(wait)
            self._clock = (timestamp_s, time.perf_counter())
        t0 = time.perf_counter()
        result = self._slam.track_monocular(np.ascontiguousarray(image_gray), float(timestamp_s))
        self.last_track_ms = (time.perf_counter() - t0) * 1e3
        state = result.state
        TS = self._pos.TrackingState
        if state == TS.OK and result.pose_wc is not None:
            R_map = np.asarray(result.pose_wc, dtype=float)[:3, :3]
            if not self._tracking:
                # (re)initialised: a new map starts at its first keyframe; chain it to the
                # last rotation reported so that rotations stay relative to one frame, and
                # start a new segment (no look-back across the gap)
                if self._last_R is not None:
                    self._segment += 1
                base = self._last_R if self._last_R is not None else np.eye(3)
                self._anchor = base @ R_map.T
                self._tracking = True
            R = self._anchor @ R_map
            self._last_R = R
            return OdometryResult(
                R, OdometryState.OK, int(result.num_tracked_points), self._segment
            )
        was_tracking = self._tracking
        self._tracking = False
        if self._last_R is None and not was_tracking and state != TS.LOST:
            return OdometryResult(None, OdometryState.NOT_INITIALISED, 0)
        return OdometryResult(
            None, OdometryState.LOST, int(result.num_tracked_points), self._segment
        )

    def reset(self) -> None:
        """Forget the map (new sequence)."""
        if self._slam is not None:
            self._slam.reset()
        self._anchor = np.eye(3)
        self._last_R = None
        self._tracking = False
        self._clock = None
        self._segment = 0

    def close(self) -> None:
        """Stop ORB-SLAM3's threads and remove the settings file."""
        if self._slam is not None:
            self._slam.shutdown()
            self._slam = None
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.close()
