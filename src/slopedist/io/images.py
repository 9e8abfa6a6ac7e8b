"""Reading one image file safely: its size from the header first, then the pixels.

A 140 KB PNG can claim 30000×30000 pixels and take gigabytes to decode, so every image slopedist
decodes (frames, depth PNGs, odometry frames) has its width and height read from the file
header (PNG ``IHDR``, JPEG ``SOFn``) and is refused above ``max_pixels``
(:data:`~slopedist.core.limits.DEFAULT_MAX_PIXELS` by default) before any pixel is decoded. Files in
other formats OpenCV reads (BMP, PGM, TIFF) are bounded by their file length instead (4 bytes
per pixel), which holds for uncompressed formats only.

Colour frames (:func:`read_colour`) are what ``cv2.imread(path, cv2.IMREAD_COLOR)`` gives; the
8-bit grey and RGB PNGs among them (KITTI's frames) are decoded faster by the optional
``imagecodecs`` (``pip install 'slopedist[png]'``) when it is installed.
"""

from __future__ import annotations

import functools
import struct
from pathlib import Path
from types import ModuleType
from typing import BinaryIO

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import InputFileError, MissingInputError
from slopedist.core.limits import DEFAULT_MAX_PIXELS
from slopedist.core.paths import utf8_name

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
JPEG_SOI = b"\xff\xd8"
_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
"""JPEG start-of-frame markers (DHT C4, JPG C8 and DAC CC share the range but are not frames)."""
_JPEG_STANDALONE = frozenset({0x01, *range(0xD0, 0xD8)})
_MAX_JPEG_SEGMENTS = 10_000
_EXIF_ORIENTATION_TAG = 0x0112
"""EXIF orientation: 5..8 turn the image by a quarter, which ``cv2.imread`` applies."""


def _png_size(fh: BinaryIO) -> tuple[int, int] | None:
    head = fh.read(16)  # IHDR chunk: length (4), type (4), width (4), height (4)
    if len(head) < 16 or head[4:8] != b"IHDR":
        return None
    width, height = struct.unpack(">II", head[8:16])
    return int(width), int(height)


def _exif_orientation(segment: bytes) -> int:
    """The EXIF orientation (1..8; 1 = upright) of a JPEG APP1 segment's payload, 1 when it is
    not EXIF or is malformed."""
    if segment[:6] != b"Exif\x00\x00":
        return 1
    tiff = segment[6:]
    order = {b"II": "<", b"MM": ">"}.get(tiff[:2])
    if order is None or len(tiff) < 8:
        return 1
    ifd = struct.unpack(order + "I", tiff[4:8])[0]
    if ifd + 2 > len(tiff):
        return 1
    for i in range(struct.unpack(order + "H", tiff[ifd : ifd + 2])[0]):
        entry = tiff[ifd + 2 + 12 * i : ifd + 14 + 12 * i]
        if len(entry) < 12:
            return 1
        if struct.unpack(order + "H", entry[:2])[0] == _EXIF_ORIENTATION_TAG:
            value = int(struct.unpack(order + "H", entry[8:10])[0])
            return value if 1 <= value <= 8 else 1
    return 1


def _jpeg_size(fh: BinaryIO) -> tuple[int, int] | None:
    orientation = 1
    for _ in range(_MAX_JPEG_SEGMENTS):
        byte = fh.read(1)
        if byte != b"\xff":
            return None
        marker = fh.read(1)
        while marker == b"\xff":  # fill bytes
            marker = fh.read(1)
        if not marker:
            return None
        m = marker[0]
        if m in _JPEG_STANDALONE:
            continue
        raw = fh.read(2)
        if len(raw) < 2 or m == 0xDA:  # start of scan before any frame header
            return None
        length = struct.unpack(">H", raw)[0]
        if m in _JPEG_SOF:
            sof = fh.read(5)  # precision (1), height (2), width (2)
            if len(sof) < 5:
                return None
            height, width = struct.unpack(">HH", sof[1:5])
            if orientation >= 5:  # turned by a quarter: OpenCV decodes it height × width
                return int(height), int(width)
            return int(width), int(height)
        if m == 0xE1 and orientation == 1:
            orientation = _exif_orientation(fh.read(max(0, length - 2)))
            continue
        fh.seek(length - 2, 1)
    return None


def header_image_size(path: str | Path) -> tuple[int, int] | None:
    """``(width, height)`` in pixels from a PNG or JPEG header, without decoding, as
    ``cv2.imread`` gives the image (a JPEG's EXIF orientation turning it by a quarter swaps the
    two); None when the file is neither or its header is cut short."""
    with Path(path).open("rb") as fh:
        magic = fh.read(8)
        if magic == PNG_SIGNATURE:
            return _png_size(fh)
        if magic[:2] == JPEG_SOI:
            fh.seek(2)
            return _jpeg_size(fh)
    return None


