"""Drive logs written with rosbags' writers (ROS 1, ROS 2 sqlite3, ROS 2 MCAP) read back as frames,
timestamps, camera and orientations."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

pytest.importorskip("rosbags")

from slopedist.cli import main
from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError, InputFileError, MissingInputError
from slopedist.io.frames import FrameStatus, ImageFolderSource
from slopedist.io.log_topics import (
    camera_info_topic,
    read_camera_info,
    read_orientations,
    read_speeds,
)
from slopedist.io.rosbag import (
    LogFrameSource,
    decode_image,
    is_log_path,
    log_topics,
)
from slopedist.io.rosbag_write import ImageEncoding, LogFormat, LogFrame, LogTopics, write_log

W, H = 64, 48
CAMERA = Camera(80.0, 31.5, 24.25).with_image_size(W, H)
TOPICS = LogTopics()
PERIOD_NS = 100_000_000


def synthetic_images(n: int) -> list[np.ndarray]:
    """Smooth colour gradients (JPEG keeps them close) shifted per frame."""
    y, x = np.mgrid[0:H, 0:W]
    return [
        np.dstack([(x * 4 + k * 7) % 256, (y * 5 + k * 3) % 256, (x + y + 40 * k) % 256]).astype(
            np.uint8
        )
        for k in range(n)
    ]


def log_path(tmp_path: Path, fmt: LogFormat, name: str = "log") -> Path:
    return tmp_path / (f"{name}.bag" if fmt is LogFormat.ROS1 else name)


def write(tmp_path: Path, fmt: LogFormat, enc: ImageEncoding, stamps_ns: list[int]) -> Path:
    images = synthetic_images(len(stamps_ns))
    frames = [LogFrame(t, im, (0.0, 0.0, 0.0, 1.0)) for t, im in zip(stamps_ns, images)]
    return write_log(log_path(tmp_path, fmt), frames, CAMERA, fmt, enc)


def expected_pixels(image: np.ndarray, enc: ImageEncoding) -> np.ndarray:
    if enc is ImageEncoding.JPEG:
        _, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 95])
        return np.asarray(cv2.imdecode(buf, cv2.IMREAD_COLOR))
    return image


@pytest.mark.parametrize("fmt", list(LogFormat))
@pytest.mark.parametrize("enc", [ImageEncoding.RAW, ImageEncoding.JPEG])
def test_frames_timestamps_and_camera_read_back(
    tmp_path: Path, fmt: LogFormat, enc: ImageEncoding
) -> None:
    n = 5
    path = write(tmp_path, fmt, enc, [k * PERIOD_NS for k in range(n)])
    assert is_log_path(path)
    source = LogFrameSource(path, TOPICS.image)
    frames = list(source)
    assert source.expected_frames() == n
    assert source.frame_size() == (W, H)
    assert [f.index for f in frames] == list(range(n))
    assert all(f.ok for f in frames)
    # header stamps relative to the first: exactly the folder's k / 10
    assert [f.timestamp_s for f in frames] == [k / 10.0 for k in range(n)]
    for f, image in zip(frames, synthetic_images(n)):
        assert f.image is not None
        np.testing.assert_array_equal(f.image, expected_pixels(image, enc))
    assert read_camera_info(path, camera_info_topic(TOPICS.image)).camera() == CAMERA
    stamps, quats = read_orientations(path, TOPICS.imu)
    assert np.array_equal(stamps - stamps[0], np.arange(n) * PERIOD_NS)
    np.testing.assert_array_equal(quats, np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))


def test_bare_mcap_file_reads_like_its_bag_folder(tmp_path: Path) -> None:
    path = write(tmp_path, LogFormat.ROS2_MCAP, ImageEncoding.RAW, [0, PERIOD_NS, 2 * PERIOD_NS])
    (mcap,) = path.glob("*.mcap")
    a = [(f.index, f.timestamp_s, f.image.tobytes()) for f in LogFrameSource(path, TOPICS.image)]
    b = [(f.index, f.timestamp_s, f.image.tobytes()) for f in LogFrameSource(mcap, TOPICS.image)]
    assert a == b and len(a) == 3


def test_gap_yields_missing_frames_and_keeps_indices(tmp_path: Path) -> None:
    stamps = [0, 1, 2, 3, 6, 7]  # frames 4 and 5 dropped
    path = write(
        tmp_path, LogFormat.ROS2_SQLITE3, ImageEncoding.RAW, [k * PERIOD_NS for k in stamps]
    )
    frames = list(LogFrameSource(path, TOPICS.image))
    assert [f.index for f in frames] == list(range(8))
    assert [f.status for f in frames] == [FrameStatus.OK] * 4 + [FrameStatus.MISSING] * 2 + [
        FrameStatus.OK
    ] * 2
    assert [f.timestamp_s for f in frames] == pytest.approx([k / 10 for k in range(8)])
    assert "stamp gap" in frames[4].detail


def test_out_of_order_stamp_is_an_unreadable_frame(tmp_path: Path) -> None:
    stamps = [0, 1, 2, 2, 3]  # a repeated stamp
    path = write(tmp_path, LogFormat.ROS1, ImageEncoding.RAW, [k * PERIOD_NS for k in stamps])
    frames = list(LogFrameSource(path, TOPICS.image))
    assert [f.status for f in frames] == [
        FrameStatus.OK,
        FrameStatus.OK,
        FrameStatus.OK,
        FrameStatus.UNREADABLE,
        FrameStatus.OK,
    ]
    assert "does not increase" in frames[3].detail
    assert [f.index for f in frames] == [0, 1, 2, 3, 4]


def test_given_fps_sets_the_slots(tmp_path: Path) -> None:
    # the first step is already a gap: only a given rate can tell
    path = write(tmp_path, LogFormat.ROS1, ImageEncoding.RAW, [0, 3 * PERIOD_NS, 4 * PERIOD_NS])
    frames = list(LogFrameSource(path, TOPICS.image, fps=10.0))
    assert [f.index for f in frames if f.ok] == [0, 3, 4]
    assert [f.status.value for f in frames] == ["ok", "missing", "missing", "ok", "ok"]


def test_errors_name_the_log_and_topic(tmp_path: Path) -> None:
    path = write(tmp_path, LogFormat.ROS1, ImageEncoding.RAW, [0, PERIOD_NS])
    with pytest.raises(ConfigurationError, match=r"no topic /nope.*/camera/image_raw"):
        LogFrameSource(path, "/nope")
    with pytest.raises(ConfigurationError, match="expected sensor_msgs/msg/Image"):
        LogFrameSource(path, TOPICS.imu)
    with pytest.raises(MissingInputError):
        LogFrameSource(tmp_path / "absent.bag", TOPICS.image)
    bad = tmp_path / "bad.bag"
    bad.write_bytes(b"not a bag")
    with pytest.raises(InputFileError, match=r"bad\.bag"):
        LogFrameSource(bad, TOPICS.image)


def test_log_topics_counts_and_rates(tmp_path: Path) -> None:
    path = write(
        tmp_path, LogFormat.ROS2_MCAP, ImageEncoding.JPEG, [k * PERIOD_NS for k in range(5)]
    )
    topics = {t.topic: t for t in log_topics(path)}
    assert set(topics) == {TOPICS.image, TOPICS.camera_info, TOPICS.imu}
    assert topics[TOPICS.image].msgtype == "sensor_msgs/msg/CompressedImage"
    assert topics[TOPICS.image].count == 5
    assert topics[TOPICS.image].rate_hz == pytest.approx(10.0)


def test_cli_log_info(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write(tmp_path, LogFormat.ROS1, ImageEncoding.RAW, [k * PERIOD_NS for k in range(3)])
    assert main(["log", "info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "/camera/image_raw" in out and "sensor_msgs/msg/Image" in out and "10.00" in out
    assert main(["log", "info", str(tmp_path / "none.bag")]) == 2
    assert "log not found" in capsys.readouterr().err


# --- image encodings --------------------------------------------------------------------------


def image_msg(encoding: str, data: np.ndarray, width: int, height: int, step: int) -> object:
    from rosbags.typesys import Stores, get_typestore

    T = get_typestore(Stores.ROS2_HUMBLE).types
    header = T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=""
    )
    return T["sensor_msgs/msg/Image"](
        header=header,
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=step,
        data=np.ascontiguousarray(data).reshape(-1),
    )


def test_decode_rgb_mono_and_padded_rows() -> None:
    bgr = synthetic_images(1)[0]
    rgb = bgr[:, :, ::-1]
    image, why = decode_image(image_msg("rgb8", rgb, W, H, 3 * W))
    assert why == "" and np.array_equal(image, bgr)
    padded = np.zeros((H, 3 * W + 8), np.uint8)
    padded[:, : 3 * W] = bgr.reshape(H, -1)
    image, _ = decode_image(image_msg("bgr8", padded, W, H, 3 * W + 8))
    assert np.array_equal(image, bgr)
    grey = bgr[:, :, 1].copy()
    image, _ = decode_image(image_msg("mono8", grey, W, H, W))
    assert np.array_equal(image, np.dstack([grey] * 3))
    words = grey.astype(np.uint16) << 8 | 0x7F
    image, _ = decode_image(image_msg("mono16", words.view(np.uint8), W, H, 2 * W))
    assert np.array_equal(image[:, :, 0], grey)


def test_decode_bayer_matches_opencv_demosaicing() -> None:
    bgr = synthetic_images(1)[0]
    mosaic = np.zeros((H, W), np.uint8)  # RGGB: R at (0, 0), B at (1, 1)
    mosaic[0::2, 0::2] = bgr[0::2, 0::2, 2]
    mosaic[0::2, 1::2] = bgr[0::2, 1::2, 1]
    mosaic[1::2, 0::2] = bgr[1::2, 0::2, 1]
    mosaic[1::2, 1::2] = bgr[1::2, 1::2, 0]
    image, why = decode_image(image_msg("bayer_rggb8", mosaic, W, H, W))
    assert why == ""
    # away from the border, demosaicing a smooth image gives back about the image
    inner = (slice(4, -4), slice(4, -4))
    assert np.abs(image[inner].astype(int) - bgr[inner].astype(int)).mean() < 12


def test_decode_failures_are_reasons_not_exceptions() -> None:
    image, why = decode_image(image_msg("32FC1", np.zeros(4 * W * H, np.uint8), W, H, 4 * W))
    assert image is None and "32FC1" in why
    image, why = decode_image(image_msg("bgr8", np.zeros(10, np.uint8), W, H, 3 * W))
    assert image is None and "bytes" in why


def camera_info_msg(D: list[float], model: str = "plumb_bob") -> object:
    from rosbags.typesys import Stores, get_typestore

    T = get_typestore(Stores.ROS2_HUMBLE).types
    K = np.array([[500.0, 0, 320], [0, 498.0, 240], [0, 0, 1]])
    P = np.array([[480.0, 0, 322, 0], [0, 480.0, 238, 0], [0, 0, 1, 0]])
    return T["sensor_msgs/msg/CameraInfo"](
        header=T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=""
        ),
        height=480,
        width=640,
        distortion_model=model,
        d=np.array(D, dtype=float),
        k=K.reshape(-1),
        r=np.eye(3).reshape(-1),
        p=P.reshape(-1),
        binning_x=0,
        binning_y=0,
        roi=T["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        ),
    )


def test_camera_info_raw_stream_keeps_the_distortion_rectified_stream_uses_p() -> None:
    from slopedist.io.log_topics import intrinsics_from_info

    raw = intrinsics_from_info(camera_info_msg([-0.3, 0.1, 0.0, 0.0, 0.0]), rectified=False)
    assert raw.K[0, 0] == 500.0 and raw.K[1, 1] == 498.0
    assert raw.dist.tolist() == [-0.3, 0.1, 0.0, 0.0, 0.0] and not raw.is_ideal
    assert raw.image_size == (640, 480)
    rect = intrinsics_from_info(camera_info_msg([-0.3, 0.1, 0.0, 0.0, 0.0]), rectified=True)
    assert rect.is_ideal and rect.camera().f == 480.0 and rect.camera().c_x == 322.0
    fisheye = intrinsics_from_info(camera_info_msg([0.1, 0.01, 0, 0], "equidistant"), False)
    assert fisheye.fisheye and fisheye.dist.size == 4
    undistorted = intrinsics_from_info(camera_info_msg([0.0] * 5), rectified=False)
    assert undistorted.is_ideal and undistorted.K[0, 0] == 480.0  # P, as for a mono camera


def test_camera_info_topic_names() -> None:
    assert camera_info_topic("/cam/image_raw") == "/cam/camera_info"
    assert camera_info_topic("/cam/image_rect/compressed") == "/cam/camera_info"


# --- real frames ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("fmt", "enc"),
    [
        (LogFormat.ROS1, ImageEncoding.RAW),
        (LogFormat.ROS2_SQLITE3, ImageEncoding.JPEG),
        (LogFormat.ROS2_MCAP, ImageEncoding.RAW),
    ],
)
def test_real_frames_read_back_like_the_folder(
    kitti_raw_lead_dir: Path, tmp_path: Path, fmt: LogFormat, enc: ImageEncoding
) -> None:
    from slopedist.io.kitti.raw import KittiRawDrive

    drive = KittiRawDrive.open(kitti_raw_lead_dir)
    folder = [f for f in ImageFolderSource(drive.image_dir) if f.index < 8]
    camera = drive.calib.camera().with_image_size(1242, 375)
    frames = [LogFrame(f.index * PERIOD_NS, f.image) for f in folder if f.image is not None]
    path = write_log(log_path(tmp_path, fmt), frames, camera, fmt, enc)
    read = list(LogFrameSource(path, TOPICS.image))
    assert [(f.index, f.timestamp_s) for f in read] == [(f.index, f.timestamp_s) for f in folder]
    for a, b in zip(read, folder):
        assert a.image is not None and b.image is not None
        np.testing.assert_array_equal(a.image, expected_pixels(b.image, enc))
    got = read_camera_info(path, TOPICS.camera_info)
    assert got.is_ideal and got.camera(camera.height_m) == camera


# --- damaged logs -----------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", list(LogFormat))
def test_damaged_logs_give_clean_errors_or_unreadable_frames(
    tmp_path: Path, fmt: LogFormat
) -> None:
    from slopedist.core.errors import SlopedistError

    path = write(tmp_path, fmt, ImageEncoding.RAW, [k * PERIOD_NS for k in range(4)])
    storage = path if path.is_file() else next(p for p in path.iterdir() if p.suffix != ".yaml")
    data = storage.read_bytes()
    rng = np.random.default_rng(7)
    readers = (
        lambda p: log_topics(p),
        lambda p: list(LogFrameSource(p, TOPICS.image)),
        lambda p: read_camera_info(p, TOPICS.camera_info),
        lambda p: read_orientations(p, TOPICS.imu),
    )
    outcomes = {"ok": 0, "clean": 0}
    for case in range(24):
        damaged = bytearray(data)
        if case % 2:
            damaged = damaged[: int(rng.integers(0, len(damaged)))]
        else:
            for _ in range(5):
                damaged[int(rng.integers(0, len(damaged)))] = int(rng.integers(0, 256))
        target = tmp_path / f"damaged{case}{storage.suffix}"
        target.write_bytes(bytes(damaged))
        for read in readers:
            try:
                read(target)
                outcomes["ok"] += 1
            except SlopedistError as exc:
                assert str(target) in str(exc)
                outcomes["clean"] += 1
    assert outcomes["clean"] > 12 and outcomes["ok"] > 12


def test_imu_without_orientation_is_refused(tmp_path: Path) -> None:
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    T = store.types
    V = T["geometry_msgs/msg/Vector3"]
    msg = T["sensor_msgs/msg/Imu"](
        header=T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="imu"
        ),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=np.array([-1.0, *[0.0] * 8]),
        angular_velocity=V(x=0.0, y=0.0, z=0.0),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=V(x=0.0, y=0.0, z=9.81),
        linear_acceleration_covariance=np.zeros(9),
    )
    with Writer(tmp_path / "imu", version=9) as writer:
        conn = writer.add_connection("/imu", msg.__msgtype__, typestore=store)
        writer.write(conn, 1_000_000_000, store.serialize_cdr(msg, msg.__msgtype__))
    with pytest.raises(InputFileError, match=r"field '/imu'.*no orientation"):
        read_orientations(tmp_path / "imu", "/imu")


@pytest.mark.parametrize("topic", [TOPICS.imu, TOPICS.odometry])
def test_a_nan_orientation_or_speed_names_the_message(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], topic: str
) -> None:
    """An IMU sample with a NaN quaternion component stopped `run --rotation-topic` with an
    internal error (scipy's "zero norm quaternions"); a NaN speed gave NaN headways."""
    images = synthetic_images(4)
    frames = [
        LogFrame(
            k * PERIOD_NS,
            im,
            (math.nan, 0.0, 0.0, 1.0) if topic == TOPICS.imu and k == 2 else (0.0, 0.0, 0.0, 1.0),
            math.inf if topic == TOPICS.odometry and k == 2 else 10.0,
        )
        for k, im in enumerate(images)
    ]
    path = write_log(tmp_path / "log", frames, CAMERA)
    read = read_orientations if topic == TOPICS.imu else read_speeds
    where = rf"field '{topic}': message 2: stamp 1317000000.200000000 s: a NaN or infinite value"
    with pytest.raises(InputFileError, match=where):
        read(path, topic)
    option = "--rotation-topic" if topic == TOPICS.imu else "--speed-topic"
    boxes = tmp_path / "boxes.csv"
    boxes.write_text("frame,left,top,right,bottom\n0,20,30,40,40\n")
    argv = ["run", str(path), "--image-topic", TOPICS.image, option, topic, "--boxes", str(boxes)]
    method = ["--method", "imu"] if topic == TOPICS.imu else ["--method", "flat"]
    assert main([*argv, *method, "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "message 2" in err and "internal error" not in err


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("d", [1e6, 0.0, 0.0, 0.0, 0.0], "not a lens"),
        ("k", [10.0, 0.0, 31.5, 0.0, 10.0, 24.25, 0.0, 0.0, 1.0], "focal length f = 10 px"),
        ("k", [80.0, 0.0, 500.0, 0.0, 80.0, 24.25, 0.0, 0.0, 1.0], "principal point c_x"),
    ],
)
def test_an_implausible_camera_info_names_the_log_and_topic(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    field: str,
    value: list[float],
    message: str,
) -> None:
    """A camera_info whose lens model moves the image's edge 50× (or whose focal length or
    principal point is implausible) failed with the calibration file's message but no file:
    the log was not named."""
    import dataclasses

    from slopedist.io import rosbag_write

    written = rosbag_write._Messages.camera_info

    def camera_info(self: object, *args: object) -> object:
        msg = written(self, *args)  # type: ignore[arg-type]
        changed = {field: np.asarray(value)}
        if field == "k":  # P too: a camera without distortion is read from P
            changed["p"] = np.hstack([np.reshape(value, (3, 3)), np.zeros((3, 1))]).reshape(-1)
        return dataclasses.replace(msg, **changed)  # type: ignore[call-overload]

    monkeypatch.setattr(rosbag_write._Messages, "camera_info", camera_info)
    path = write(tmp_path, LogFormat.ROS2_MCAP, ImageEncoding.RAW, [0, PERIOD_NS])
    where = rf"{path.name}, field '{TOPICS.camera_info}': not a usable CameraInfo: .*{message}"
    with pytest.raises(InputFileError, match=where):
        read_camera_info(path, TOPICS.camera_info)
    boxes = tmp_path / "boxes.csv"
    boxes.write_text("frame,left,top,right,bottom\n0,20,20,40,40\n", encoding="utf-8")
    args = ["run", str(path), "--image-topic", TOPICS.image, "--boxes", str(boxes)]
    code = main([*args, "--odometry", "none", "--method", "flat", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and f"{path.name}, field '{TOPICS.camera_info}'" in err and message in err


def test_a_camera_info_that_changes_during_the_log_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A camera_info whose focal length changed from the third message on (a zoom, another
    calibration loaded) was read from its first message only: every frame after the change had
    its distances `ok` and 40 % off."""
    from slopedist.io import rosbag_write

    written = rosbag_write._Messages.camera_info
    zoomed = Camera(112.0, 31.5, 24.25).with_image_size(W, H)

    def camera_info(self: object, header: object, camera: Camera, w: int, h: int) -> object:
        later = header.stamp.nanosec >= 2 * PERIOD_NS  # type: ignore[attr-defined]
        return written(self, header, zoomed if later else camera, w, h)  # type: ignore[arg-type]

    monkeypatch.setattr(rosbag_write._Messages, "camera_info", camera_info)
    path = write(
        tmp_path, LogFormat.ROS2_MCAP, ImageEncoding.RAW, [k * PERIOD_NS for k in range(4)]
    )
    where = (
        rf"field '{TOPICS.camera_info}': message 2 \(stamp 1317000000.200000000 s\) changes the "
        r"calibration: fx 112, .* the first message has fx 80, "
    )
    with pytest.raises(InputFileError, match=where):
        read_camera_info(path, TOPICS.camera_info)
    boxes = tmp_path / "boxes.csv"
    boxes.write_text("frame,left,top,right,bottom\n0,20,30,40,40\n")
    argv = ["run", str(path), "--image-topic", TOPICS.image, "--boxes", str(boxes)]
    assert (
        main([*argv, "--method", "flat", "--odometry", "none", "--out", str(tmp_path / "o")]) == 2
    )
    assert "changes the calibration" in capsys.readouterr().err


def test_repeated_camera_info_messages_read_as_one(tmp_path: Path) -> None:
    path = write(tmp_path, LogFormat.ROS1, ImageEncoding.RAW, [k * PERIOD_NS for k in range(5)])
    got = read_camera_info(path, TOPICS.camera_info)
    assert got.camera(CAMERA.height_m) == CAMERA


def test_logs_of_a_crashed_recorder_say_how_to_repair_them(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A ROS 2 bag folder without metadata.yaml (the recorder writes it on closing) was taken for
    an image folder ("--image-topic is for drive logs …, not FOLDER"; `log info`: "Expected
    metadata file"); an MCAP cut before anything in it is whole said only "File end magic is
    invalid" (one cut later reads up to the cut: tests/io/test_mcap_log.py)."""
    stamps = [k * PERIOD_NS for k in range(3)]
    folder = write(tmp_path, LogFormat.ROS2_SQLITE3, ImageEncoding.RAW, stamps)
    (folder / "metadata.yaml").unlink()
    boxes = tmp_path / "boxes.csv"
    boxes.write_text("frame,left,top,right,bottom\n0,20,30,40,40\n")
    run = ["run", str(folder), "--image-topic", TOPICS.image, "--boxes", str(boxes)]
    for argv in (["log", "info", str(folder)], [*run, "--out", str(tmp_path / "o"), "--quiet"]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "without metadata.yaml" in err and str(folder / "log.db3") in err
    assert {t.count for t in log_topics(folder / "log.db3")} == {3}  # the storage file reads
    (tmp_path / "m").mkdir()
    bag = write(tmp_path / "m", LogFormat.ROS2_MCAP, ImageEncoding.RAW, stamps)
    mcap = next(bag.glob("*.mcap"))
    cut = tmp_path / "cut.mcap"  # cut before its first channel: nothing to read up to the cut
    cut.write_bytes(mcap.read_bytes()[:60])
    with pytest.raises(InputFileError, match=rf"mcap recover {cut} -o repaired.mcap"):
        log_topics(cut)


def test_a_folder_that_is_not_a_log_is_not_called_a_crashed_bag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`log info FOLDER` on a folder of anything else said "a ROS 2 bag folder without
    metadata.yaml (its recorder stopped without closing it?) ... ros2 bag reindex"."""
    folder = tmp_path / "frames"
    folder.mkdir()
    (folder / "000000.png").write_bytes(b"not a log")
    assert main(["log", "info", str(folder)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"slopedist: error: {folder}: not a log")
    assert "reindex" not in err and "recorder" not in err


def test_a_topic_whose_images_never_decode_says_why(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A camera publishing `yuv422` (usb_cam's default) failed with "no image on T decodes",
    without the encoding."""
    import dataclasses

    from slopedist.io import rosbag_write

    written = rosbag_write._Messages.image

    def image(self: object, *args: object) -> object:
        return dataclasses.replace(written(self, *args), encoding="yuv422")  # type: ignore[arg-type]

    monkeypatch.setattr(rosbag_write._Messages, "image", image)
    path = write(tmp_path, LogFormat.ROS2_MCAP, ImageEncoding.RAW, [0, PERIOD_NS])
    source = LogFrameSource(path, TOPICS.image)
    with pytest.raises(InputFileError, match=r"decodes \(message 0: image encoding 'yuv422' is"):
        source.frame_size()


def test_a_stamp_that_does_not_increase_is_named_to_the_nanosecond() -> None:
    """Stamps since 1970 printed through a float (``t_ns * 1e-9``) lost their last digits:
    a repeated stamp 1317000000.123456789 s read 1317000000.123456955 s."""
    from slopedist.io.rosbag import _Slots

    slots = _Slots(None)
    slots.place(1_317_000_000_123_456_789)
    problem = slots.place(1_317_000_000_123_456_789)[2]
    assert "header stamp 1317000000.123456789 s does not increase" in problem
    assert problem.endswith("(the frame before has 1317000000.123456789 s)")
