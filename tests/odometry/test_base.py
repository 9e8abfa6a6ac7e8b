"""RotationTrack.from_arrays: one clear DataMismatchError for a track that does not fit."""

from __future__ import annotations

import numpy as np
import pytest

from slopedist.core.errors import DataMismatchError
from slopedist.odometry.base import RotationTrack

EYE2 = np.tile(np.eye(3), (2, 1, 1))


@pytest.mark.parametrize(
    ("t", "R", "valid", "message"),
    [
        ([0.0, 0.1], EYE2, [True], "valid must be one flag per frame \\(2\\), got shape \\(1,\\)"),
        ([0.0, 0.1], 2 * EYE2, None, "frame 0: the rotation is not a rotation matrix"),
        ([0.0, 0.1], EYE2 * [[[1]], [[-1]]], None, "frame 1: the rotation is not a rotation"),
        ([0.0, np.nan], EYE2, None, "timestamps must be finite: frame 1 at nan s"),
        ([[0.0, 0.1]], EYE2[:1], None, "one per frame \\(N,\\), got shape \\(1, 2\\)"),
        (["a", "b"], EYE2, None, "rotation track: could not convert"),
    ],
)
def test_a_track_that_does_not_fit_is_a_data_mismatch(
    t: object, R: np.ndarray, valid: object, message: str
) -> None:
    """A wrong-length ``valid`` and non-rotations were accepted (a scaled matrix's θ came out
    silently wrong in batch, while the stream refused the frame); a NaN timestamp passed the
    increasing check; text failed with numpy's bare ValueError."""
    with pytest.raises(DataMismatchError, match=message):
        RotationTrack.from_arrays(t, R, valid)  # type: ignore[arg-type]


def test_frames_without_a_rotation_may_hold_anything() -> None:
    R = np.stack([np.eye(3), 2 * np.eye(3), np.full((3, 3), np.nan)])
    track = RotationTrack.from_arrays([0.0, 0.1, 0.2], R, [True, False, True])
    assert len(track) == 3
