"""Writing a synthetic sequence in the layouts the other commands read (``slopedist simulate``).

Layout of the output folder (every file written as the frames are rendered)::

    scenario.toml      the scenario's TOML (copy it to make your own)
    calib.txt          KITTI calib, one line ``P2: f 0 c_x 0 0 f c_y 0 0 0 1 0``
                       (read by Camera.from_kitti_calib; the camera height is in info.json)
    info.json          camera height (m), mount angle (deg), frame rate, image size, counts
    poses.txt          KITTI poses: 12 numbers per line, 3×4 camera-to-world [R | t]
                       relative to the first frame (camera x right, y down, z forward)
    times.txt          timestamp of each frame, seconds (KITTI odometry layout)
    boxes.csv          noisy detector boxes, slopedist box CSV with track ids and the
                       ground-truth distance gt_distance_m (KITTI z, metres), so that
                       ``slopedist run`` → ``slopedist report`` scores the run
    boxes_exact.csv    exact boxes of every target in view (+ z, truncation, visible_share,
                       gt_distance_m = z)
    truth.csv          per frame and target: distances, boxes, gradients (see TRUTH_FIELDS)
    frames.csv         per frame: ego position, gradient, pitch, true θ of eq. 4
    image_02/NNNNNN.png    the rendered frames (BGR PNG)
    depth/NNNNNN.png       true depth, KITTI depth PNG (uint16, metres × 256, 0 = sky or
                           beyond 255.99 m), or depth/NNNNNN.npy (float32 metres, inf = sky)

Convention: distances in metres, angles in degrees in the files (radians inside), grades in
percent, timestamps in seconds, boxes ``(left, top, right, bottom)`` pixels.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from enum import Enum
from pathlib import Path
from typing import Any, NamedTuple

import cv2
import numpy as np

from slopedist.core.errors import ConfigurationError, InputFileError
from slopedist.core.geometry import ego_road_gradient
from slopedist.core.paths import utf8_name
from slopedist.io.depth.files import write_kitti_depth_png
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.readers import CSV_BOX_COLUMNS, CSV_TRUTH_COLUMN
from slopedist.io.formatting import CsvStreamWriter, write_json
from slopedist.odometry.base import lookback_indices
from slopedist.synthetic.scene import Scenario, SceneTruth
from slopedist.synthetic.sequence import SyntheticFrame, SyntheticSequence

TRUTH_FIELDS = (
    "frame",
    "timestamp_s",
    "track_id",
    "class",
    "in_view",
    "detected",
    "z_m",
    "z_centre_m",
    "z_rear_m",
    "x_m",
    "y_m",
    "distance_m",
    "left",
    "top",
    "right",
    "bottom",
    "truncation",
    "visible_share",
    "target_grade_pct",
    "target_pitch_deg",
    "ego_grade_pct",
    "ego_pitch_deg",
)
"""Columns of ``truth.csv``. ``z_m`` is KITTI's label z: camera z of the 3D box's bottom
centre (the distance scored); ``z_centre_m`` the camera z of the box centre; ``z_rear_m`` that
of the middle of the rear bottom edge (the contact point eq. 1 sees); ``distance_m`` the
Euclidean distance to the bottom centre; the box is the exact one (projection of the 8
corners, clipped to the image)."""

FRAME_FIELDS = (
    "frame",
    "timestamp_s",
    "ego_s_m",
    "ego_grade_pct",
    "ego_pitch_deg",
    "camera_pitch_deg",
    "theta_true_deg",
)
"""Columns of ``frames.csv``; ``theta_true_deg`` is eq. 4 on the true rotations (1 s look-back)."""


IMAGE_DIR_NAME, DEPTH_DIR_NAME = "image_02", "depth"
"""The folders of the rendered frames and of the true depth maps in a simulation's folder."""


def frame_file_name(k: int, extension: str) -> str:
    """File name of frame ``k`` in :data:`IMAGE_DIR_NAME` or :data:`DEPTH_DIR_NAME`
    (``000007.png``)."""
    return f"{k:06d}.{extension}"


class DepthFormat(str, Enum):
    """How ``slopedist simulate`` stores the true depth maps."""

    PNG = "png"
    NPY = "npy"
    NONE = "none"


def box_rows(boxes: BoxTable, extra: tuple[str, ...] = ()) -> list[list[Any]]:
    """Rows of the slopedist box CSV (``CSV_BOX_COLUMNS`` then ``extra`` columns)."""
    return [
        [
            int(boxes.frame[i]),
            *boxes.boxes[i],
            int(boxes.track_id[i]),
            boxes.score[i],
            boxes.cls[i],
            *(boxes.extra[k][i] for k in extra),
        ]
        for i in range(len(boxes))
    ]


