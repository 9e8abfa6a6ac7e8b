"""The working size of the built-in visual odometry: hand-computed scaling, and a doubled real
sequence tracked at its working size giving the rotations of the original frames."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError, DataMismatchError
from slopedist.odometry.visual import BuiltinVisualOdometry, VisualOdometryConfig
from slopedist.odometry.working_size import WorkingSize

CAMERA = Camera(1000.0, 959.5, 539.5)


def test_narrow_frames_are_kept_as_they_are() -> None:
    work = WorkingSize.choose(CAMERA, 1242, 375, 1280)
    assert not work.scaled and work.size == (1242, 375) and work.camera is CAMERA
    image = np.arange(375 * 1242, dtype=np.uint8).reshape(375, 1242)
    assert np.array_equal(work.image(image), image)
    boxes = np.array([[10.0, 20.0, 30.0, 40.0]])
    assert work.boxes(boxes) is boxes
    assert WorkingSize.choose(CAMERA, 4000, 3000, None).size == (4000, 3000)


def test_1080p_is_scaled_by_two_thirds() -> None:
    work = WorkingSize.choose(CAMERA, 1920, 1080, 1280)
    assert work.scaled and work.size == (1280, 720)
    # the centre of a 1920×1080 frame (959.5, 539.5) is the centre of 1280×720 (639.5, 359.5)
    assert work.camera.f == pytest.approx(1000.0 * 2 / 3)
    assert (work.camera.c_x, work.camera.c_y) == pytest.approx((639.5, 359.5))
    assert (work.camera.image_width, work.camera.image_height) == (1280, 720)
    # pixel (−0.5, −0.5) is the outer corner of both frames; (2.5, 2.5) → (1.5, 1.5)
    boxes = np.array([[-0.5, -0.5, 2.5, 2.5]])
    assert np.allclose(work.boxes(boxes), [[-0.5, -0.5, 1.5, 1.5]])
    pts = np.array([[1.5, 1.5], [639.5, 359.5]], dtype=np.float32)
    assert np.allclose(work.to_full(pts), [[2.5, 2.5], [959.5, 539.5]])
    image = np.zeros((1080, 1920), np.uint8)
    assert work.image(image).shape == (720, 1280)


def test_max_width_is_checked() -> None:
    with pytest.raises(ConfigurationError, match="max_width_px"):
        VisualOdometryConfig(max_width_px=10)


def test_frame_size_is_checked_at_full_size() -> None:
    vo = BuiltinVisualOdometry(CAMERA.with_image_size(1920, 1080))
    with pytest.raises(DataMismatchError, match="1280×720 px differs from the 1920×1080"):
        vo.process(np.zeros((720, 1280), np.uint8), 0.0)


def test_doubled_frames_give_the_rotations_of_the_originals(kitti_odometry_dir: Path) -> None:
    """Real seq06 frames doubled (each pixel a 2×2 block) and tracked at half their width are
    the original frames again (area averaging undoes the doubling): the same rotations and the
    same tracks, in full-frame pixels."""
    from slopedist.io.kitti.odometry import read_kitti_odometry

    seq = read_kitti_odometry(kitti_odometry_dir / "seq06_000-050")
    cam = seq.camera
    width, height = cam.image_width, cam.image_height
    assert width is not None and height is not None
    doubled_cam = Camera(2 * cam.f, 2 * cam.c_x + 0.5, 2 * cam.c_y + 0.5)
    original = BuiltinVisualOdometry(cam)
    doubled = BuiltinVisualOdometry(doubled_cam, VisualOdometryConfig(max_width_px=width))
    n_ok = 0
    for k, t, image in seq.frames():
        if k >= 15:
            break
        big = cv2.resize(image, (2 * width, 2 * height), interpolation=cv2.INTER_NEAREST)
        a = original.process(image, t)
        b = doubled.process(big, t)
        assert a.state == b.state
        if a.R_world_cam is not None and b.R_world_cam is not None:
            np.testing.assert_allclose(b.R_world_cam, a.R_world_cam, atol=1e-9)
            n_ok += 1
        np.testing.assert_allclose(doubled.tracks, 2 * original.tracks + 0.5, atol=1e-3)
    assert n_ok == 15
