from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from slopedist.odometry import RotationTrack
from slopedist.odometry.jumps import (
    JUMP_SETTLE_FRAMES,
    JUMP_SETTLE_S,
    MAX_PITCH_RATE_RAD_S,
    PITCH_NOISE_RAD,
    JumpVerdict,
    PitchJumpGuard,
    camera_pitch,
    track_jumps,
    trusted_rotations,
)


def pitched(deg: float, yaw_deg: float = 0.0) -> np.ndarray:
    """A camera pitched by ``deg`` (and turned by ``yaw_deg``), camera-to-world."""
    return Rotation.from_euler("YX", [yaw_deg, deg], degrees=True).as_matrix()


def verdicts(times: list[float], pitches_deg: list[float]) -> list[JumpVerdict]:
    guard = PitchJumpGuard()
    return [guard.update(t, pitched(p)) for t, p in zip(times, pitches_deg, strict=True)]


def test_camera_pitch_is_the_pitch_whatever_the_heading() -> None:
    for yaw in (0.0, 90.0, 180.0):
        assert math.isclose(abs(camera_pitch(pitched(3.0, yaw))), math.radians(3.0), abs_tol=1e-9)


def test_a_one_frame_5_degree_glitch_is_a_jump_and_the_next_frame_is_kept() -> None:
    t = [0.1 * k for k in range(6)]
    got = verdicts(t, [0, 0, 0, 5, 0, 0])
    assert got == [JumpVerdict.KEPT] * 3 + [JumpVerdict.JUMP] + [JumpVerdict.KEPT] * 2


def test_a_two_frame_glitch_is_two_jumps() -> None:
    got = verdicts([0.1 * k for k in range(6)], [0, 0, 5, 5.2, 0, 0])
    assert got[2:4] == [JumpVerdict.JUMP, JumpVerdict.JUMP]
    assert got[4:] == [JumpVerdict.KEPT, JumpVerdict.KEPT]


def test_a_step_that_persists_is_accepted_after_the_settling_time() -> None:
    t = [0.1 * k for k in range(20)]
    got = verdicts(t, [0.0] * 5 + [5.0] * 15)
    first_new = got.index(JumpVerdict.NEW_LEVEL)
    assert got[5:first_new] == [JumpVerdict.JUMP] * (first_new - 5)
    assert t[first_new] - t[5] >= JUMP_SETTLE_S - 1e-9
    assert first_new - 5 + 1 >= JUMP_SETTLE_FRAMES
    assert t[first_new - 1] - t[5] < JUMP_SETTLE_S  # not later than needed
    assert got[first_new + 1 :] == [JumpVerdict.KEPT] * (len(t) - first_new - 1)


def test_at_a_low_frame_rate_a_step_needs_the_settling_frames_too() -> None:
    t = [1.0 * k for k in range(8)]
    got = verdicts(t, [0.0, 0.0] + [40.0] * 6)
    assert got[2 : 2 + JUMP_SETTLE_FRAMES - 1] == [JumpVerdict.JUMP] * (JUMP_SETTLE_FRAMES - 1)
    assert got[2 + JUMP_SETTLE_FRAMES - 1] is JumpVerdict.NEW_LEVEL


def test_frames_without_a_rotation_change_nothing_and_widen_the_bound() -> None:
    guard = PitchJumpGuard()
    assert guard.update(0.0, pitched(0.0)) is JumpVerdict.KEPT
    assert guard.update(0.1, None) is JumpVerdict.KEPT
    assert guard.update(0.2, np.full((3, 3), np.nan)) is JumpVerdict.KEPT
    # 1 s without a rotation: 15° is within reach of 20°/s
    assert guard.update(1.0, pitched(15.0)) is JumpVerdict.KEPT


def test_reset_forgets_the_level() -> None:
    guard = PitchJumpGuard()
    guard.update(0.0, pitched(0.0))
    guard.reset()
    assert guard.update(0.1, pitched(30.0)) is JumpVerdict.KEPT


