"""θ and relative-rotation errors of a rotation source against ground truth."""

from __future__ import annotations

import numpy as np
import pytest

from slopedist.core import geometry as geo
from slopedist.core.errors import DataMismatchError
from slopedist.odometry import twoview as tv
from slopedist.odometry.accuracy import (
    OdometryEvaluation,
    OdometryRun,
    lookback_pairs,
    rotation_errors,
    run_odometry,
)
from slopedist.odometry.base import OdometryResult, OdometryState, RotationTrack


def truth(n: int = 25) -> RotationTrack:
    """A car pitching up at 1°/s and turning at 10°/s, 10 Hz."""
    R = np.array([tv.so3_exp(np.radians([0.1 * k, 1.0 * k, 0.0])) for k in range(n)])
    return RotationTrack.from_arrays(np.arange(n) * 0.1, R)


def make_run(
    R: np.ndarray, valid: np.ndarray | None = None, segment: np.ndarray | None = None
) -> OdometryRun:
    n = len(R)
    return OdometryRun(
        np.arange(n) * 0.1,
        R,
        np.ones(n, bool) if valid is None else valid,
        np.zeros(n, np.int64) if segment is None else segment,
        0.5,
        0.4,
    )


def test_exact_rotations_have_no_error() -> None:
    gt = truth()
    errors = rotation_errors(make_run(gt.R_world_cam.copy()), gt)
    assert np.nanmax(np.abs(errors.theta_err_rad)) < 1e-12
    assert np.all(np.isnan(errors.rel_err_rad[:10]))  # less than a full look-back of history
    assert np.nanmax(errors.rel_err_rad[10:]) < 1e-7
    figures = OdometryEvaluation.from_run(make_run(gt.R_world_cam.copy()), gt).as_dict()
    assert figures["frames"] == 25 and figures["frames_ok"] == 25
    assert figures["theta_rms_deg"] == 0.0 and figures["rel_rot_median_deg"] == 0.0
    assert figures["ms_per_frame"] == 20.0 and figures["cpu_ms_per_frame"] == 16.0


def test_a_pitch_error_shows_in_theta_and_rel_rot() -> None:
    gt = truth()
    R = gt.R_world_cam.copy()
    err = tv.so3_exp(np.radians([0.2, 0.0, 0.0]))  # 0.2° more nose-up from frame 15 on
    R[15:] = R[15:] @ err
    errors = rotation_errors(make_run(R), gt)
    theta_deg = np.degrees(errors.theta_err_rad)
    assert np.allclose(theta_deg[:15], 0.0, atol=1e-9)
    # frames 15–24 look back across the error (to frames 5–14): about +0.2° of θ
    assert np.allclose(theta_deg[15:25], 0.2, atol=0.01)
    assert np.allclose(np.degrees(errors.rel_err_rad[15:25]), 0.2, atol=1e-6)


def test_invalid_frames_and_segments_are_skipped() -> None:
    gt = truth()
    R = gt.R_world_cam.copy()
    valid = np.ones(25, bool)
    valid[12] = False
    R[12] = np.eye(3)  # garbage where the backend had no rotation
    segment = np.zeros(25, np.int64)
    segment[18:] = 1
    R[18:] = tv.so3_exp(np.radians([3.0, -5.0, 1.0])) @ R[18:]  # a restart: new world frame
    run = make_run(R, valid, segment)
    j, i, full = lookback_pairs(run)
    assert 12 not in j and 12 not in i
    assert np.all(segment[j] == segment[i])
    assert i[full].min() == 10 and 18 not in i[full]  # segment 1 is too short for a window
    errors = rotation_errors(run, gt)
    assert np.isnan(errors.theta_err_rad[12])
    assert np.nanmax(np.abs(errors.theta_err_rad)) < 1e-9
    figures = OdometryEvaluation.from_run(run, gt)
    assert figures.frames_ok == 24


def test_lengths_must_match() -> None:
    with pytest.raises(DataMismatchError):
        rotation_errors(make_run(truth(20).R_world_cam), truth(25))


class _Replay:
    """A fake backend replaying rotations, lost on one frame."""

    def __init__(self, R: np.ndarray) -> None:
        self.R = R

    def process(self, image, timestamp_s, mask_boxes=None):  # type: ignore[no-untyped-def]
        k = round(timestamp_s / 0.1)
        if k == 3:
            return OdometryResult(None, OdometryState.LOST, 0)
        return OdometryResult(self.R[k], OdometryState.OK, 50, segment=0)

    def reset(self) -> None:
        pass


def test_run_odometry_collects_states() -> None:
    gt = truth(6)
    seen = []
    run = run_odometry(
        _Replay(gt.R_world_cam),
        ((k * 0.1, np.zeros((4, 4), np.uint8)) for k in range(6)),
        on_result=lambda k, r: seen.append((k, r.state)),
    )
    assert run.valid.tolist() == [True, True, True, False, True, True]
    assert np.allclose(run.R_world_cam[3], np.eye(3))
    assert len(seen) == 6 and run.seconds >= 0.0
    assert geo.rotation_angle_rad(run.R_world_cam[5].T @ gt.R_world_cam[5]) < 1e-12


def test_rel_rot_error_is_exact_with_rounded_ground_truth() -> None:
    """Ground truth rounded to 7 significant digits (as KITTI poses are) must not inflate a
    0.2° error (arccos of the trace would report about 0.2 + δ/sin 0.2°)."""
    gt = truth()
    R = gt.R_world_cam.copy()
    R[15:] = R[15:] @ tv.so3_exp(np.radians([0.0, 0.2, 0.0]))
    rounded = np.array([[[float(f"{x:.6e}") for x in row] for row in M] for M in gt.R_world_cam])
    assert np.abs(rounded[20].T @ rounded[20] - np.eye(3)).max() > 1e-8  # not orthonormal
    noisy = RotationTrack.from_arrays(gt.timestamps_s, rounded)
    errors = rotation_errors(make_run(R), noisy)
    assert np.allclose(np.degrees(errors.rel_err_rad[15:25]), 0.2, atol=2e-4)