def with_truth_distance(seq: SyntheticSequence, boxes: BoxTable) -> BoxTable:
    """``boxes`` of one frame with the column ``gt_distance_m``: the true KITTI z (metres) of
    the target of each box's track id."""
    if not len(boxes):
        return BoxTable(
            boxes.frame,
            boxes.boxes,
            boxes.track_id,
            boxes.score,
            boxes.cls,
            {**boxes.extra, CSV_TRUTH_COLUMN: np.zeros(0)},
        )
    ids = seq.truth.track_ids
    m = np.searchsorted(ids, boxes.track_id)
    if np.any(m >= len(ids)) or np.any(ids[np.minimum(m, len(ids) - 1)] != boxes.track_id):
        raise ConfigurationError("a box's track id is not a target of the scenario")
    return BoxTable(
        boxes.frame,
        boxes.boxes,
        boxes.track_id,
        boxes.score,
        boxes.cls,
        {**boxes.extra, CSV_TRUTH_COLUMN: seq.truth.z_m[boxes.frame, m]},
    )


def kitti_calib_line(scenario: Scenario) -> str:
    """The ``P2:`` line of the scenario's camera."""
    c = scenario.camera
    P = [c.f, 0.0, c.c_x, 0.0, 0.0, c.f, c.c_y, 0.0, 0.0, 0.0, 1.0, 0.0]
    return "P2: " + " ".join(f"{v:.12e}" for v in P)


def true_theta(truth: SceneTruth, mount_angle_rad: float) -> np.ndarray:
    """θ of eq. 4 (radians) from the true camera rotations, 1 s look-back."""
    R = truth.poses_cam0()[:, :, :3]
    ref = lookback_indices(truth.timestamps_s)
    return np.asarray(ego_road_gradient(R[ref], R, mount_angle_rad))


def truth_rows(seq: SyntheticSequence, frame: SyntheticFrame) -> list[list[Any]]:
    """Rows of ``truth.csv`` for one frame (every target, in view or not)."""
    tr, k = seq.truth, frame.index
    detected = set(frame.detections.track_id.tolist())
    rows = []
    for m, spec in enumerate(seq.scenario.targets):
        rows.append(
            [
                k,
                frame.timestamp_s,
                spec.track_id,
                spec.cls,
                bool(tr.in_view[k, m]),
                spec.track_id in detected,
                tr.z_m[k, m],
                tr.z_centre_m[k, m],
                tr.z_rear_m[k, m],
                tr.x_m[k, m],
                tr.y_m[k, m],
                tr.distance_m[k, m],
                *tr.box[k, m],
                tr.truncation[k, m],
                frame.visible_share[m],
                100.0 * tr.target_grade[k, m],
                math.degrees(tr.target_pitch_rad[k, m]),
                100.0 * tr.ego_grade[k],
                math.degrees(tr.ego_pitch_rad[k]),
            ]
        )
    return rows


class _FrameFiles(NamedTuple):
    """Where a frame's image and depth map go (``images``: write the image; ``depth``: its
    format)."""

    image_dir: Path
    depth_dir: Path
    images: bool
    depth: DepthFormat


def _write_sequence_files(seq: SyntheticSequence, out: Path, scenario_text: str, n: int) -> None:
    """``scenario.toml``, ``calib.txt``, ``poses.txt`` and ``times.txt`` of the first ``n``
    frames."""
    (out / "scenario.toml").write_text(scenario_text, encoding="utf-8")
    (out / "calib.txt").write_text(kitti_calib_line(seq.scenario) + "\n")
    poses = seq.truth.poses_cam0()[:n]
    np.savetxt(out / "poses.txt", poses.reshape(n, 12), fmt="%.9e")
    np.savetxt(out / "times.txt", seq.truth.timestamps_s[:n], fmt="%.6f")


def _open_streams(out: Path) -> dict[str, CsvStreamWriter]:
    """The per-frame CSV files: detector boxes, exact boxes, truth and frames."""
    return {
        "boxes": CsvStreamWriter.open(out / "boxes.csv", (*CSV_BOX_COLUMNS, CSV_TRUTH_COLUMN)),
        "exact": CsvStreamWriter.open(
            out / "boxes_exact.csv",
            (*CSV_BOX_COLUMNS, "z", "truncation", "visible_share", CSV_TRUTH_COLUMN),
        ),
        "truth": CsvStreamWriter.open(out / "truth.csv", TRUTH_FIELDS),
        "frames": CsvStreamWriter.open(out / "frames.csv", FRAME_FIELDS),
    }


def _write_frame_files(f: SyntheticFrame, files: _FrameFiles) -> None:
    """The frame's image (PNG) and true depth map (KITTI depth PNG or float32 ``.npy``)."""
    k = f.index
    if files.images:
        path = files.image_dir / frame_file_name(k, "png")
        with utf8_name(path) as name:
            if not cv2.imwrite(name, f.image, [cv2.IMWRITE_PNG_COMPRESSION, 1]):
                raise InputFileError(path, "could not be written as PNG")
    if files.depth is DepthFormat.PNG:
        write_kitti_depth_png(files.depth_dir / frame_file_name(k, "png"), f.depth_m)
    elif files.depth is DepthFormat.NPY:
        np.save(files.depth_dir / frame_file_name(k, "npy"), f.depth_m)


