"""MCAP logs read as far as they are whole: a cut log gives its frames up to the cut with a
warning, a chunk whose CRC does not match is skipped (its frames unreadable), never used.

The logs are written by rosbags (through :func:`slopedist.io.rosbag_write.write_log`) and
rewritten with the ``mcap`` package's writer, which computes chunk CRCs, in small chunks."""

from __future__ import annotations

import logging
import struct
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")
pytest.importorskip("mcap")

from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer

from slopedist.cli import main
from slopedist.core.camera import Camera
from slopedist.core.errors import InputFileError
from slopedist.io.frames import Frame, FrameStatus
from slopedist.io.log_topics import read_camera_info
from slopedist.io.mcap_log import McapLog
from slopedist.io.rosbag import LogFrameSource, log_topics
from slopedist.io.rosbag_write import ImageEncoding, LogFormat, LogFrame, LogTopics, write_log

W, H = 64, 48
N = 12
CAMERA = Camera(80.0, 31.5, 24.25).with_image_size(W, H)
TOPICS = LogTopics()
PERIOD_NS = 100_000_000
START_NS = 1_317_000_000 * 10**9
"""rosbag_write's first stamp."""


def images() -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    return [rng.integers(0, 255, (H, W, 3), dtype=np.uint8) for _ in range(N)]


def rosbags_log(tmp_path: Path) -> Path:
    """The rosbags-written MCAP file of ``N`` frames (one chunk, no CRC)."""
    frames = [LogFrame(k * PERIOD_NS, im, (0.0, 0.0, 0.0, 1.0)) for k, im in enumerate(images())]
    folder = write_log(tmp_path / "bag", frames, CAMERA, LogFormat.ROS2_MCAP, ImageEncoding.RAW)
    return next(folder.glob("*.mcap"))


def rewrite(
    src: Path,
    dst: Path,
    compression: CompressionType = CompressionType.NONE,
    index_types: IndexType = IndexType.ALL,
) -> Path:
    """``src``'s schemas, channels and messages written again by the mcap writer: a chunk per
    frame (about 10 KB of image each), with CRCs."""
    with src.open("rb") as fh, dst.open("wb") as out:
        writer = Writer(out, chunk_size=4096, compression=compression, index_types=index_types)
        writer.start(profile="ros2", library="slopedist tests")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in make_reader(fh).iter_messages():
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas.get(channel.schema_id, 0)
                )
            writer.add_message(
                channels[channel.id], message.log_time, message.data, message.publish_time
            )
        writer.finish()
    return dst


def chunks(path: Path) -> list[tuple[int, int, int, int]]:
    """``(offset, length, start ns, end ns)`` of every chunk record, from the summary."""
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    return [
        (c.chunk_start_offset, c.chunk_length, c.message_start_time, c.message_end_time)
        for c in summary.chunk_indexes
    ]


def image_chunk(path: Path, k: int) -> tuple[int, int, int, int]:
    """The chunk that holds the image of frame ``k``: of those whose time span holds its time,
    the longest (an image is 9 KB, its camera_info and IMU messages 1 KB)."""
    t = START_NS + k * PERIOD_NS
    return max((c for c in chunks(path) if c[2] <= t <= c[3]), key=lambda c: c[1])


def frames_of(path: Path) -> list[Frame]:
    return list(LogFrameSource(path, TOPICS.image))


@pytest.fixture(scope="module")
def whole(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("mcap")
    return rewrite(rosbags_log(tmp), tmp / "whole.mcap")


def test_a_whole_log_reads_as_rosbags_reads_it(whole: Path) -> None:
    from rosbags.highlevel import AnyReader

    assert len(chunks(whole)) > N  # the image of a frame fills a chunk of its own
    frames = frames_of(whole)
    assert [f.index for f in frames] == list(range(N)) and all(f.ok for f in frames)
    for frame, image in zip(frames, images()):
        np.testing.assert_array_equal(frame.image, image)
    with McapLog(whole) as log, AnyReader([whole]) as reader:
        mine = [(c.topic, t, bytes(raw)) for c, t, raw in log.messages()]
        theirs = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
        assert {c.topic: c.msgcount for c in log.connections} == {
            c.topic: c.msgcount for c in reader.connections
        }
    assert sorted(mine, key=lambda m: m[1]) == sorted(theirs, key=lambda m: m[1])


@pytest.mark.parametrize("compression", list(CompressionType))
def test_a_log_cut_in_half_gives_its_frames_up_to_the_cut_with_a_warning(
    whole: Path, tmp_path: Path, compression: CompressionType, caplog: pytest.LogCaptureFixture
) -> None:
    """What a recorder that lost power leaves: no summary, no footer, a record cut short. It was
    refused ("File end magic is invalid"), losing the whole drive."""
    log = rewrite(whole, tmp_path / "log.mcap", compression)
    data = log.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with caplog.at_level(logging.WARNING):
        frames = frames_of(cut)
    assert 3 <= len(frames) < N and all(f.ok for f in frames)
    assert [f.index for f in frames] == list(range(len(frames)))
    for frame, image in zip(frames, images()):
        np.testing.assert_array_equal(frame.image, image)
    (warning,) = [r.getMessage() for r in caplog.records if "ends at byte" in r.getMessage()]
    assert str(cut) in warning and f"ends at byte {len(data) // 2}" in warning
    assert read_camera_info(cut, TOPICS.camera_info).camera(CAMERA.height_m) == CAMERA
    counts = {t.topic: t.count for t in log_topics(cut)}
    assert len(frames) <= counts[TOPICS.image] < N


def test_a_log_cut_before_any_channel_is_refused_with_the_repair_hint(
    whole: Path, tmp_path: Path
) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole.read_bytes()[:40])
    with pytest.raises(InputFileError, match=rf"ends at byte .*mcap recover {cut}"):
        frames_of(cut)