def test_track_jumps_marks_the_glitch_and_counts_the_new_levels() -> None:
    n = 20
    p = np.r_[np.zeros(3), 6.0, np.zeros(4), np.full(12, -6.0)]
    R = np.stack([pitched(x) for x in p])
    valid = np.ones(n, bool)
    valid[1] = False
    marks = track_jumps(RotationTrack.from_arrays(0.1 * np.arange(n), R, valid))
    assert marks.jump[3] and not marks.jump[:3].any() and not marks.jump[4:8].any()
    assert marks.jump[8] and marks.level[7] == 0 and marks.level[-1] == 1


@settings(max_examples=60, deadline=None)
@given(
    dts=st.lists(st.floats(0.005, 0.6), min_size=1, max_size=40),
    rates=st.lists(st.floats(-0.9, 0.9), min_size=40, max_size=40),
    start=st.floats(-20.0, 20.0),
)
def test_a_car_that_pitches_within_the_bound_never_trips_at_any_frame_rate(
    dts: list[float], rates: list[float], start: float
) -> None:
    """Irregular frame periods, the first frame anywhere: a pitch that changes at most at 90 %
    of the physical rate is never a jump."""
    guard = PitchJumpGuard()
    t, p = 0.0, math.radians(start)
    assert guard.update(t, pitched(math.degrees(p))) is JumpVerdict.KEPT  # first frame
    for dt, r in zip(dts, rates, strict=False):
        t += dt
        p += r * MAX_PITCH_RATE_RAD_S * dt
        assert guard.update(t, pitched(math.degrees(p))) is JumpVerdict.KEPT


@settings(max_examples=60, deadline=None)
@given(
    dt=st.floats(0.01, 0.2),
    before=st.integers(1, 10),
    excess=st.floats(0.1, 60.0),
    sign=st.sampled_from([-1.0, 1.0]),
)
def test_a_glitch_beyond_the_bound_is_a_jump_at_any_frame_period(
    dt: float, before: int, excess: float, sign: float
) -> None:
    bound = math.degrees(MAX_PITCH_RATE_RAD_S * dt + PITCH_NOISE_RAD)
    pitches = [0.0] * before + [sign * (bound + excess)] + [0.0]
    got = verdicts([dt * k for k in range(len(pitches))], pitches)
    assert got == [JumpVerdict.KEPT] * before + [JumpVerdict.JUMP, JumpVerdict.KEPT]


def test_trusted_rotations_hold_the_last_trusted_rotation_over_jumps() -> None:
    R = np.stack([pitched(x, 30.0) for x in (0.0, 0.0, 7.0, 7.0, 0.0)])
    valid = np.array([True, False, True, True, True])
    track = RotationTrack.from_arrays(0.1 * np.arange(5), R, valid)
    held = trusted_rotations(track, track_jumps(track))
    np.testing.assert_array_equal(held[[0, 2, 3, 4]], R[[0, 0, 0, 4]])


def test_a_frame_back_near_the_trusted_level_after_a_small_glitch_is_kept() -> None:
    # 3.2° is a jump at 10 Hz (bound 2.5°); the next frame, 0.8° from the trusted level, is
    # within reach of the glitch too: it is kept, not the start of 0.5 s of jumps
    got = verdicts([0.1 * k for k in range(8)], [0, 0, 0, 3.2, 0.8, 0.8, 0.5, 0.2])
    assert got == [JumpVerdict.KEPT] * 3 + [JumpVerdict.JUMP] + [JumpVerdict.KEPT] * 4


def test_a_small_step_that_persists_is_still_held_until_it_settles() -> None:
    # within reach of the trusted level from the second frame on, but nearer to the step
    got = verdicts([0.1 * k for k in range(12)], [0, 0, 0] + [3.2] * 9)
    assert got[3:8] == [JumpVerdict.JUMP] * 5 and got[8] is JumpVerdict.NEW_LEVEL