def _write_frame_rows(
    seq: SyntheticSequence, f: SyntheticFrame, streams: dict[str, CsvStreamWriter], theta_rad: float
) -> None:
    """The frame's rows of the four CSV files (``theta_rad``: the true θ of eq. 4)."""
    tr, k = seq.truth, f.index
    streams["boxes"].write_values(
        box_rows(with_truth_distance(seq, f.detections), (CSV_TRUTH_COLUMN,))
    )
    streams["exact"].write_values(
        box_rows(
            with_truth_distance(seq, f.exact),
            ("z", "truncation", "visible_share", CSV_TRUTH_COLUMN),
        )
    )
    streams["truth"].write_values(truth_rows(seq, f))
    streams["frames"].write_values(
        [
            [
                k,
                f.timestamp_s,
                tr.ego_s[k],
                100.0 * tr.ego_grade[k],
                math.degrees(tr.ego_pitch_rad[k]),
                math.degrees(tr.camera_pitch_rad[k]),
                math.degrees(theta_rad),
            ]
        ]
    )


def _info(sc: Scenario, n: int, n_det: int, files: _FrameFiles) -> dict[str, Any]:
    """The content of ``info.json``."""
    return {
        "scenario": sc.name,
        "source": sc.source,
        "frames": n,
        "frame_rate_hz": sc.frame_rate_hz,
        "image_width": sc.camera.image_width,
        "image_height": sc.camera.image_height,
        "camera_height_m": sc.camera.rig.height_m,
        "mount_angle_deg": math.degrees(sc.camera.rig.mount_angle_rad),
        "targets": [t.track_id for t in sc.targets],
        "detections": n_det,
        "distance_scored": "z_m of truth.csv: camera z of the 3D box's bottom centre (KITTI z)",
        "depth": files.depth.value,
        "images": files.images,
    }


SIMULATION_NAMES = (
    "scenario.toml",
    "calib.txt",
    "info.json",
    "poses.txt",
    "times.txt",
    "boxes.csv",
    "boxes_exact.csv",
    "truth.csv",
    "frames.csv",
    IMAGE_DIR_NAME,
    DEPTH_DIR_NAME,
)
"""The files and folders :func:`write_simulation` writes in its output folder."""


def refuse_stale_frames(out_dir: Path, n: int, images: bool, depth: DepthFormat) -> None:
    """Refuse an :data:`IMAGE_DIR_NAME` or :data:`DEPTH_DIR_NAME` folder under ``out_dir``
    holding files a :func:`write_simulation` of ``n`` frames would not replace (a longer
    earlier run, another depth format, a drive's own frames): old and new frames would mix.
    Nothing is deleted.

    Raises:
        ConfigurationError: names the folder, how many such files it holds and up to three.
    """
    expected = {
        IMAGE_DIR_NAME: {frame_file_name(k, "png") for k in range(n)} if images else set(),
        DEPTH_DIR_NAME: set()
        if depth is DepthFormat.NONE
        else {frame_file_name(k, depth.value) for k in range(n)},
    }
    for folder, names in expected.items():
        d = out_dir / folder
        if not d.is_dir():
            continue
        stale = sorted(p.name for p in d.iterdir() if p.name not in names)
        if stale:
            shown = ", ".join(stale[:3]) + (", ..." if len(stale) > 3 else "")
            raise ConfigurationError(
                f"{d} holds {len(stale)} file(s) this simulation would not replace ({shown}): "
                "old and new frames would mix; choose another --out or remove them"
            )


def write_simulation(
    seq: SyntheticSequence,
    out_dir: str | Path,
    scenario_text: str,
    *,
    depth: DepthFormat = DepthFormat.PNG,
    images: bool = True,
    max_frames: int | None = None,
    on_frame: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Render ``seq`` and write it to ``out_dir`` (see the module docstring); returns info.json."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sc = seq.scenario
    n = len(seq) if max_frames is None else min(len(seq), max_frames)
    if n < 1:
        raise ConfigurationError("nothing to simulate: the frame limit must be ≥ 1")
    _write_sequence_files(seq, out, scenario_text, n)
    files = _FrameFiles(out / IMAGE_DIR_NAME, out / DEPTH_DIR_NAME, images, depth)
    if images:
        files.image_dir.mkdir(exist_ok=True)
    if depth is not DepthFormat.NONE:
        files.depth_dir.mkdir(exist_ok=True)
    theta = true_theta(seq.truth, sc.camera.rig.mount_angle_rad)
    streams = _open_streams(out)
    n_det = 0
    try:
        for k in range(n):
            f = seq.frame(k)
            _write_frame_files(f, files)
            _write_frame_rows(seq, f, streams, theta[k])
            n_det += len(f.detections)
            if on_frame is not None:
                on_frame(k)
    finally:
        for s in streams.values():
            s.close()
    info = _info(sc, n, n_det, files)
    write_json(out / "info.json", info)
    return info