@pytest.mark.parametrize("compression", list(CompressionType))
def test_a_chunk_whose_crc_does_not_match_is_skipped_and_its_frames_are_unreadable(
    whole: Path, tmp_path: Path, compression: CompressionType, caplog: pytest.LogCaptureFixture
) -> None:
    """400 damaged bytes inside a chunk were read without a word (all frames ok)."""
    log = rewrite(whole, tmp_path / "log.mcap", compression)
    offset, length, _, _ = image_chunk(log, 5)
    data = bytearray(log.read_bytes())
    middle = offset + length // 2
    data[middle - 200 : middle + 200] = bytes(b ^ 0x5A for b in data[middle - 200 : middle + 200])
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    with caplog.at_level(logging.WARNING):
        frames = frames_of(damaged)
    assert [f.index for f in frames] == list(range(N))
    bad = [f.index for f in frames if not f.ok]
    assert 5 in bad and len(bad) <= 2
    assert all(frames[k].status is FrameStatus.UNREADABLE for k in bad)
    assert f"chunk at byte {offset}" in frames[5].detail
    for frame, image in zip(frames, images()):
        if frame.ok:
            np.testing.assert_array_equal(frame.image, image)
    warnings = [r.getMessage() for r in caplog.records if str(damaged) in r.getMessage()]
    assert len(warnings) == 1 and f"chunk at byte {offset}" in warnings[0]


def test_a_damaged_chunk_without_message_index_marks_the_frames_of_its_time_span(
    whole: Path, tmp_path: Path
) -> None:
    log = rewrite(whole, tmp_path / "log.mcap", index_types=IndexType.CHUNK)
    offset, length, _, _ = image_chunk(log, 7)
    data = bytearray(log.read_bytes())
    data[offset + length // 2] ^= 0xFF
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    frames = frames_of(damaged)
    assert [f.index for f in frames] == list(range(N))
    assert frames[7].status is FrameStatus.UNREADABLE and "CRC" in frames[7].detail
    assert sum(not f.ok for f in frames) <= 2


def test_a_damaged_record_length_resumes_at_the_next_whole_chunk(
    whole: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    offset, _, _, _ = image_chunk(whole, 4)
    data = bytearray(whole.read_bytes())
    data[offset + 1 : offset + 9] = struct.pack("<Q", 2**40)  # a chunk longer than the file
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    with caplog.at_level(logging.WARNING):
        frames = frames_of(damaged)
    assert [f.index for f in frames] == list(range(N))
    assert not frames[4].ok and sum(f.ok for f in frames) >= N - 2
    assert any(f"bytes {offset} to" in r.getMessage() for r in caplog.records)


def test_run_on_a_damaged_log_writes_the_damaged_frames_as_unreadable(
    whole: Path, tmp_path: Path
) -> None:
    offset, length, _, _ = image_chunk(whole, 6)
    data = bytearray(whole.read_bytes())
    data[offset + length // 2] ^= 0xFF
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    boxes = tmp_path / "boxes.csv"
    boxes.write_text(
        "frame,left,top,right,bottom\n" + "".join(f"{k},20,26,40,40\n" for k in range(N))
    )
    out = tmp_path / "out"
    argv = ["run", str(damaged), "--image-topic", TOPICS.image, "--boxes", str(boxes)]
    argv += ["--method", "flat", "--odometry", "none", "--quiet", "--out", str(out)]
    assert main(argv) == 0
    rows = (out / "frames.csv").read_text().splitlines()
    header = rows[0].split(",")
    column = header.index("frame_status")
    status = {int(r.split(",")[0]): r.split(",")[column] for r in rows[1:]}
    assert status[6] == "unreadable" and list(status.values()).count("unreadable") <= 2
    assert len(status) == N
