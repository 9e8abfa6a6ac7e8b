"""PyAV video frames timed by their presentation timestamps (variable frame rate)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("av")

from slopedist.core.errors import InputFileError, MissingInputError
from slopedist.io.frames import FrameStatus, VideoSource
from slopedist.io.overlay import H264Writer
from slopedist.io.video import PyAVVideoSource, open_video

W, H = 64, 48
VFR_TIMES = [0.0, 0.033, 0.07, 0.1, 0.25, 0.283, 0.4, 1.0, 1.05]
"""A dashcam that stalls: steps of 33 to 600 ms."""


def write_vfr(path: Path, times: list[float]) -> Path:
    writer = H264Writer(path, (W, H), 30.0)
    for k, t in enumerate(times):
        writer.write(np.full((H, W, 3), 20 * k, np.uint8), t)
    writer.close()
    return path


def test_vfr_mp4_gives_the_true_timestamps(tmp_path: Path) -> None:
    path = write_vfr(tmp_path / "vfr.mp4", VFR_TIMES)
    frames = list(PyAVVideoSource(path))
    assert [f.index for f in frames] == list(range(len(VFR_TIMES)))
    assert all(f.ok for f in frames)
    assert [f.timestamp_s for f in frames] == pytest.approx(VFR_TIMES, abs=1e-9)
    # pixels decode (grey levels survive H.264 within a few levels)
    assert [int(f.image[H // 2, W // 2, 0]) for f in frames] == pytest.approx(
        [20 * k for k in range(len(VFR_TIMES))], abs=3
    )
    # OpenCV's nominal rate would put frame 7 at about 7 / 30 s, not 1.0 s
    assert frames[7].timestamp_s == pytest.approx(1.0)


def test_open_video_prefers_pyav_and_forced_fps_uses_opencv(tmp_path: Path) -> None:
    path = write_vfr(tmp_path / "vfr.mp4", VFR_TIMES)
    assert isinstance(open_video(path), PyAVVideoSource)
    forced = open_video(path, fps=10.0)
    assert isinstance(forced, VideoSource)
    assert [f.timestamp_s for f in forced][:3] == [0.0, 0.1, 0.2]


def test_frame_size_and_given_timestamps(tmp_path: Path) -> None:
    path = write_vfr(tmp_path / "vfr.mp4", VFR_TIMES[:3])
    source = PyAVVideoSource(path, timestamps_s=np.array([5.0, 6.0, 7.0]))
    assert source.frame_size() == (W, H)
    assert [f.timestamp_s for f in source] == [5.0, 6.0, 7.0]
    short = PyAVVideoSource(path, timestamps_s=np.array([5.0]))
    with pytest.raises(InputFileError, match="1 timestamps given"):
        list(short)


def test_non_increasing_given_time_is_unreadable(tmp_path: Path) -> None:
    path = write_vfr(tmp_path / "vfr.mp4", VFR_TIMES[:3])
    frames = list(PyAVVideoSource(path, timestamps_s=np.array([0.0, 0.0, 1.0])))
    assert [f.status for f in frames] == [FrameStatus.OK, FrameStatus.UNREADABLE, FrameStatus.OK]
    assert "does not increase" in frames[1].detail


def write_rotated(path: Path, degrees: int) -> Path:
    """A 64×48 MPEG-4 video whose display matrix turns it by ``degrees`` (as a phone writes)."""
    import av

    with av.open(str(path), "w") as container:
        stream = container.add_stream("mpeg4", rate=10)
        stream.width, stream.height, stream.pix_fmt = W, H, "yuv420p"
        stream.set_display_rotation(degrees)
        image = np.zeros((H, W, 3), np.uint8)
        image[: H // 2, : W // 2] = 255  # a white top-left quarter shows the orientation
        for _ in range(3):
            for packet in stream.encode(av.VideoFrame.from_ndarray(image, format="bgr24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    return path


@pytest.mark.parametrize("degrees", [90, 180, 270])
def test_rotation_metadata_is_applied_as_opencv_and_players_do(
    tmp_path: Path, degrees: int
) -> None:
    # a phone video or an upside-down dashcam: the boxes of a detector that saw the frames
    # upright (OpenCV turns them) must meet the same pixels here, with or without PyAV
    path = write_rotated(tmp_path / f"rot{degrees}.mp4", degrees)
    pyav, opencv = PyAVVideoSource(path), VideoSource(path, 10.0)
    assert pyav.frame_size() == opencv.frame_size()
    first = next(iter(pyav))
    reference = next(iter(opencv))
    assert first.image is not None and reference.image is not None
    assert first.image.shape == reference.image.shape
    assert np.abs(first.image.astype(int) - reference.image).mean() < 3
    assert all(f.ok for f in pyav)


def test_bad_files(tmp_path: Path) -> None:
    with pytest.raises(MissingInputError):
        PyAVVideoSource(tmp_path / "none.mp4")
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"no video here")
    with pytest.raises(InputFileError, match="cannot be opened"):
        PyAVVideoSource(bad)


def test_run_on_a_vfr_video_writes_the_true_times_to_frames_csv(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import csv

    from slopedist.cli import main
    from slopedist.io.detections.boxes import BoxTable
    from slopedist.io.detections.writers import write_box_csv

    video = write_vfr(tmp_path / "dashcam.mp4", VFR_TIMES)
    (tmp_path / "calib.txt").write_text("P2: 60 0 32 0 0 60 24 0 0 0 1 0\n")
    n = len(VFR_TIMES)
    boxes = BoxTable.build(np.arange(n), np.tile([20.0, 30.0, 40.0, 40.0], (n, 1)))
    write_box_csv(boxes, tmp_path / "boxes.csv")
    args = ["run", str(video), "--calib", str(tmp_path / "calib.txt")]
    args += ["--boxes", str(tmp_path / "boxes.csv"), "--method", "flat", "--odometry", "none"]
    assert main([*args, "--out", str(tmp_path / "out"), "--quiet"]) == 0, capsys.readouterr().err
    with (tmp_path / "out" / "frames.csv").open(newline="") as fh:
        times = [float(r["timestamp_s"]) for r in csv.DictReader(fh)]
    assert times == pytest.approx(VFR_TIMES, abs=1e-6)


def write_textured(path: Path, codec: str, n: int = 24, gop: int = 12) -> Path:
    """``n`` frames of a moving texture (320×240, a key frame every ``gop``) in ``codec``."""
    import av

    rng = np.random.default_rng(1)
    base = np.repeat(np.repeat(rng.integers(0, 255, (60, 80, 3), np.uint8), 4, 0), 4, 1)
    with av.open(str(path), "w") as container:
        stream = container.add_stream(codec, rate=10)
        stream.width, stream.height, stream.pix_fmt = 320, 240, "yuv420p"
        stream.gop_size = gop
        for k in range(n):
            image = np.roll(base, 3 * k, axis=1)
            for packet in stream.encode(av.VideoFrame.from_ndarray(image, format="bgr24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    return path


def middle_of_a_predicted_frame(path: Path) -> int:
    """The byte in the middle of the largest packet of a frame predicted from others, early in
    the first group of pictures (its slice data: damage there is concealed, not a hard
    error; and the key frame of the next group is far enough on to end it)."""
    import av

    with av.open(str(path)) as container:
        packets = [p for p in container.demux(container.streams.video[0]) if p.size]
    first_gop = [p for p in packets[1:6] if not p.is_keyframe]
    largest = max(first_gop, key=lambda p: p.size)
    return int(largest.pos) + largest.size // 2


@pytest.mark.parametrize("codec", ["mpeg4", "libx264"])
def test_frames_the_decoder_reports_damaged_are_unreadable_never_used(
    tmp_path: Path, codec: str
) -> None:
    """Bytes flipped in ``mdat`` (libav: "ac-tex damaged", "Error at MB") gave every frame
    ``ok``, θ −0.25° instead of +0.06° and distances up to 23 % long."""
    path = write_textured(tmp_path / "clean.mp4", codec)
    clean = list(PyAVVideoSource(path))
    assert len(clean) == 24 and all(f.ok for f in clean)
    data = bytearray(path.read_bytes())
    start = middle_of_a_predicted_frame(path)
    data[start - 8 : start + 8] = bytes(b ^ 0xFF for b in data[start - 8 : start + 8])
    damaged_path = tmp_path / "damaged.mp4"
    damaged_path.write_bytes(bytes(data))
    damaged = list(PyAVVideoSource(damaged_path))
    assert [f.index for f in damaged] == list(range(24))
    changed = [
        k
        for k, (a, b) in enumerate(zip(clean, damaged))
        if b.image is None or np.abs(a.image.astype(int) - b.image).mean() > 0.5
    ]
    assert changed  # the damage shows
    for k in changed:  # and no frame that shows it is used
        assert damaged[k].status is FrameStatus.UNREADABLE, (k, damaged[k].detail)
        assert "damage" in damaged[k].detail
    assert damaged[-1].ok  # the next key frame ends it
