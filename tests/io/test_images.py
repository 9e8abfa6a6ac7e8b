"""Image sizes from headers, and decompression bombs refused before any pixel is decoded."""

from __future__ import annotations

import resource
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from slopedist.core.errors import InputFileError
from slopedist.io import images
from slopedist.io.depth.files import read_kitti_depth_png
from slopedist.io.frames import FrameStatus, open_frames
from slopedist.io.images import (
    header_image_size,
    image_size_problem,
    read_colour,
    read_image_file,
)


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_bomb(path: Path, side: int = 30_000, rows_per_block: int = 1_000) -> Path:
    """A valid greyscale PNG of side × side zero pixels (≈0.9 MB for 30000²), written without
    ever holding the pixels: one deflate block of ``rows_per_block`` rows is compressed once
    (ended by a full flush, so it repeats byte for byte) and written side / rows_per_block
    times; the Adler-32 of n zero bytes is ``(n mod 65521) << 16 | 1``."""
    block = bytes((side + 1) * rows_per_block)  # one filter byte + side pixels per row
    comp = zlib.compressobj(9)
    first = comp.compress(block) + comp.flush(zlib.Z_FULL_FLUSH)
    again = comp.compress(block) + comp.flush(zlib.Z_FULL_FLUSH)
    n = (side + 1) * side
    stream = first + again * (side // rows_per_block - 1) + b"\x03\x00"
    stream += struct.pack(">I", (n % 65521) << 16 | 1)
    ihdr = struct.pack(">IIBBBBB", side, side, 8, 0, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + _chunk(b"IHDR", ihdr)
        + _chunk(b"IDAT", stream)
        + _chunk(b"IEND", b"")
    )
    return path


def test_decompression_bomb_is_refused_from_its_header(tmp_path: Path) -> None:
    frames = tmp_path / "frames"
    frames.mkdir()
    cv2.imwrite(str(frames / "000000.png"), np.zeros((40, 60, 3), np.uint8))
    bomb = png_bomb(frames / "000001.png")
    assert bomb.stat().st_size < 2_000_000
    assert header_image_size(bomb) == (30_000, 30_000)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(
        InputFileError, match=r"000001\.png: not an image; .*30000×30000 px = 900 Mpx"
    ):
        read_image_file(bomb, cv2.IMREAD_COLOR, "image", "not an image")
    source = open_frames(frames)
    assert source.frame_size() == (60, 40)
    got = list(source)
    assert got[0].ok and got[1].status is FrameStatus.UNREADABLE
    assert "over the limit of 50 Mpx" in got[1].detail and "000001.png" in got[1].detail
    grown_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before
    assert grown_kb < 200_000  # decoding it would take 900 MB (grey) to 2.7 GB (BGR)
    with pytest.raises(InputFileError, match=r"000000\.png: not decoded.*0\.0024 Mpx, over the"):
        open_frames(frames, max_pixels=2000).frame_size()  # a lower configured limit
    first_is_bomb = tmp_path / "first"
    first_is_bomb.mkdir()
    bomb.rename(first_is_bomb / "000000.png")
    with pytest.raises(InputFileError, match="900 Mpx"):
        open_frames(first_is_bomb).frame_size()


def test_depth_png_bomb_is_refused(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="8000×8000 px = 64 Mpx, over the limit"):
        read_kitti_depth_png(png_bomb(tmp_path / "0000000000.png", side=8_000))


@pytest.mark.parametrize(("w", "h"), [(1, 1), (1242, 375), (17, 3001)])
@pytest.mark.parametrize("ext", [".png", ".jpg"])
def test_header_size_matches_opencv(tmp_path: Path, w: int, h: int, ext: str) -> None:
    path = tmp_path / f"x{ext}"
    assert cv2.imwrite(str(path), np.full((h, w, 3), 90, np.uint8))
    assert header_image_size(path) == (w, h)
    assert image_size_problem(path) == ""
    assert image_size_problem(path, max_pixels=w * h - 1) != "" or w * h == 1


def _with_exif_orientation(jpeg: bytes, orientation: int, order: str = "<") -> bytes:
    """``jpeg`` with an EXIF APP1 segment saying ``orientation`` (as a phone writes it)."""
    tiff = (b"II" if order == "<" else b"MM") + struct.pack(order + "HI", 42, 8)
    tiff += struct.pack(order + "H", 1) + struct.pack(order + "HHIH2x", 0x0112, 3, 1, orientation)
    tiff += struct.pack(order + "I", 0)
    payload = b"Exif\x00\x00" + tiff
    return jpeg[:2] + b"\xff\xe1" + struct.pack(">H", len(payload) + 2) + payload + jpeg[2:]


@pytest.mark.parametrize(("orientation", "order"), [(1, "<"), (3, ">"), (6, "<"), (8, ">")])
def test_jpeg_header_size_follows_the_exif_orientation_as_opencv(
    tmp_path: Path, orientation: int, order: str
) -> None:
    # a phone's portrait JPEG is stored 40×24 and shown (and decoded by OpenCV) 24×40: its
    # header size must be the decoded one, or the frames' size (calibration check, border
    # cuts of every box) disagrees with the pixels
    ok, jpeg = cv2.imencode(".jpg", np.zeros((24, 40, 3), np.uint8))
    assert ok
    path = tmp_path / "phone.jpg"
    path.write_bytes(_with_exif_orientation(jpeg.tobytes(), orientation, order))
    decoded = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert header_image_size(path) == (decoded.shape[1], decoded.shape[0])
    assert header_image_size(path) == ((24, 40) if orientation >= 5 else (40, 24))
    frames = open_frames(tmp_path)
    assert frames.frame_size() == (decoded.shape[1], decoded.shape[0])
    assert all(f.status is FrameStatus.OK for f in frames)


@settings(max_examples=100, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=64))
def test_exif_parser_never_fails_on_junk(tmp_path: Path, data: bytes) -> None:
    path = tmp_path / "junk.jpg"
    payload = b"Exif\x00\x00" + data
    path.write_bytes(b"\xff\xd8\xff\xe1" + struct.pack(">H", len(payload) + 2) + payload)
    assert header_image_size(path) is None  # no frame header after it


