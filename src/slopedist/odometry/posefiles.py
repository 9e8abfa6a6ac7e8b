"""Readers for pose files: KITTI 3×4 per line, TUM ``t x y z qx qy qz qw``, and OXTS/IMU poses.

Every reader returns a :class:`~slopedist.odometry.base.RotationTrack` of camera-to-world
rotations relative to the first frame (camera frame x right, y down, z forward).
"""

from __future__ import annotations

import math
from enum import Enum
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.core.camera import read_kitti_calib
from slopedist.core.errors import InputFileError
from slopedist.core.geometry import not_rotations, rotation_angle_rad
from slopedist.core.limits import MAX_ABS_POSITION_M, MAX_FRAME_INTERVAL_S
from slopedist.core.textfiles import numbered_lines
from slopedist.odometry.base import RotationTrack
from slopedist.odometry.jumps import (
    MAX_SPEED_M_S,
    MAX_TURN_RATE_RAD_S,
    TURN_NOISE_RAD,
    impossible_steps,
)

KITTI_FRAME_PERIOD_S = 0.1
"""KITTI records at 10 Hz."""

R_CAM_VEHICLE_NOMINAL = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
"""Nominal rotation from the vehicle frame (x forward, y left, z up) to the camera frame."""


class PoseFormat(str, Enum):
    """Layout of a pose file."""

    KITTI = "kitti"
    TUM = "tum"


