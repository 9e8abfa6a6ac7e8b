"""Depth maps stored as files, one per frame: KITTI depth PNG and ``.npy``.

Formats:

- KITTI depth PNG: single-channel 16-bit PNG, ``value / 256`` = metres, ``0`` = no value
  (the layout of the KITTI depth benchmark and of projected LiDAR maps); ``65535`` (255.996 m),
  the largest value, is no value too: writers clip every depth beyond the format's range to
  it (:func:`write_kitti_depth_png` does), so it says only "this far or further".
- ``.npy``: a 2-D float array of metres; NaN, ±inf and values ≤ 0 mean no value.

A folder of depth files is indexed by file name: every ``*.png`` / ``*.npy`` whose stem is an
integer (``0000000005.png``, ``000123.npy``) is the map of that frame index.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import (
    ConfigurationError,
    DataMismatchError,
    InputFileError,
    MissingInputError,
)
from slopedist.core.limits import DEFAULT_MAX_PIXELS
from slopedist.core.paths import utf8_name
from slopedist.io.depth.base import DepthSource
from slopedist.io.images import read_image_file

DEPTH_FILE_SUFFIXES = (".png", ".npy")
"""File name endings of depth maps."""

KITTI_DEPTH_SCALE = 256.0
"""KITTI depth PNG: stored value = metres × 256."""

KITTI_DEPTH_BEYOND = np.iinfo(np.uint16).max
"""KITTI depth PNG: the stored value of a depth at or beyond the format's range (255.996 m),
to which writers clip: no measurement."""


def read_kitti_depth_png(path: str | Path) -> NDArray[np.float32]:
    """Read a KITTI depth PNG (uint16, value/256 = metres, 0 and 65535 = no value) → float32
    metres, NaN where there is no value.

    Raises:
        MissingInputError: the file does not exist.
        InputFileError: it does not decode, or is not a single-channel 16-bit PNG.
    """
    path = Path(path)
    raw = read_image_file(
        path,
        cv2.IMREAD_UNCHANGED,
        "depth file",
        "does not decode as a PNG image (corrupt or not a PNG)",
    )
    if raw.dtype != np.uint16 or raw.ndim != 2:
        channels = 1 if raw.ndim == 2 else raw.shape[2]
        raise InputFileError(
            path,
            f"expected a single-channel 16-bit PNG (KITTI depth: uint16 / 256 = metres), got "
            f"{channels} channel(s) of {raw.dtype}",
        )
    depth = raw.astype(np.float32) / np.float32(KITTI_DEPTH_SCALE)
    depth[(raw == 0) | (raw == KITTI_DEPTH_BEYOND)] = np.nan
    return depth


def write_kitti_depth_png(path: str | Path, depth_m: NDArray[np.floating]) -> None:
    """Write a depth map (metres; NaN or ≤ 0 = no value) as a KITTI depth PNG.

    Values are rounded to 1/256 m; depths beyond the format's range (255.996 m) are written as
    its largest value, which :func:`read_kitti_depth_png` reads as no value.
    """
    path = Path(path)
    d = np.asarray(depth_m, dtype=np.float64)
    if d.ndim != 2:
        raise DataMismatchError(f"a depth map must be 2-D (H×W), got shape {d.shape}")
    valid = np.isfinite(d) & (d > 0)
    stored = np.zeros(d.shape, dtype=np.uint16)
    stored[valid] = np.clip(np.round(d[valid] * KITTI_DEPTH_SCALE), 1, np.iinfo(np.uint16).max)
    path.parent.mkdir(parents=True, exist_ok=True)
    with utf8_name(path) as name:
        if not cv2.imwrite(name, stored):
            raise InputFileError(path, "could not be written as PNG")


def _check_npy_header(path: Path, max_pixels: int) -> None:
    """Refuse a ``.npy`` file from its header alone: not 2-D, not real numbers, or more than
    ``max_pixels`` values (a header can claim any shape; np.load would try to allocate it)."""
    try:
        with path.open("rb") as fh:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
            elif version == (2, 0):
                shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
            else:
                raise ValueError(f".npy format version {version} is not read")
    except (ValueError, OSError, EOFError, SyntaxError) as exc:
        raise InputFileError(path, f"not a readable .npy array ({exc})") from None
    if len(shape) != 2:
        raise InputFileError(path, f"expected a 2-D depth array (H×W metres), got shape {shape}")
    if dtype.kind not in "fiu":
        raise InputFileError(path, f"expected float metres, got dtype {dtype}")
    if shape[0] * shape[1] > max_pixels:
        raise InputFileError(
            path,
            f"its header claims a {shape[1]}×{shape[0]} depth map, over the limit of "
            f"{max_pixels / 1e6:.3g} Mpx (a corrupt or hostile file?)",
        )


def read_npy_depth(path: str | Path, max_pixels: int = DEFAULT_MAX_PIXELS) -> NDArray[np.float32]:
    """Read a ``.npy`` depth map (2-D float metres) → float32, NaN where ≤ 0 or non-finite.

    The header is checked before loading (2-D, real numbers, at most ``max_pixels`` values).

    Raises:
        MissingInputError: the file does not exist.
        InputFileError: it is not a readable ``.npy`` file of a 2-D real-valued array, or it is
            too large.
    """
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"depth file not found: {path}")
    _check_npy_header(path, max_pixels)
    try:
        raw = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise InputFileError(path, f"not a readable .npy array ({exc})") from None
    if not isinstance(raw, np.ndarray) or raw.ndim != 2:
        shape = getattr(raw, "shape", None)
        raise InputFileError(path, f"expected a 2-D depth array (H×W metres), got shape {shape}")
    if not (np.issubdtype(raw.dtype, np.floating) or np.issubdtype(raw.dtype, np.integer)):
        raise InputFileError(path, f"expected float metres, got dtype {raw.dtype}")
    depth = raw.astype(np.float32)
    with np.errstate(invalid="ignore"):
        depth[~(np.isfinite(depth) & (depth > 0))] = np.nan
    return depth


def read_depth_file(path: str | Path) -> NDArray[np.float32]:
    """Read a depth file by its ending: ``.png`` (KITTI depth) or ``.npy``."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".png":
        return read_kitti_depth_png(path)
    if suffix == ".npy":
        return read_npy_depth(path)
    raise ConfigurationError(
        f"{path}: unknown depth file type '{suffix}' (expected {', '.join(DEPTH_FILE_SUFFIXES)})"
    )