def test_damaged_headers(tmp_path: Path) -> None:
    path = tmp_path / "x.png"
    cv2.imwrite(str(path), np.zeros((10, 10), np.uint8))
    data = path.read_bytes()
    path.write_bytes(data[:20])
    assert header_image_size(path) is None
    assert "cut short" in image_size_problem(path)
    path.write_bytes(data[:16] + struct.pack(">II", 0, 10) + data[24:])
    assert "empty 0×10" in image_size_problem(path)
    jpg = tmp_path / "x.jpg"
    jpg.write_bytes(b"\xff\xd8\xff\xe0\x00\x10JFIF")
    assert header_image_size(jpg) is None


@settings(max_examples=100, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=64), png=st.booleans())
def test_header_parser_never_fails_on_junk(tmp_path: Path, data: bytes, png: bool) -> None:
    path = tmp_path / "junk.png"
    path.write_bytes((b"\x89PNG\r\n\x1a\n" if png else b"\xff\xd8") + data)
    size = header_image_size(path)
    assert size is None or (size[0] >= 0 and size[1] >= 0)
    assert isinstance(image_size_problem(path), str)


def test_video_frames_over_the_limit_are_refused_before_decoding(tmp_path: Path) -> None:
    path = tmp_path / "clip.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"mp4v"), 5.0, (64, 48))
    assert writer.isOpened()
    for k in range(3):
        writer.write(np.full((48, 64, 3), 20 * k, np.uint8))
    writer.release()
    assert open_frames(path).frame_size() == (64, 48)
    with pytest.raises(InputFileError, match=r"clip\.mp4: its frames are 64×48 px, over the limit"):
        open_frames(path, max_pixels=64 * 48 - 1)


# ----------------------------------------------------------------------------- read_colour
def _colour_files(tmp_path: Path) -> list[Path]:
    """PNGs of every kind (8-bit grey, RGB, RGBA, 16-bit, palette, RGB with tRNS), a JPEG and
    a PNG whose data fails its CRC: the fast path's cases and its fallbacks."""
    from PIL import Image

    rng = np.random.default_rng(3)
    bgr = rng.integers(0, 256, (37, 53, 3), dtype=np.uint8)
    files = []
    for name, image, params in (
        ("grey.png", bgr[:, :, 0], [cv2.IMWRITE_PNG_COMPRESSION, 1]),
        ("bgr.png", bgr, [cv2.IMWRITE_PNG_COMPRESSION, 9]),
        ("bgra.png", np.dstack([bgr, bgr[:, :, :1]]), []),
        ("deep.png", bgr.astype(np.uint16) * 257, []),
        ("frame.jpg", bgr, []),
    ):
        cv2.imwrite(str(tmp_path / name), image, params)
        files.append(tmp_path / name)
    rgb = Image.fromarray(bgr[:, :, ::-1])
    rgb.save(tmp_path / "trns.png", transparency=(0, 0, 0))
    rgb.quantize(16).save(tmp_path / "palette.png")
    data = bytearray((tmp_path / "bgr.png").read_bytes())
    data[data.find(b"IEND") - 5] ^= 0x10  # the IDAT chunk's CRC
    (tmp_path / "crc.png").write_bytes(bytes(data))
    return [*files, tmp_path / "trns.png", tmp_path / "palette.png", tmp_path / "crc.png"]


@pytest.mark.parametrize("fast", [True, False], ids=["imagecodecs", "opencv"])
def test_read_colour_is_opencvs_imread(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fast: bool
) -> None:
    """Every kind of file gives exactly ``cv2.imread(..., IMREAD_COLOR)`` (None for the PNG
    whose data fails its CRC), with and without imagecodecs."""
    if fast:
        pytest.importorskip("imagecodecs")
    else:
        monkeypatch.setattr(images, "_png_codec", lambda: None)
    for path in _colour_files(tmp_path):
        expected = cv2.imread(str(path), cv2.IMREAD_COLOR)
        got = read_colour(path)
        if expected is None:
            assert got is None, path.name
        else:
            assert got is not None and got.dtype == np.uint8, path.name
            np.testing.assert_array_equal(got, expected, err_msg=path.name)
    assert read_colour(tmp_path / "crc.png") is None


def test_fast_png_path_takes_only_8_bit_grey_and_rgb(tmp_path: Path) -> None:
    """The header rule: 8-bit grey and RGB, not interlaced, without tRNS; nothing else."""
    taken = {
        p.name
        for p in _colour_files(tmp_path)
        if images._fast_png_conversion(p.read_bytes()) is not None
    }
    assert taken == {"grey.png", "bgr.png", "crc.png"}
    header = bytearray((tmp_path / "bgr.png").read_bytes())
    header[28] = 1  # IHDR interlace method: Adam7
    assert images._fast_png_conversion(bytes(header)) is None


def test_kitti_frames_decode_identically(kitti_raw_lead_dir: Path) -> None:
    """The shared KITTI colour frames: the fast path's pixels are OpenCV's, bit for bit."""
    pytest.importorskip("imagecodecs")
    files = sorted((kitti_raw_lead_dir / "image_02").glob("*.png"))[:10]
    assert files
    for path in files:
        assert images._fast_png_conversion(path.read_bytes()) == cv2.COLOR_RGB2BGR
        np.testing.assert_array_equal(read_colour(path), cv2.imread(str(path)))