def image_size_problem(path: str | Path, max_pixels: int = DEFAULT_MAX_PIXELS) -> str:
    """Why ``path`` must not be decoded (``""`` if it may): a PNG/JPEG header that is cut
    short, a zero size, more than ``max_pixels`` pixels, or (other formats) a file larger than
    ``max_pixels`` × 4 bytes."""
    path = Path(path)
    with path.open("rb") as fh:
        magic = fh.read(8)
    if magic == PNG_SIGNATURE or magic[:2] == JPEG_SOI:
        size = header_image_size(path)
        if size is None:
            return "its PNG/JPEG header is damaged or cut short"
        width, height = size
        if width == 0 or height == 0:
            return f"its header claims an empty {width}×{height} px image"
        if width * height > max_pixels:
            return (
                f"its header claims {width}×{height} px = {width * height / 1e6:.3g} Mpx, over "
                f"the limit of {max_pixels / 1e6:.3g} Mpx (a corrupt or hostile file?)"
            )
        return ""
    if path.stat().st_size > 4 * max_pixels:
        return f"a {path.stat().st_size} byte image file is over the limit of {max_pixels} px"
    return ""


def read_image_file(
    path: str | Path,
    flags: int,
    what: str,
    not_decoded: str,
    max_pixels: int = DEFAULT_MAX_PIXELS,
) -> NDArray:
    """Decode ``path`` with ``cv2.imread(path, flags)`` after checking its header size.

    Raises:
        MissingInputError: the file does not exist (``"{what} not found: {path}"``).
        InputFileError: it cannot be decoded (message ``not_decoded``), or must not be (then
            followed by the reason from :func:`image_size_problem`).
    """
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"{what} not found: {path}")
    problem = image_size_problem(path, max_pixels)
    if problem:
        raise InputFileError(path, f"{not_decoded}; {problem}")
    with utf8_name(path) as name:
        image = cv2.imread(name, flags)
    if image is None:
        raise InputFileError(path, not_decoded)
    return np.asarray(image)


FAST_PNG_CONVERSIONS = {0: cv2.COLOR_GRAY2BGR, 2: cv2.COLOR_RGB2BGR}
"""PNG colour types (``IHDR``) that :func:`read_colour` decodes with ``imagecodecs`` when it is
installed, at 8 bits and not interlaced: grey (0) and RGB (2), with the conversion to BGR."""


@functools.cache
def _png_codec() -> ModuleType | None:
    """The optional ``imagecodecs`` module if installed with its PNG codec, else None."""
    try:
        import imagecodecs
    except ImportError:
        return None
    return imagecodecs if hasattr(imagecodecs, "png_decode") else None


def _fast_png_conversion(data: bytes) -> int | None:
    """The BGR conversion of a PNG that :func:`read_colour` decodes itself (8-bit grey or RGB,
    not interlaced, no ``tRNS`` chunk), None for any other file."""
    if len(data) < 33 or data[:8] != PNG_SIGNATURE or data[12:16] != b"IHDR":
        return None
    bit_depth, colour_type, interlace = data[24], data[25], data[28]
    if bit_depth != 8 or interlace != 0 or b"tRNS" in data[33 : data.find(b"IDAT")]:
        return None
    return FAST_PNG_CONVERSIONS.get(colour_type)


def read_colour(path: str | Path) -> NDArray[np.uint8] | None:
    """The pixels of an image file as BGR ``H×W×3`` uint8: exactly ``cv2.imread(path,
    cv2.IMREAD_COLOR)``, None when the file cannot be decoded (check its size first:
    :func:`image_size_problem`).

    With the optional ``imagecodecs`` installed, 8-bit grey and RGB PNGs are decoded by its
    libpng with zlib-ng, which inflates faster than OpenCV's build: 6.5 against 8.9 ms per
    1242×375 KITTI frame, bit for bit the same pixels, and the same CRC and Adler-32 checks of
    the data (``pyspng`` is faster still but skips them, so a corrupt frame would pass as
    readable). Any other file, and any file it cannot decode, goes to OpenCV.
    """
    codec = _png_codec()
    if codec is not None:
        data = Path(path).read_bytes()
        conversion = _fast_png_conversion(data)
        if conversion is not None:
            try:
                pixels = np.asarray(codec.png_decode(data))
            except Exception:  # imagecodecs' errors are its own types: OpenCV decides
                pixels = None
            shape = () if conversion == cv2.COLOR_GRAY2BGR else (3,)  # after (H, W)
            if pixels is not None and pixels.dtype == np.uint8 and pixels.shape[2:] == shape:
                return np.asarray(cv2.cvtColor(pixels, conversion), dtype=np.uint8)
    with utf8_name(path) as name:
        image = cv2.imread(name, cv2.IMREAD_COLOR)
    return None if image is None else np.asarray(image, dtype=np.uint8)