def _read_numeric_rows(
    path: str | Path, n_fields: int, names: list[str], also: int | None = None
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """``(rows × n_fields numbers, the file line of each row)``; with ``also``, every row may
    instead have that many numbers (the first row decides; ``names`` covers the longer)."""
    rows: list[list[float]] = []
    lines: list[int] = []
    for lineno, line in numbered_lines(path, "pose file"):
        tokens = line.replace(",", " ").split()
        if not rows and also is not None and len(tokens) == also:
            n_fields = also
        if len(tokens) != n_fields:
            raise InputFileError(
                path, f"expected {n_fields} numbers, found {len(tokens)}", line=lineno
            )
        rows.append([_pose_number(path, lineno, name, tok) for name, tok in zip(names, tokens)])
        lines.append(lineno)
    if not rows:
        raise InputFileError(path, "file has no poses")
    return np.asarray(rows), np.asarray(lines, dtype=np.int64)


def _pose_number(path: str | Path, lineno: int, name: str, tok: str) -> float:
    try:
        value = float(tok)
    except ValueError:
        raise InputFileError(path, f"'{tok}' is not a number", line=lineno, field=name) from None
    if not np.isfinite(value):
        raise InputFileError(path, f"non-finite value {tok}", line=lineno, field=name)
    return value


KITTI_POSE_FIELDS = [f"r{i}{j}" if j < 3 else f"t{i}" for i in range(3) for j in range(4)]
KITTI_4X4_FIELDS = [*KITTI_POSE_FIELDS, "m30", "m31", "m32", "m33"]
"""A KITTI pose line written as the whole 4×4 matrix (last row ``0 0 0 1``)."""

HOMOGENEOUS_ROW_TOL = 1e-9
"""Largest difference of a 4×4 pose's last row from ``0 0 0 1``: the row is written exactly by
every tool (``0`` or ``0.000000e+00``), so any difference beyond rounding is not a pose."""

TUM_POSE_FIELDS = ["t", "x", "y", "z", "qx", "qy", "qz", "qw"]


def _check_rotations(path: str | Path, R: NDArray[np.float64], lines: NDArray[np.int64]) -> None:
    bad = np.flatnonzero(not_rotations(R))
    if bad.size:
        raise InputFileError(
            path,
            "rotation part is not a rotation matrix",
            line=int(lines[bad[0]]),
            field="r00..r22",
        )


def read_kitti_poses(
    path: str | Path, frame_period_s: float = KITTI_FRAME_PERIOD_S
) -> RotationTrack:
    """KITTI pose file: 12 numbers per line, row-major 3×4 camera-to-world ``[R | t]`` (or
    16, the whole 4×4 with its last row ``0 0 0 1``).

    Frame k gets timestamp ``k × frame_period_s``. Rotations are made relative to the first pose.

    Raises:
        InputFileError: a malformed line, or lines whose poses are not one drive in order
            (:func:`check_pose_order`).
    """
    data, lines = _read_numeric_rows(path, 12, KITTI_4X4_FIELDS, also=16)
    if data.shape[1] == 16:  # the whole 4×4: its last row must be 0 0 0 1
        off = np.abs(data[:, 12:] - [0, 0, 0, 1]) > HOMOGENEOUS_ROW_TOL
        bad = np.flatnonzero(off.any(axis=1))
        if bad.size:
            raise InputFileError(
                path,
                "a 4×4 pose's last row must be 0 0 0 1",
                line=int(lines[bad[0]]),
                field="m30..m33",
            )
        data = data[:, :12]
    R = data.reshape(-1, 3, 4)[:, :, :3]
    _check_rotations(path, R, lines)
    t = np.arange(len(R)) * frame_period_s
    check_pose_order(path, t, R, data[:, [3, 7, 11]], lines, ("r00..r22", "t0 t1 t2"))
    return RotationTrack.from_arrays(t, R[0].T @ R)


def _read_tum(
    path: str | Path,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """``(rows of t x y z qx qy qz qw, rotations (N, 3, 3), the file line of each row)`` of a
    TUM-layout file."""
    data, lines = _read_numeric_rows(path, 8, TUM_POSE_FIELDS)
    q = data[:, 4:8]
    norms = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > 1e-2)
    if bad.size:
        raise InputFileError(
            path,
            f"quaternion norm {norms[bad[0]]:.4f} is not 1",
            line=int(lines[bad[0]]),
            field="qx qy qz qw",
        )
    from scipy.spatial.transform import Rotation  # here: 0.3 s of imports, rarely needed

    return data, Rotation.from_quat(q / norms[:, None]).as_matrix(), lines


MAX_IMPOSSIBLE_STEPS = 2
"""Steps faster than a car moves or turns that a pose file may hold and still be read: an
odometry glitch (out and back) or a restart in another frame (one jump), which the jump check
of the rotations (:class:`~slopedist.odometry.jumps.PitchJumpGuard`) handles frame by frame."""

MAX_IMPOSSIBLE_SHARE = 0.05
"""Share of a pose file's steps that may be faster than a car moves or turns (beyond
:data:`MAX_IMPOSSIBLE_STEPS`): more is not one drive in order."""


def _check_positions(
    path: str | Path, positions_m: NDArray[np.float64], lines: NDArray[np.int64], field: str
) -> None:
    """Refuse a position that is not finite or beyond :data:`MAX_ABS_POSITION_M`.

    Raises:
        InputFileError: naming the first such line and ``field``.
    """
    ok = np.isfinite(positions_m) & (np.abs(positions_m) <= MAX_ABS_POSITION_M)
    bad = np.flatnonzero(~ok.all(axis=1))
    if bad.size:
        k = int(bad[0])
        raise InputFileError(
            path,
            f"a position must be a finite number of metres within ±{MAX_ABS_POSITION_M:g}, got "
            + " ".join(f"{v:g}" for v in positions_m[k]),
            line=int(lines[k]),
            field=field,
        )


def check_pose_order(
    path: str | Path,
    timestamps_s: ArrayLike,
    R: NDArray[np.float64],
    positions_m: NDArray[np.float64],
    lines: NDArray[np.int64],
    fields: tuple[str, str],
) -> None:
    """Refuse a pose file whose consecutive poses are, too often, further apart than a car
    moves or turns over their time step (:func:`~slopedist.odometry.jumps.impossible_steps`):
    lines out of order (shuffled, or two files merged), poses at another rate than the
    frames, or translations not in metres. Read as a drive, such poses give every frame a
    rotation from another moment, and every distance is off. A few such steps (at most
    :data:`MAX_IMPOSSIBLE_STEPS`, or :data:`MAX_IMPOSSIBLE_SHARE` of them) are glitches or
    restarts, left to the rotations' jump check.

    Raises:
        InputFileError: naming the first such line and its field (``fields``: the rotation's
            and the position's names).
    """
    _check_positions(path, positions_m, lines, fields[1])
    t = np.asarray(timestamps_s, dtype=float)
    bad = impossible_steps(t, R, positions_m)
    n = int(bad.sum())
    if n <= MAX_IMPOSSIBLE_STEPS or n <= MAX_IMPOSSIBLE_SHARE * len(bad):
        return
    k = int(np.argmax(bad)) + 1
    dt = float(t[k] - t[k - 1])
    turn = math.degrees(float(rotation_angle_rad(R[k - 1].T @ R[k])))
    moved = float(np.linalg.norm(positions_m[k] - positions_m[k - 1]))
    turns_too_fast = math.radians(turn) > MAX_TURN_RATE_RAD_S * dt + TURN_NOISE_RAD
    raise InputFileError(
        path,
        f"this pose is {moved:.3g} m and {turn:.3g}° from the one before, {dt:g} s earlier, "
        f"and {n} of the {len(bad)} steps are faster than a car moves "
        f"({MAX_SPEED_M_S:g} m/s) or turns ({math.degrees(MAX_TURN_RATE_RAD_S):g}°/s): are "
        "the lines out of order, the poses at another rate than the frames (--frame-period), "
        "or the translations not in metres?",
        line=int(lines[k]),
        field=fields[0] if turns_too_fast else fields[1],
    )


def read_tum_poses(path: str | Path, frame_period_s: float | None = None) -> RotationTrack:
    """TUM pose file: ``t x y z qx qy qz qw`` per line, camera-to-world.

    Timestamps come from the ``t`` column, or are ``index × frame_period_s`` when that is given.

    Raises:
        InputFileError: a malformed line, (timestamps from the file) a ``t`` that does not
            increase, or lines whose poses are not one drive in order
            (:func:`check_pose_order`), naming the line.
    """
    data, R, lines = _read_tum(path)
    if frame_period_s is not None:
        t = np.arange(len(R)) * frame_period_s
        check_pose_order(path, t, R, data[:, 1:4], lines, ("qx qy qz qw", "x y z"))
        return RotationTrack.from_arrays(t, R[0].T @ R)
    t = data[:, 0]
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        k = int(back[0]) + 1
        raise InputFileError(
            path, f"time {t[k]:g} s does not follow {t[k - 1]:g} s", line=int(lines[k]), field="t"
        )
    if len(t) > 1 and (step := float(np.median(np.diff(t)))) > MAX_FRAME_INTERVAL_S:
        raise InputFileError(
            path,
            f"poses are {step:g} s apart (median): timestamps in milliseconds, microseconds "
            "or nanoseconds? The t column is in seconds",
            line=int(lines[1]),
            field="t",
        )
    check_pose_order(path, t, R, data[:, 1:4], lines, ("qx qy qz qw", "x y z"))
    return RotationTrack.from_arrays(t, R[0].T @ R)


def read_pose_file(
    path: str | Path, fmt: PoseFormat | None = None, frame_period_s: float = KITTI_FRAME_PERIOD_S
) -> RotationTrack:
    """Read a KITTI or TUM pose file; the layout is detected from the field count if not given.

    When the layout is detected (``fmt`` None), a TUM-layout file whose motion shows a vehicle
    frame (x forward, y left, z up: OXTS/IMU poses) rather than a camera frame is refused, since
    read as camera poses it would give a wrong road gradient; see :func:`vehicle_frame_evidence`.

    Raises:
        InputFileError: a malformed line, or (detected layout) vehicle-frame poses.
    """
    if fmt is None:
        first = next(iter(numbered_lines(path, "pose file")), (0, ""))[1]
        fmt = PoseFormat.TUM if len(first.replace(",", " ").split()) == 8 else PoseFormat.KITTI
        if fmt is PoseFormat.TUM:
            data, R, _ = _read_tum(path)
            why = vehicle_frame_evidence(data[:, 1:4], R)
            if why:
                raise InputFileError(
                    path,
                    f"these look like vehicle-frame poses (x forward, z up; e.g. OXTS), not "
                    f"camera poses: {why}; give the pose format explicitly (oxts for vehicle "
                    f"poses, tum if these really are camera poses)",
                )
    if fmt is PoseFormat.TUM:
        return read_tum_poses(path)
    return read_kitti_poses(path, frame_period_s)


MIN_TURN_EVIDENCE_RAD = math.radians(10.0)
"""Total turning, radians, above which the turning axis decides the frame of a pose file."""

MIN_PATH_EVIDENCE_M = 5.0
"""Path length, metres, above which the main direction of travel decides the frame."""

EVIDENCE_STRIDE = 10
"""Poses compared EVIDENCE_STRIDE lines apart (1 s at 10 Hz), so jitter does not add up."""


def vehicle_frame_evidence(xyz: NDArray[np.float64], R: NDArray[np.float64]) -> str | None:
    """Why poses ``(positions (N, 3) m, camera-to-world rotations (N, 3, 3))`` look like a
    vehicle frame (x forward, y left, z up) and not a camera frame (x right, y down, z forward),
    or None.

    A road vehicle turns about its vertical axis: with more than :data:`MIN_TURN_EVIDENCE_RAD`
    of turning, the axis most of the rotation between poses :data:`EVIDENCE_STRIDE` apart is
    about decides (z: vehicle; y, a camera's vertical: not). Without turning, the main direction
    of travel over more than :data:`MIN_PATH_EVIDENCE_M` decides (x: vehicle, z: camera).
    Otherwise (almost no motion) nothing is said.
    """
    keep = np.r_[np.arange(0, len(R) - 1, EVIDENCE_STRIDE), len(R) - 1]
    if len(keep) < 2:
        return None
    from scipy.spatial.transform import Rotation  # here: 0.3 s of imports, rarely needed

    Rs, ps = R[keep], xyz[keep]
    turn = np.abs(Rotation.from_matrix(np.swapaxes(Rs[:-1], -1, -2) @ Rs[1:]).as_rotvec())
    turn = turn.sum(axis=0)
    if turn.sum() > MIN_TURN_EVIDENCE_RAD:
        if int(np.argmax(turn)) != 2:
            return None
        turned = f"{math.degrees(turn[2]):.0f}° of its {math.degrees(turn.sum()):.0f}°"
        return f"{turned} of turning is about z (a camera turns about y)"
    path = np.abs(np.diff(ps, axis=0)).sum(axis=0)
    if path.sum() > MIN_PATH_EVIDENCE_M and int(np.argmax(path)) == 0:
        travel = f"{path[0]:.0f} m of its {path.sum():.0f} m"
        return f"{travel} of travel is along x (a camera moves along z)"
    return None


def camera_from_imu_rotation(calib_path: str | Path | None) -> NDArray[np.float64]:
    """Rotation ``R_cam_imu`` from the IMU/vehicle frame to the rectified camera frame.

    From a KITTI tracking calib: ``R0_rect · R_velo_to_cam · R_imu_to_velo``. Without a calib the
    nominal axes swap (x forward, y left, z up → x right, y down, z forward) is used.
    """
    if calib_path is None:
        return R_CAM_VEHICLE_NOMINAL.copy()
    calib = read_kitti_calib(calib_path)
    needed = ("R0_rect", "Tr_velo_to_cam", "Tr_imu_to_velo")
    missing = [k for k in needed if k not in calib]
    if missing:
        raise InputFileError(calib_path, f"missing {', '.join(missing)} needed for OXTS rotations")
    R_rect = calib["R0_rect"].reshape(3, 3)
    R_cam_velo = calib["Tr_velo_to_cam"].reshape(3, 4)[:, :3]
    R_velo_imu = calib["Tr_imu_to_velo"].reshape(3, 4)[:, :3]
    R = R_rect @ R_cam_velo @ R_velo_imu
    u, _, vt = np.linalg.svd(R)  # re-orthonormalise the product of rounded matrices
    return np.asarray(u @ vt)


def read_oxts_rotations(
    path: str | Path,
    calib_path: str | Path | None = None,
    frame_period_s: float = KITTI_FRAME_PERIOD_S,
) -> RotationTrack:
    """Camera rotations from OXTS (GPS/IMU) vehicle poses in TUM layout.

    The file holds vehicle-to-world poses in the IMU frame (x forward, y left, z up) relative to
    frame 0. Each rotation is carried into the camera frame: ``R_cam = R_cam_imu · R_imu ·
    R_cam_imuᵀ``. Timestamps are ``line index × frame_period_s`` (the shared files' ``t`` column
    was written with a wrong step, so it is ignored, but it must not go back: the lines'
    order).

    Raises:
        InputFileError: a malformed line, a ``t`` before the line's above it, or lines whose
            poses are not one drive in order (:func:`check_pose_order`), naming the line.
    """
    data, R_imu, lines = _read_tum(path)
    back = np.flatnonzero(np.diff(data[:, 0]) < 0)
    if back.size:
        k = int(back[0]) + 1
        raise InputFileError(
            path,
            f"time {data[k, 0]:g} s comes after {data[k - 1, 0]:g} s: the lines are out of "
            "order (frame k is timed k × the frame period, but the t column keeps the order)",
            line=int(lines[k]),
            field="t",
        )
    t = np.arange(len(R_imu)) * frame_period_s
    check_pose_order(path, t, R_imu, data[:, 1:4], lines, ("qx qy qz qw", "x y z"))
    R_cam_imu = camera_from_imu_rotation(calib_path)
    R_cam = R_cam_imu @ (R_imu[0].T @ R_imu) @ R_cam_imu.T
    return RotationTrack.from_arrays(t, R_cam)


TUM_HEADER = "# timestamp tx ty tz qx qy qz qw"


class TumPoseWriter:
    """Writes poses in TUM layout (``timestamp tx ty tz qx qy qz qw``, one pose per line,
    flushed per line), as ``evo_traj tum FILE`` and ``evo_ape tum REF FILE`` read it.

    Convention: camera-to-world poses, timestamp in seconds, translation in metres (zero for
    rotation-only sources such as slopedist's odometry: compare them with ``evo_ape
    --pose_relation angle_deg``), quaternion x y z w. Numbers are written with Python's
    shortest round-trip form (``repr``), so they read back exactly.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = self.path.open("w", newline="\n")
        self._fh.write(TUM_HEADER + "\n")
        self._fh.flush()
        self.poses = 0
        self.skipped = 0

    def write(
        self,
        timestamp_s: float,
        R_world_cam: NDArray[np.float64],
        t_world_cam: NDArray[np.float64] | None = None,
    ) -> bool:
        """Append one pose (rotation ``(3, 3)``, translation ``(3,)`` metres or None = 0);
        returns False, writing nothing, for a pose that is not one (a time, rotation or
        translation with a value that is not finite, or a matrix that is not a rotation): a
        frame without a rotation has no line (counted in :attr:`skipped`)."""
        from scipy.spatial.transform import Rotation  # here: 0.3 s of imports, rarely needed

        t = np.zeros(3) if t_world_cam is None else np.asarray(t_world_cam, dtype=float)
        R = np.asarray(R_world_cam, dtype=float)
        if not (
            math.isfinite(float(timestamp_s)) and np.isfinite(R).all() and np.isfinite(t).all()
        ):
            self.skipped += 1
            return False
        try:
            q = Rotation.from_matrix(R).as_quat()
        except (ValueError, np.linalg.LinAlgError):  # a null or left-handed matrix
            self.skipped += 1
            return False
        values = [float(timestamp_s), *(float(v) for v in t), *(float(v) for v in q)]
        self._fh.write(" ".join(repr(v) for v in values) + "\n")
        self._fh.flush()
        self.poses += 1
        return True

    def close(self) -> None:
        self._fh.close()


def write_tum_poses(path: str | Path, track: RotationTrack) -> Path:
    """Write the valid rotations of ``track`` as a TUM file (:class:`TumPoseWriter`)."""
    writer = TumPoseWriter(path)
    try:
        for t, R, ok in zip(track.timestamps_s, track.R_world_cam, track.valid):
            if ok:
                writer.write(float(t), R)
    finally:
        writer.close()
    return writer.path
