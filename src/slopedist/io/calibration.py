"""Camera calibrations in the forms people have.

:func:`read_calibration` reads, chosen by content:

- a KITTI calib file (``P2:``/``P0:`` lines of 12 numbers, as :func:`slopedist.core.camera.
  read_kitti_calib`): ``fx = P[0,0]``, ``fy = P[1,1]``, ``cx = P[0,2]``, ``cy = P[1,2]``;
- a 3×3 K as text (three lines of three numbers, or nine on one line), optionally followed by a
  line of distortion coefficients;
- an OpenCV FileStorage YAML/JSON (what ``cv::FileStorage`` and OpenCV's calibration samples
  write): ``camera_matrix`` and ``distortion_coefficients`` (or ``dist_coeffs``), optional
  ``image_width``/``image_height``;
- a ROS ``camera_info`` YAML (``camera_calibration``'s ``ost.yaml``: ``camera_matrix: {data:
  […]}``, ``distortion_model``, ``distortion_coefficients``) or a ``camera_info`` message dump
  (``K``/``D``, ``k``/``d``, ``width``/``height``).

The result is :class:`CameraCalibration`: the :class:`~slopedist.io.intrinsics.Intrinsics` (with
lens distortion) and the ideal square-pixel :class:`~slopedist.core.camera.Camera` the estimators
use,
into which boxes are mapped (see :mod:`slopedist.io.intrinsics`).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import KITTI_CAMERA_HEIGHT_M, Camera, read_kitti_calib
from slopedist.core.errors import ConfigurationError, InputFileError
from slopedist.core.paths import utf8_name
from slopedist.core.textfiles import read_text
from slopedist.io.frames import check_calibration, check_implied_image
from slopedist.io.intrinsics import DISTORTION_COUNTS, Intrinsics

MATRIX_KEYS = ("camera_matrix", "K", "k", "cameraMatrix", "intrinsic_matrix")
DIST_KEYS = ("distortion_coefficients", "dist_coeffs", "D", "d", "distCoeffs", "distortion")
WIDTH_KEYS = ("image_width", "width")
HEIGHT_KEYS = ("image_height", "height")
FISHEYE_MODELS = ("equidistant", "fisheye", "kannala_brandt")

T = TypeVar("T")


@dataclass(frozen=True)
class CameraCalibration:
    """What a calibration file gives: the :class:`Intrinsics` and the ideal :class:`Camera` the
    estimators use (boxes must go through :meth:`Intrinsics.rectify_table` first unless
    ``intrinsics.is_ideal``)."""

    intrinsics: Intrinsics
    camera: Camera

    @property
    def point_map(self) -> Callable[[NDArray[np.float64]], NDArray[np.float64]] | None:
        """Pixels of the real camera → pixels of :attr:`camera` (``(N, 2)``; what the built-in
        odometry's ``point_map`` takes), or None when the camera is ideal already."""
        return None if self.intrinsics.is_ideal else self.intrinsics.rectify_points


def read_calibration(
    path: str | Path | Intrinsics,
    height_m: float = KITTI_CAMERA_HEIGHT_M,
    mount_angle_rad: float = 0.0,
    kitti_key: str = "P2",
    image_size: tuple[int, int] | None = None,
) -> CameraCalibration:
    """Read a calibration file of any supported form (see the module docstring), or take
    ``Intrinsics`` given as values (``--fx --fy --cx --cy``); the mount is given in metres and
    radians. ``image_size`` (width, height; pixels; ``--image-size``) completes a calibration
    that states none (KITTI, K text, the values); it must agree with one that does.

    Example:
        >>> import pathlib, tempfile
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "K.txt"
        >>> _ = path.write_text("721.5 0 609.6\\n0 721.5 172.9\\n0 0 1\\n")
        >>> camera = read_calibration(path, height_m=1.5).camera
        >>> camera.f, camera.c_y, camera.height_m
        (721.5, 172.9, 1.5)

    Raises:
        ConfigurationError: ``image_size`` differs from the calibration's own, or the mount
            (height, angle) is out of range.
        InputFileError: the file's camera is implausible (focal length, principal point, a
            lens model that moves the image's edges by more than
            :data:`~slopedist.io.intrinsics.MAX_LENS_SCALE`).
        DataMismatchError: the camera cannot belong to images of ``image_size`` (principal
            point far from their centre, field of view; the frames' rule,
            :func:`~slopedist.io.frames.check_calibration`).
        InputFileError / ConfigurationError: without an image size (given or stated), no
            image fits the camera (:func:`~slopedist.io.frames.check_implied_image`: a
            principal point at or beyond the image origin, such as ``c_y = 0``).
    """
    intrinsics = path if isinstance(path, Intrinsics) else read_intrinsics(path, kitti_key)
    where = "the calibration" if isinstance(path, Intrinsics) else str(path)
    if image_size is not None:
        where += f" with --image-size {image_size[0]}x{image_size[1]}"
        if intrinsics.image_size is None:  # the frames' rule first: it names the likely cause
            check_calibration(_file_camera(path, intrinsics), *image_size, where)
    intrinsics = intrinsics.with_image_size(image_size)
    _file_camera(path, intrinsics)  # focal length, principal point (against a stated size)
    if not isinstance(path, Intrinsics):  # the file's own part of the camera, named as such
        _checked(Path(path), intrinsics.check_lens_scale, "distortion")
    else:
        intrinsics.check_lens_scale()
    camera = intrinsics.camera(height_m, mount_angle_rad)
    if image_size is not None:
        check_calibration(camera, *image_size, where)
    elif intrinsics.image_size is None:  # no size to check against: some image must fit
        if isinstance(path, Intrinsics):
            check_implied_image(camera)
        else:
            _checked(Path(path), lambda: check_implied_image(camera), None)
    return CameraCalibration(intrinsics, camera)


def _file_camera(path: str | Path | Intrinsics, intrinsics: Intrinsics) -> Camera:
    """The camera of ``intrinsics`` (focal length and principal point checked), its errors
    naming the file ``path`` when it came from one."""
    if isinstance(path, Intrinsics):
        return intrinsics.camera()
    return _checked(Path(path), intrinsics.camera, None)


def read_intrinsics(path: str | Path, kitti_key: str = "P2") -> Intrinsics:
    """:class:`Intrinsics` from a KITTI, K-text, OpenCV or ROS calibration file."""
    path = Path(path)
    text = read_text(path, "calibration file")
    if path.suffix.lower() in (".yaml", ".yml", ".json", ".xml"):
        return read_filestorage(path)
    if _KITTI_LINE.search(text) or _first_line_count(text) == 12:
        return _from_kitti(path, kitti_key)
    if text.lstrip()[:1] in ("%", "{", "<") or re.search(r"^\s*\w+\s*:", text, re.MULTILINE):
        return read_filestorage(path)
    return read_k_text(path, text)


_KITTI_LINE = re.compile(
    r"^\s*(P\d|R0?_rect|Tr_velo_(to_)?cam|Tr_imu_(to_)?velo)\s*:", re.MULTILINE
)
"""A line of a KITTI calib file (a file with ``R0_rect:`` but no ``P2:`` is one that lacks its
``P2:`` line, not a YAML file)."""


def _first_line_count(text: str) -> int:
    for line in text.splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            return len(line.split())
    return 0


def _checked(path: Path, build: Callable[[], T], field: str | None) -> T:
    """``build()``, with a configuration error turned into one naming the file and field."""
    try:
        return build()
    except ConfigurationError as exc:
        raise InputFileError(path, str(exc), field=field) from None


def _from_kitti(path: Path, key: str) -> Intrinsics:
    calib = read_kitti_calib(path)
    if key not in calib:
        if key == "P2" and "P0" in calib:
            key = "P0"
        else:
            raise InputFileError(path, f"no '{key}:' line (found: {', '.join(calib)})")
    P = calib[key].reshape(3, 4)
    return _checked(path, lambda: Intrinsics(P[:, :3] / P[2, 2]), key)


def read_k_text(path: Path, text: str) -> Intrinsics:
    """Nine numbers of K (row by row), then optionally the distortion coefficients."""
    values: list[float] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].replace(",", " ").replace("[", " ").replace("]", " ")
        for i, tok in enumerate(line.split()):
            try:
                values.append(float(tok))
            except ValueError:
                name = "K" if len(values) < 9 else "distortion"
                raise InputFileError(
                    path, f"'{tok}' is not a number", line=lineno, field=f"{name}[{i}]"
                ) from None
    if len(values) < 9:
        raise InputFileError(path, f"expected 9 numbers of a 3×3 K, found {len(values)}", field="K")
    K = np.asarray(values[:9]).reshape(3, 3)
    _checked(path, lambda: Intrinsics(K), "K")
    return _checked(path, lambda: Intrinsics(K, np.asarray(values[9:])), "distortion")


