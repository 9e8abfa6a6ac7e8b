"""Odometry jumps: a camera pitch that changes faster than a car can pitch is a glitch.

A road's gradient and a car body's pitch change slowly. Vertical curves are designed so that
the grade changes over tens of metres (AASHTO, *A Policy on Geometric Design of Highways and
Streets*, crest and sag curves: a rate of vertical curvature K of metres per percent of grade
change), a few degrees per second at most at any speed a curve is designed for; a car body
pitches a few degrees under hard braking or acceleration, over about half a second (the
suspension's pitch mode is about 1–1.5 Hz). Together they change the camera's pitch by well
under :data:`MAX_PITCH_RATE_RAD_S` (20°/s); the 13 KITTI tracking drives pitch by at most 7.2°/s
frame to frame, with ORB-SLAM3 or OXTS rotations alike. A rotation whose pitch departs from
the last trusted one by more than that rate over the time between them, plus the odometry's
noise (:data:`PITCH_NOISE_RAD`), is an odometry glitch (a visual-odometry or pose-file jump of
one or a few frames): its θ is not trusted, and it is not kept as a look-back reference.

A jump that persists is a re-initialisation of the odometry, not a glitch: once the frames
after it agree with each other (within the same bound, frame to frame) for
:data:`JUMP_SETTLE_S` and at least :data:`JUMP_SETTLE_FRAMES` frames, the new level is
accepted and the look-back starts again from it, so a run does not go dark.

Causal: a frame's verdict depends on it and the frames before it only. Convention: rotations
camera-to-world ``(3, 3)``; pitch in radians (positive nose up); timestamps in seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.core import geometry as geo
from slopedist.odometry.base import RotationTrack

MAX_PITCH_RATE_RAD_S = math.radians(20.0)
"""The fastest change of the camera's pitch a road and a car body give, radians per second
(20°/s; see the module's description for the sources)."""

PITCH_NOISE_RAD = math.radians(0.5)
"""Allowance for the odometry's own frame-to-frame pitch noise, radians (0.5°; on the KITTI
tracking drives the 99th percentile of the frame-to-frame pitch change, real motion and noise
together, is 0.13–0.51° with ORB-SLAM3 rotations)."""

JUMP_SETTLE_S = 0.5
"""How long frames must agree on a new pitch level before it is accepted, seconds (the time a
car body's pitch transient takes to settle)."""

JUMP_SETTLE_FRAMES = 3
"""The least number of frames that must agree on a new pitch level (at a low frame rate,
0.5 s may be one or two frames)."""

JUMP_STATE = "odometry_jump"
"""The odometry state a run's outputs give a frame whose rotation is a jump (``frames.csv``'s
``odometry_state``, ``run.json``'s ``odometry_states``, the overlay's header), whatever state
the odometry itself reported (it tracked, so ``ok``): its θ is not trusted."""


MAX_SPEED_M_S = 100.0
"""The fastest a road vehicle moves, metres per second (360 km/h; the KITTI drives reach
19 m/s). A pose file whose consecutive poses are further apart over their time step is not
one drive in order (see :func:`impossible_steps`)."""

MAX_TURN_RATE_RAD_S = math.radians(180.0)
"""The fastest a road vehicle turns, radians per second (180°/s, a car spinning out; the
KITTI drives turn at most 35°/s frame to frame, ORB-SLAM3 and OXTS rotations alike)."""

POSITION_NOISE_M = 1.0
"""Allowance for a pose file's position noise from one pose to the next, metres (GPS jitter;
the OXTS positions of the KITTI drives step by at most 1.9 m per frame at 19 m/s)."""

TURN_NOISE_RAD = math.radians(2.0)
"""Allowance for a pose file's rotation noise from one pose to the next, radians."""


def impossible_steps(
    timestamps_s: ArrayLike,
    R_world_cam: ArrayLike,
    positions_m: ArrayLike | None = None,
) -> NDArray[np.bool_]:
    """Which steps ``k → k+1`` of a trajectory (``(N,)`` seconds, ``(N, 3, 3)`` rotations,
    ``(N, 3)`` positions in metres or None) turn faster than :data:`MAX_TURN_RATE_RAD_S` or
    move faster than :data:`MAX_SPEED_M_S` (each with its noise allowance): ``(N − 1,)``.

    A pose file's step is a frame period, so a drive's steps stay far below the bounds; lines
    out of order (a shuffled or merged file) jump tens of metres and degrees at once.
    """
    t = np.asarray(timestamps_s, dtype=float)
    dt = np.diff(t)
    R = np.asarray(R_world_cam, dtype=float)
    turn = geo.rotation_angle_rad(np.swapaxes(R[:-1], -1, -2) @ R[1:])
    bad = turn > MAX_TURN_RATE_RAD_S * dt + TURN_NOISE_RAD
    if positions_m is not None:
        p = np.asarray(positions_m, dtype=float)
        moved = np.linalg.norm(np.diff(p, axis=0), axis=1)
        bad |= moved > MAX_SPEED_M_S * dt + POSITION_NOISE_M
    return np.asarray(bad)


def shown_state(state: str, jump: bool) -> str:
    """The odometry ``state`` of a frame as its outputs give it: :data:`JUMP_STATE` when its
    rotation is a jump."""
    return JUMP_STATE if jump else state


class JumpVerdict(str, Enum):
    """What :class:`PitchJumpGuard` says of one frame's rotation."""

    KEPT = "kept"
    """Within the bound of the last trusted frame (or nothing to compare with): trusted."""
    JUMP = "jump"
    """Departs from the last trusted frame by more than a car can pitch: not trusted."""
    NEW_LEVEL = "new_level"
    """A jump that persisted: the new level is accepted from this frame on (the look-back
    starts again here)."""


def camera_pitch(R_world_cam: NDArray[np.float64], mount_angle_rad: float = 0.0) -> float:
    """The camera's pitch relative to the first frame's road plane, radians (the θ of eq. 4
    with the first frame as look-back)."""
    return float(geo.ego_road_gradient(np.eye(3), R_world_cam, mount_angle_rad))


@dataclass
class _Level:
    """A pitch level: the last frame that holds it (time, pitch) and since when it is held."""

    time_s: float
    pitch_rad: float
    since_s: float
    frames: int = 1


class PitchJumpGuard:
    """Judges each frame's rotation against the last trusted one (:class:`JumpVerdict`).

    Example::

        guard = PitchJumpGuard(camera.mount_angle_rad)
        for t, R in frames:
            if guard.update(t, R) is JumpVerdict.JUMP:
                ...  # θ of this frame is not trusted
    """

    def __init__(
        self,
        mount_angle_rad: float = 0.0,
        max_rate_rad_s: float = MAX_PITCH_RATE_RAD_S,
        noise_rad: float = PITCH_NOISE_RAD,
        settle_s: float = JUMP_SETTLE_S,
        settle_frames: int = JUMP_SETTLE_FRAMES,
    ) -> None:
        self.mount_angle_rad = mount_angle_rad
        self.max_rate_rad_s = max_rate_rad_s
        self.noise_rad = noise_rad
        self.settle_s = settle_s
        self.settle_frames = settle_frames
        self._trusted: _Level | None = None
        self._candidate: _Level | None = None

    def reset(self) -> None:
        """Forget every frame (a new sequence or a new odometry segment)."""
        self._trusted = self._candidate = None

    def _agrees(self, level: _Level, timestamp_s: float, pitch_rad: float) -> bool:
        """Whether ``pitch_rad`` at ``timestamp_s`` is within reach of ``level``'s last frame."""
        dt = max(timestamp_s - level.time_s, 0.0)
        return abs(pitch_rad - level.pitch_rad) <= self.max_rate_rad_s * dt + self.noise_rad

    def _holds_candidate(self, cand: _Level, timestamp_s: float, pitch_rad: float) -> bool:
        """Whether ``pitch_rad`` continues the jump ``cand``: within its reach, and nearer to
        it than to the trusted level when within reach of both (a frame back near the trusted
        level after a jump of a few degrees is kept, not taken for the jump's new level)."""
        if not self._agrees(cand, timestamp_s, pitch_rad):
            return False
        trusted = self._trusted
        if trusted is None or not self._agrees(trusted, timestamp_s, pitch_rad):
            return True
        return abs(pitch_rad - cand.pitch_rad) < abs(pitch_rad - trusted.pitch_rad)

    def update(self, timestamp_s: float, R_world_cam: NDArray[np.float64] | None) -> JumpVerdict:
        """The verdict on the frame at ``timestamp_s`` (seconds, increasing); a frame without
        a (finite) rotation is :attr:`JumpVerdict.KEPT` and changes nothing."""
        if R_world_cam is None:
            return JumpVerdict.KEPT
        pitch = camera_pitch(R_world_cam, self.mount_angle_rad)
        if not math.isfinite(pitch):
            return JumpVerdict.KEPT
        here = _Level(timestamp_s, pitch, timestamp_s)
        cand = self._candidate
        if cand is not None and self._holds_candidate(cand, timestamp_s, pitch):
            self._candidate = here = _Level(timestamp_s, pitch, cand.since_s, cand.frames + 1)
            if here.frames < self.settle_frames or timestamp_s - here.since_s < self.settle_s:
                return JumpVerdict.JUMP
            self._trusted, self._candidate = here, None
            return JumpVerdict.NEW_LEVEL
        if self._trusted is None or self._agrees(self._trusted, timestamp_s, pitch):
            self._trusted, self._candidate = here, None
            return JumpVerdict.KEPT
        self._candidate = here
        return JumpVerdict.JUMP


@dataclass(frozen=True)
class JumpMarks:
    """The verdicts of a whole track: ``jump`` ``(N,)`` bool (rotation not trusted) and
    ``level`` ``(N,)`` int (counts the accepted new levels up to each frame: the look-back
    never crosses a change of it)."""

    jump: NDArray[np.bool_]
    level: NDArray[np.int64]


def track_jumps(track: RotationTrack, mount_angle_rad: float = 0.0) -> JumpMarks:
    """:class:`PitchJumpGuard`'s verdict on every frame of ``track``, in order (the verdicts
    a stream of its frames gets)."""
    guard = PitchJumpGuard(mount_angle_rad)
    n = len(track)
    jump = np.zeros(n, dtype=bool)
    new_level = np.zeros(n, dtype=np.int64)
    for k in range(n):
        R = track.R_world_cam[k] if track.valid[k] else None
        verdict = guard.update(float(track.timestamps_s[k]), R)
        jump[k] = verdict is JumpVerdict.JUMP
        new_level[k] = verdict is JumpVerdict.NEW_LEVEL
    return JumpMarks(jump, np.cumsum(new_level))


def trusted_rotations(track: RotationTrack, marks: JumpMarks) -> NDArray[np.float64]:
    """``track``'s rotations ``(N, 3, 3)`` with each jump frame's replaced by the last trusted
    one before it (no rotation since: what an estimator that compensates the camera's rotation
    is given, as :class:`~slopedist.streaming.step.FrameStep` gives it in a stream)."""
    n = len(track)
    kept = track.valid & ~marks.jump
    last = np.maximum.accumulate(np.where(kept, np.arange(n), -1))
    index = np.where(marks.jump & (last >= 0), last, np.arange(n))
    return track.R_world_cam[index]
