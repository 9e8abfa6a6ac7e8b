"""Frame sources: image folders and video files, their timestamps, bad input, calibration."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slopedist.core.camera import Camera
from slopedist.core.errors import (
    ConfigurationError,
    DataMismatchError,
    InputFileError,
    MissingInputError,
)
from slopedist.io.frames import (
    DEFAULT_FPS,
    FrameStatus,
    ImageFolderSource,
    VideoSource,
    check_box_frames,
    check_calibration,
    check_implied_image,
    implied_image_sizes,
    open_frames,
    read_timestamps,
)

W, H = 64, 48


def _image(k: int, w: int = W, h: int = H) -> np.ndarray:
    img = np.zeros((h, w, 3), np.uint8)
    img[:] = (10 * k) % 250
    return img


def make_folder(root: Path, indices: list[int], *, digits: int = 6, ext: str = ".png") -> Path:
    root.mkdir(parents=True, exist_ok=True)
    for k in indices:
        assert cv2.imwrite(str(root / f"{k:0{digits}d}{ext}"), _image(k))
    return root


def make_video(path: Path, n: int, fps: float = 5.0) -> Path:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"mp4v"), fps, (W, H))
    assert writer.isOpened()
    for k in range(n):
        writer.write(_image(k))
    writer.release()
    return path


def test_numbered_folder_yields_frames_in_order_with_default_fps(tmp_path: Path) -> None:
    src = open_frames(make_folder(tmp_path / "f", [0, 1, 2, 3]))
    assert isinstance(src, ImageFolderSource)
    frames = list(src)
    assert [f.index for f in frames] == [0, 1, 2, 3]
    assert [f.timestamp_s for f in frames] == pytest.approx([0, 0.1, 0.2, 0.3])
    assert all(f.ok and f.image is not None and f.image.shape == (H, W, 3) for f in frames)
    assert frames[2].image is not None and int(frames[2].image[0, 0, 0]) == 20
    assert src.frame_size() == (W, H)
    assert src.expected_frames() == 4
    assert DEFAULT_FPS == 10.0


def test_gap_in_numbering_is_a_missing_frame_and_timing_follows_the_number(tmp_path: Path) -> None:
    frames = list(open_frames(make_folder(tmp_path / "f", [3, 4, 6]), fps=20))
    assert [(f.index, f.status) for f in frames] == [
        (3, FrameStatus.OK),
        (4, FrameStatus.OK),
        (5, FrameStatus.MISSING),
        (6, FrameStatus.OK),
    ]
    assert frames[2].image is None and "5" in frames[2].detail
    assert [f.timestamp_s for f in frames] == pytest.approx([0.15, 0.2, 0.25, 0.3])


def test_unreadable_and_resized_files_are_per_frame_states(tmp_path: Path) -> None:
    root = make_folder(tmp_path / "f", [0, 1, 3])
    (root / "000002.png").write_bytes(b"not a png at all")
    cv2.imwrite(str(root / "000004.png"), _image(4, 2 * W, H))
    frames = list(open_frames(root))
    assert [f.status for f in frames] == [
        FrameStatus.OK,
        FrameStatus.OK,
        FrameStatus.UNREADABLE,
        FrameStatus.OK,
        FrameStatus.SIZE_CHANGED,
    ]
    assert "000002.png" in frames[2].detail
    assert "128×48" in frames[4].detail and frames[4].image is None


def test_unnumbered_names_are_numbered_in_sorted_order(tmp_path: Path) -> None:
    root = tmp_path / "f"
    root.mkdir()
    for name in ("b.jpg", "a.PNG", "c.jpeg"):
        cv2.imwrite(str(root / name), _image(1))
    (root / "notes.txt").write_text("ignored")
    frames = list(open_frames(root))
    assert [(f.index, f.source) for f in frames] == [(0, "a.PNG"), (1, "b.jpg"), (2, "c.jpeg")]


def test_duplicate_frame_numbers_name_both_files(tmp_path: Path) -> None:
    root = make_folder(tmp_path / "f", [1])
    cv2.imwrite(str(root / "01.png"), _image(1))
    with pytest.raises(InputFileError, match="frame number 1"):
        open_frames(root)


def test_missing_and_empty_inputs(tmp_path: Path) -> None:
    with pytest.raises(MissingInputError, match="frames not found"):
        open_frames(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(MissingInputError, match="no image files"):
        open_frames(tmp_path / "empty")


def test_video_frames_and_container_rate(tmp_path: Path) -> None:
    src = open_frames(make_video(tmp_path / "v.mp4", 6, fps=5.0))
    assert isinstance(src, VideoSource)
    frames = list(src)
    assert [f.index for f in frames] == list(range(6))
    assert [f.timestamp_s for f in frames] == pytest.approx([0, 0.2, 0.4, 0.6, 0.8, 1.0])
    assert src.frame_size() == (W, H)
    # lossy codec: the grey level of each frame survives approximately
    assert [round(float(f.image.mean()) / 10) for f in frames if f.image is not None] == list(
        range(6)
    )
    assert [f.timestamp_s for f in open_frames(tmp_path / "v.mp4", fps=10)][:2] == pytest.approx(
        [0, 0.1]
    )


def test_file_that_is_not_a_video_is_a_clear_error(tmp_path: Path) -> None:
    bad = tmp_path / "clip.mp4"
    bad.write_text("this is not a video\n")
    with pytest.raises(InputFileError, match=r"clip\.mp4.*cannot be opened as a video"):
        open_frames(bad)


def test_timestamps_file_seconds_and_kitti_datetimes(tmp_path: Path) -> None:
    secs = tmp_path / "t.txt"
    secs.write_text("# seconds\n0.0\n0.05\n0.2\n")
    assert read_timestamps(secs) == pytest.approx([0, 0.05, 0.2])
    kitti = tmp_path / "timestamps.txt"
    kitti.write_text(
        "2011-09-26 13:02:25.964389445\n2011-09-26 13:02:26.074898324\n"
        "2011-09-26 13:02:26.185451000\n"
    )
    assert read_timestamps(kitti) == pytest.approx([0, 0.110509, 0.221062], abs=2e-6)
    frames = list(open_frames(make_folder(tmp_path / "f", [0, 1, 2]), timestamps=secs))
    assert [f.timestamp_s for f in frames] == pytest.approx([0, 0.05, 0.2])


def test_timestamps_going_backwards_name_the_line(tmp_path: Path) -> None:
    path = tmp_path / "t.txt"
    path.write_text("0.0\n0.1\n0.05\n")
    with pytest.raises(InputFileError, match=r"t\.txt, line 3.*does not increase"):
        read_timestamps(path)
    path.write_text("0.0\nzero point one\n")
    with pytest.raises(InputFileError, match="line 2"):
        read_timestamps(path)


def test_timestamps_in_milliseconds_are_refused_naming_the_unit(tmp_path: Path) -> None:
    # 15 Hz in milliseconds read as seconds: every frame 67 s after the last, a gap of the
    # odometry each time, and the run said "odometry: ok"
    path = tmp_path / "t.txt"
    path.write_text("".join(f"{round(k * 1000 / 15)}\n" for k in range(30)))
    with pytest.raises(InputFileError, match=r"t\.txt, field 'timestamp'.*67 s apart.*millisec"):
        read_timestamps(path)
    path.write_text("".join(f"{1.7e9 + k / 15!r}\n" for k in range(30)))  # Unix seconds: fine
    assert np.diff(read_timestamps(path)) == pytest.approx(1 / 15, abs=1e-6)


def test_too_few_timestamps(tmp_path: Path) -> None:
    ts = tmp_path / "t.txt"
    ts.write_text("0\n0.1\n")
    with pytest.raises(DataMismatchError, match="2 timestamps"):
        open_frames(make_folder(tmp_path / "f", [0, 1, 2]), timestamps=ts)
    video = make_video(tmp_path / "v.mp4", 4)
    with pytest.raises(DataMismatchError, match="frame 2"):
        list(open_frames(video, timestamps=ts))


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(min_value=0.001, max_value=10.0), min_size=1, max_size=30))
def test_read_timestamps_round_trips_increasing_seconds(
    tmp_path_factory: pytest.TempPathFactory, steps: list[float]
) -> None:
    t = np.cumsum(steps)
    path = tmp_path_factory.mktemp("ts") / "t.txt"
    path.write_text("".join(f"{float(v)!r}\n" for v in t))
    assert read_timestamps(path) == pytest.approx(t, rel=0, abs=0)


KITTI = Camera(721.5377, 609.5593, 172.854)


def test_calibration_matches_kitti_frames() -> None:
    check_calibration(KITTI, 1242, 375)


@pytest.mark.parametrize(
    ("size", "message"),
    [
        ((621, 188), "principal point c_x = 609.6 px is far from the centre"),
        ((600, 375), "outside"),
        ((1242, 700), "c_y = 172.9 px is far from the centre"),
    ],
)
def test_calibration_of_other_frames_is_refused(size: tuple[int, int], message: str) -> None:
    with pytest.raises(DataMismatchError, match=message):
        check_calibration(KITTI, *size, where="clip.mp4")


def test_a_calibration_of_frames_of_another_resolution_is_refused() -> None:
    """KITTI's calibration scaled by 1.5 (frames 1.5 times as large) on KITTI's frames: c_x
    is 24 % of the width off the centre (it passed a 25 % bound, and every car was ok 7–24 %
    too near); a bonnet cropped off the bottom still passes (c_y 20 % off)."""
    scaled = Camera(721.5377 * 1.5, 609.5593 * 1.5, 172.854 * 1.5)
    with pytest.raises(DataMismatchError, match=r"c_x = 914\.3 px is far from the centre"):
        check_calibration(scaled, 1242, 375)
    check_calibration(Camera(721.5377, 609.5593, 375 / 2 + 0.2 * 375), 1242, 375)


@pytest.mark.parametrize(
    ("files", "box_frames", "refused"),
    [
        (range(5), [1, 2, 5], True),  # counted from 1 against files from 0
        (range(5), [0, 2, 4], False),
        (range(5), [1, 4], False),  # no box past the last frame: cannot tell
        (range(1, 6), [1, 5], False),  # files numbered from 1 too
        (range(5), [6], False),  # not one past: the run warns of boxes without frames
    ],
)
def test_box_frames_counted_from_one_are_refused(
    tmp_path: Path, files: range, box_frames: list[int], refused: bool
) -> None:
    source = ImageFolderSource(make_folder(tmp_path / "f", list(files)))
    frames = np.array(box_frames, dtype=np.int64)
    if not refused:
        check_box_frames(frames, source)
        return
    with pytest.raises(DataMismatchError, match=r"frames 1\.\.5 but .* has frames 0\.\.4"):
        check_box_frames(frames, source)


def test_calibration_with_known_size_must_match() -> None:
    with pytest.raises(DataMismatchError, match="calibration is for 1242×375"):
        check_calibration(KITTI.with_image_size(1242, 375), 1241, 376)


@pytest.mark.parametrize(("f", "width", "fov"), [(52.0, 1242, "170.4°"), (20_000.0, 1000, "2.9°")])
def test_focal_length_must_fit_the_image_width(f: float, width: int, fov: str) -> None:
    check_calibration(Camera(60.0, 609.6, 172.9), 1242, 375)  # 169°: a fisheye
    check_calibration(Camera(12_000.0, 609.6, 172.9), 1242, 375)  # 5.9°: a telephoto
    with pytest.raises(DataMismatchError, match=rf"field of view of {fov}"):
        check_calibration(Camera(f, width / 2, 172.9), width, 375)


def test_the_images_a_principal_point_fits_are_those_check_calibration_accepts() -> None:
    kitti = Camera(721.5, 609.6, 172.9)
    (w_lo, w_hi), (h_lo, h_hi) = implied_image_sizes(kitti)
    assert w_lo < 1242 < w_hi and h_lo < 375 < h_hi
    check_implied_image(kitti)
    for width, height in ((int(w_lo) + 1, 375), (int(w_hi), 375), (1242, int(h_hi))):
        check_calibration(kitti, width, height)  # the edges of the range are accepted
    for width, height in ((int(w_lo) - 1, 375), (int(w_hi) + 2, 375), (1242, int(h_hi) + 2)):
        with pytest.raises(DataMismatchError):
            check_calibration(kitti, width, height)


@pytest.mark.parametrize(
    ("camera", "said"),
    [
        (Camera(721.5, 609.6, 0.0), "c_y = 0 px is on or beyond the top edge"),
        (Camera(721.5, -3.0, 172.9), "c_x = -3 px is on or beyond the left edge"),
        (Camera(721.5, 609.6, 1e-320), "fits only images under a pixel in height"),
        (Camera(20000.0, 30.0, 172.9), "focal length f = 20000 px fits no image"),
    ],
)
def test_a_camera_that_fits_no_image_is_refused(camera: Camera, said: str) -> None:
    with pytest.raises(ConfigurationError, match=said):
        check_implied_image(camera)