def index_depth_folder(folder: str | Path) -> dict[int, Path]:
    """``{frame index: file}`` of the depth files in ``folder`` (see the module docstring).

    Raises:
        MissingInputError: the folder does not exist or holds no depth files.
        ConfigurationError: two files claim the same frame (e.g. ``5.png`` and ``000005.npy``).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise MissingInputError(f"depth folder not found: {folder}")
    index: dict[int, Path] = {}
    for path in sorted(folder.iterdir()):
        if path.suffix.lower() not in DEPTH_FILE_SUFFIXES or not path.stem.isdigit():
            continue
        k = int(path.stem)
        if k in index:
            raise ConfigurationError(
                f"{folder}: frame {k} has two depth files, {index[k].name} and {path.name}"
            )
        index[k] = path
    if not index:
        raise MissingInputError(
            f"no depth files in {folder}: expected files named by frame number, e.g. "
            f"0000000000.png (KITTI depth PNG) or 000000.npy (float metres)"
        )
    return index


class FileDepthSource(DepthSource):
    """Depth maps read from a folder of per-frame files (see the module docstring).

    Args:
        folder: the folder.
        missing_ok: when True, a frame without a file yields ``None`` (its targets are then
            reported as missing with reason ``no_depth``); when False (default) it is an error.
        expected_shape: ``(H, W)`` every map must have (the camera image size), if known.
    """

    kind = "file read"

    def __init__(
        self,
        folder: str | Path,
        missing_ok: bool = False,
        expected_shape: tuple[int, int] | None = None,
    ) -> None:
        super().__init__()
        self.folder = Path(folder)
        self.files = index_depth_folder(self.folder)
        self.missing_ok = missing_ok
        self.expected_shape = expected_shape

    def __len__(self) -> int:
        return len(self.files)

    def _depth(
        self, frame_index: int, image: NDArray[np.uint8] | None
    ) -> NDArray[np.float32] | None:
        path = self.files.get(frame_index)
        if path is None:
            if self.missing_ok:
                return None
            raise MissingInputError(
                f"no depth file for frame {frame_index} in {self.folder} (it has "
                f"{len(self.files)} files for frames {min(self.files)}..{max(self.files)})"
            )
        depth = read_depth_file(path)
        shape = self.expected_shape or (image.shape[:2] if image is not None else None)
        if shape is not None and depth.shape != tuple(shape):
            raise DataMismatchError(
                f"{path}: depth map is {depth.shape[1]}×{depth.shape[0]} pixels but the image is "
                f"{shape[1]}×{shape[0]}"
            )
        return depth