def _node_values(node: cv2.FileNode) -> np.ndarray | None:
    """Numbers of a FileStorage node: a matrix, a ``{data: […]}`` map or a plain list."""
    if node.empty() or node.isNone():
        return None
    if node.isMap():
        data = node.getNode("data")
        if not data.empty():
            return _node_values(data)
        mat = node.mat()
        return None if mat is None else np.asarray(mat, dtype=float).reshape(-1)
    if node.isSeq():
        return np.array([node.at(i).real() for i in range(node.size())], dtype=float)
    if node.isReal() or node.isInt():
        return np.array([node.real()])
    return None


def _first(fs: cv2.FileStorage, keys: tuple[str, ...]) -> tuple[str, np.ndarray | None]:
    for key in keys:
        values = _node_values(fs.getNode(key))
        if values is not None:
            return key, values
    return keys[0], None


def _open_filestorage(path: Path) -> cv2.FileStorage:
    try:
        with utf8_name(path) as name:
            fs = cv2.FileStorage(name, cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:
        cause = exc.__cause__ or exc
        match = re.search(r"\((\d+)\): ([^'\n]+)", str(cause))
        line, msg = (int(match.group(1)), match.group(2)) if match else (None, "cannot parse it")
        raise InputFileError(path, f"not a readable YAML/JSON/XML file: {msg}", line=line) from None
    if not fs.isOpened():
        raise InputFileError(path, "OpenCV cannot open it as YAML/JSON/XML")
    return fs


def _image_size(fs: cv2.FileStorage) -> tuple[int, int] | None:
    _, w = _first(fs, WIDTH_KEYS)
    _, h = _first(fs, HEIGHT_KEYS)
    if w is None or h is None or w.size != 1 or h.size != 1:
        return None
    if not (0 < w[0] <= 1_000_000 and 0 < h[0] <= 1_000_000):  # NaN, inf and 1e308 too
        return None
    return int(w[0]), int(h[0])


def read_filestorage(path: str | Path) -> Intrinsics:
    """An OpenCV FileStorage or ROS ``camera_info`` YAML/JSON/XML (see the module docstring)."""
    path = Path(path)
    fs = _open_filestorage(path)
    try:
        key, k = _first(fs, MATRIX_KEYS)
        if k is None:
            raise InputFileError(path, f"no camera matrix (one of {', '.join(MATRIX_KEYS)})")
        if k.size != 9:
            raise InputFileError(path, f"expected 9 numbers, found {k.size}", field=key)
        dist_key, dist = _first(fs, DIST_KEYS)
        model = fs.getNode("distortion_model")
        fisheye = model.isString() and model.string().strip().lower() in FISHEYE_MODELS
        size = _image_size(fs)
    finally:
        fs.release()
    dist_values = np.zeros(0) if dist is None else dist
    _checked(path, lambda: Intrinsics(k.reshape(3, 3)), key)
    return _checked(
        path,
        lambda: Intrinsics(k.reshape(3, 3), _trim(dist_values, fisheye), fisheye, size),
        dist_key,
    )


def _trim(dist: np.ndarray, fisheye: bool) -> np.ndarray:
    """ROS writes fisheye ``D`` with 4 values and some tools pad with zeros: drop trailing zeros
    beyond the nearest length OpenCV accepts."""
    counts = (0, 4) if fisheye else DISTORTION_COUNTS
    if dist.size in counts:
        return dist
    for n in counts:
        if n > 0 and dist.size > n and not np.any(dist[n:] != 0):
            return dist[:n]
    return dist
