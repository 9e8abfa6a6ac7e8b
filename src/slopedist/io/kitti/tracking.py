"""KITTI tracking sequences: calibration, labels, rotations (ORB-SLAM3 or OXTS), detections.

Layout under the data root (see docs/inputs.md, the KITTI data layout)::

    calib/NNNN.txt  label_02/NNNN.txt  orbslam3_poses/NNNN.txt  oxts_poses/NNNN.txt
    pointrcnn_car/NNNN.txt

Frame k has timestamp ``k × 0.1 s``; camera 2 (``P2``) is the camera of the labels.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import Enum
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import KITTI_CAMERA_HEIGHT_M, Camera
from slopedist.core.errors import DataMismatchError, MissingInputError
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.readers import read_kitti_labels, read_pointrcnn, read_rrc
from slopedist.io.detections.sizes import without_sizes
from slopedist.odometry.base import RotationTrack
from slopedist.odometry.posefiles import KITTI_FRAME_PERIOD_S, read_kitti_poses, read_oxts_rotations

PROTOCOL_CLASSES = ("Car", "Van")
PROTOCOL_MAX_TRUNCATED = 0.0
PROTOCOL_MAX_OCCLUDED = 1
PROTOCOL_MAX_DISTANCE_M = 80.0


class RotationSource(str, Enum):
    """Where the camera rotations of a KITTI tracking sequence come from."""

    ORBSLAM3 = "orbslam3"
    OXTS = "oxts"


class BoxSource(str, Enum):
    """Which 2D boxes are fed to the estimators."""

    GT = "gt"
    POINTRCNN = "pointrcnn"
    RRC = "rrc"

    @property
    def is_detector(self) -> bool:
        """Whether the boxes are a detector's (matched to the truth by IoU, with a recall)."""
        return self is not BoxSource.GT


DETECTOR_CLASSES = ("Car",)
"""The class every detector box of the shared data carries, whatever the vehicle's type."""

DETECTION_FOLDERS = {BoxSource.POINTRCNN: "pointrcnn_car", BoxSource.RRC: "rrc_car"}
"""Folder of each detector's boxes in a KITTI tracking root (``<folder>/NNNN.txt``)."""


ROTATION_FOLDERS = {RotationSource.ORBSLAM3: "orbslam3_poses", RotationSource.OXTS: "oxts_poses"}


def list_sequences(root: str | Path) -> list[str]:
    """Names (``"0000"``, ...) of the sequences: one per label file. A sequence whose
    ``calib/`` file is missing is listed, so that :func:`load_sequence` names the file instead of
    the sequence being left out of an evaluation unsaid."""
    root = Path(root)
    if not (root / "label_02").is_dir():
        raise MissingInputError(
            f"no KITTI tracking data at {root}: expected folders label_02/ and calib/ there"
        )
    return sorted(p.stem for p in (root / "label_02").glob("*.txt"))


def protocol_mask(
    labels: BoxTable, max_distance_m: float = PROTOCOL_MAX_DISTANCE_M
) -> NDArray[np.bool_]:
    """Label rows kept by the evaluation protocol: Car or Van, truncated = 0, occluded ≤ 1,
    0 < z ≤ ``max_distance_m``."""
    z = labels.extra["z"]
    return (
        np.isin(labels.cls.astype(str), PROTOCOL_CLASSES)
        & (labels.extra["truncated"] <= PROTOCOL_MAX_TRUNCATED)
        & (labels.extra["occluded"] <= PROTOCOL_MAX_OCCLUDED)
        & (z > 0)
        & (z <= max_distance_m)
    )


@dataclass(frozen=True)
class KittiTrackingSequence:
    """One KITTI tracking sequence.

    Attributes:
        root: data root folder.
        name: sequence name, e.g. ``"0001"``.
        camera: cam 2 intrinsics with the given mount.
        labels: every label row (use :func:`protocol_mask` for the evaluated ones).
        n_frames: number of frames (last labelled frame + 1).
    """

    root: Path
    name: str
    camera: Camera
    labels: BoxTable
    n_frames: int

    @property
    def timestamps_s(self) -> NDArray[np.float64]:
        """``k × 0.1 s`` for every frame k."""
        return np.arange(self.n_frames, dtype=np.float64) * KITTI_FRAME_PERIOD_S

    @property
    def calib_path(self) -> Path:
        return self.root / "calib" / f"{self.name}.txt"

    def rotation_path(self, source: RotationSource) -> Path:
        return self.root / ROTATION_FOLDERS[RotationSource(source)] / f"{self.name}.txt"

    def has_rotations(self, source: RotationSource) -> bool:
        return self.rotation_path(source).is_file()

    def rotations(self, source: RotationSource) -> RotationTrack:
        """Camera rotations from ORB-SLAM3 poses or the OXTS (GPS/IMU) poses.

        Raises:
            MissingInputError: the pose file is absent.
            DataMismatchError: it has fewer poses than the sequence has frames.
        """
        source = RotationSource(source)
        path = self.rotation_path(source)
        if not path.is_file():
            raise MissingInputError(
                f"sequence {self.name}: no {source.value} poses, expected {path}"
            )
        track = (
            read_kitti_poses(path)
            if source is RotationSource.ORBSLAM3
            else read_oxts_rotations(path, self.calib_path)
        )
        if len(track) < self.n_frames:
            raise DataMismatchError(
                f"{path}: {len(track)} poses do not cover the {self.n_frames} frames of "
                f"sequence {self.name}"
            )
        return track

    def detections(
        self,
        min_score: float | None = None,
        source: BoxSource = BoxSource.POINTRCNN,
        sizes: bool = False,
    ) -> BoxTable:
        """A detector's car boxes (PointRCNN's or RRC's) with score ≥ ``min_score``; with
        ``sizes`` the vehicle sizes the detector gives (PointRCNN's, LiDAR-derived: the box
        columns of :mod:`slopedist.io.detections.sizes`), else none (RRC gives none)."""
        path = self.root / DETECTION_FOLDERS[source] / f"{self.name}.txt"
        if not path.is_file():
            raise MissingInputError(
                f"sequence {self.name}: no {source.value} detections, expected {path}"
            )
        reader = read_pointrcnn if source is BoxSource.POINTRCNN else read_rrc
        table = reader(path, min_score)
        return table if sizes else replace(table, extra=without_sizes(table.extra))


def load_sequence(
    root: str | Path,
    name: str,
    height_m: float = KITTI_CAMERA_HEIGHT_M,
    mount_angle_rad: float = 0.0,
) -> KittiTrackingSequence:
    """Read a sequence's calibration (``P2``) and labels."""
    root = Path(root)
    calib = root / "calib" / f"{name}.txt"
    labels_path = root / "label_02" / f"{name}.txt"
    for path, what in ((calib, "calibration"), (labels_path, "labels")):
        if not path.is_file():
            raise MissingInputError(f"sequence {name}: no {what}, expected {path}")
    camera = Camera.from_kitti_calib(calib, "P2", height_m, mount_angle_rad)
    labels = read_kitti_labels(labels_path)
    n_frames = int(labels.frame.max()) + 1 if len(labels) else 0
    return KittiTrackingSequence(root, name, camera, labels, n_frames)
