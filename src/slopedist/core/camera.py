"""Camera intrinsics and mount.

Convention: camera frame x right, y down, z forward; image rows grow downwards, origin top-left.
Focal length and principal point in pixels, height in metres, mount angle θ0 in radians as it
enters the paper's eq. 2 (``n0 = [0, −cos θ0, −sin θ0]``): with the camera at rest eq. 4 gives
θ = −θ0 and eq. 5 puts the horizon at row ``c_y + f·tan θ0``, so a positive θ0 is an optical
axis pitched up (horizon below the principal point).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from slopedist.core.errors import ConfigurationError, InputFileError
from slopedist.core.textfiles import numbered_lines

KITTI_CAMERA_HEIGHT_M = 1.65
"""Height of KITTI's cam 2 above the road, metres."""

FOCAL_RANGE_PX = (50.0, 20_000.0)
"""Accepted focal lengths, pixels: from a fisheye on a tiny image to a telephoto on a large one;
values outside (1e-9, 1e308, a focal length in millimetres) are a broken calibration."""

MAX_PRINCIPAL_POINT_PX = 100_000.0
"""Largest accepted |c_x|, |c_y|, pixels, when the image size is not known."""

MAX_CAMERA_HEIGHT_M = 50.0
"""Largest accepted camera height above the road, metres."""

MAX_MOUNT_ANGLE_RAD = math.radians(60.0)
"""Largest accepted |mount angle θ0|, radians (a road camera looks roughly forward)."""


def focal_in_range(f_px: float) -> bool:
    """Whether a focal length (pixels) lies in :data:`FOCAL_RANGE_PX`."""
    return FOCAL_RANGE_PX[0] <= f_px <= FOCAL_RANGE_PX[1]


def height_in_range(height_m: float) -> bool:
    """Whether a camera height above the road (metres) is > 0 and ≤ :data:`MAX_CAMERA_HEIGHT_M`."""
    return 0 < height_m <= MAX_CAMERA_HEIGHT_M


@dataclass(frozen=True)
class Camera:
    """Pinhole intrinsics plus how the camera is mounted on the ego vehicle.

    Attributes:
        f: focal length in pixels (the paper's f/δ_y; square pixels assumed).
        c_x: principal-point column, pixels.
        c_y: principal-point row, pixels.
        height_m: camera height above the road, metres (the paper's h).
        mount_angle_rad: mount angle θ0 in the camera's yz plane, radians.
        image_width: image width in pixels, if known (used to validate frames).
        image_height: image height in pixels, if known.
    """

    f: float
    c_x: float
    c_y: float
    height_m: float = KITTI_CAMERA_HEIGHT_M
    mount_angle_rad: float = 0.0
    image_width: int | None = None
    image_height: int | None = None

    def __post_init__(self) -> None:
        for name in ("f", "c_x", "c_y", "height_m", "mount_angle_rad"):
            value = getattr(self, name)
            if isinstance(value, (bool, np.bool_)) or not isinstance(
                value, (int, float, np.integer, np.floating)
            ):
                raise ConfigurationError(f"camera {name} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ConfigurationError(f"camera {name} must be finite, got {value}")
        if not focal_in_range(self.f):
            lo, hi = FOCAL_RANGE_PX
            raise ConfigurationError(
                f"camera focal length f = {self.f:g} px is outside the plausible {lo:g}..{hi:g} px"
            )
        if not height_in_range(self.height_m):
            raise ConfigurationError(
                f"camera height must be > 0 and ≤ {MAX_CAMERA_HEIGHT_M:g} m, got {self.height_m:g}"
            )
        if abs(self.mount_angle_rad) > MAX_MOUNT_ANGLE_RAD:
            raise ConfigurationError(
                f"camera mount angle {math.degrees(self.mount_angle_rad):g}° is beyond "
                f"±{math.degrees(MAX_MOUNT_ANGLE_RAD):g}°"
            )
        self._check_principal_point()

    def _check_principal_point(self) -> None:
        """c_x, c_y inside the image when its size is known, else within ±100000 px."""
        for name, c, size in (
            ("c_x", self.c_x, self.image_width),
            ("c_y", self.c_y, self.image_height),
        ):
            if size is not None and not (
                isinstance(size, (int, np.integer))
                and not isinstance(size, bool)
                and 0 < size <= 1_000_000
            ):
                raise ConfigurationError(f"camera image size must be 1..1000000 px, got {size}")
            high = MAX_PRINCIPAL_POINT_PX if size is None else float(size)
            low = -MAX_PRINCIPAL_POINT_PX if size is None else 0.0
            if not low <= c <= high:
                raise ConfigurationError(
                    f"camera principal point {name} = {c:g} px is outside {low:g}..{high:g} px"
                )

    @property
    def K(self) -> np.ndarray:
        """3×3 intrinsic matrix (pixels)."""
        return np.array([[self.f, 0.0, self.c_x], [0.0, self.f, self.c_y], [0.0, 0.0, 1.0]])

    def with_mount(
        self, *, height_m: float | None = None, mount_angle_rad: float | None = None
    ) -> Camera:
        """Copy with a different mount (height in metres, mount angle in radians)."""
        return replace(
            self,
            height_m=self.height_m if height_m is None else height_m,
            mount_angle_rad=self.mount_angle_rad if mount_angle_rad is None else mount_angle_rad,
        )

    def with_image_size(self, width: int, height: int) -> Camera:
        """Copy that knows the image size in pixels."""
        return replace(self, image_width=int(width), image_height=int(height))

    @classmethod
    def from_values(
        cls,
        f: float,
        c_x: float,
        c_y: float,
        height_m: float = KITTI_CAMERA_HEIGHT_M,
        mount_angle_deg: float = 0.0,
    ) -> Camera:
        """Camera from explicit values; the mount angle is given in degrees (an edge of the API)."""
        return cls(f, c_x, c_y, height_m, math.radians(mount_angle_deg))

    @classmethod
    def from_projection(
        cls, P: np.ndarray, height_m: float = KITTI_CAMERA_HEIGHT_M, mount_angle_rad: float = 0.0
    ) -> Camera:
        """Camera from a 3×4 projection matrix: f = P[0,0], c_x = P[0,2], c_y = P[1,2]."""
        return cls(float(P[0, 0]), float(P[0, 2]), float(P[1, 2]), height_m, mount_angle_rad)

    @classmethod
    def from_kitti_calib(
        cls,
        path: str | Path,
        key: str = "P2",
        height_m: float = KITTI_CAMERA_HEIGHT_M,
        mount_angle_rad: float = 0.0,
    ) -> Camera:
        """Camera from a KITTI calib file (tracking ``P2:`` layout or odometry ``P0:`` layout).

        A file without ``key`` but whose first line is 12 bare numbers (KITTI odometry ``calib.txt``
        written without names) is also accepted.
        """
        calib, lines = _read_calib_lines(Path(path))
        if key not in calib:
            if key == "P2" and "P0" in calib:  # KITTI odometry layout: only cam 0/1 given
                key = "P0"
            else:
                raise InputFileError(path, f"no '{key}:' line (found: {', '.join(calib)})")
        try:
            return cls.from_projection(calib[key].reshape(3, 4), height_m, mount_angle_rad)
        except ConfigurationError as exc:
            raise InputFileError(path, str(exc), line=lines[key], field=key) from None


def read_kitti_calib(path: str | Path) -> dict[str, np.ndarray]:
    """Read a KITTI calib file into ``{name: flat float64 array}``.

    Lines look like ``P2: 12 numbers`` (tracking uses ``R_rect``/``Tr_velo_cam`` or
    ``R0_rect:``/``Tr_velo_to_cam:`` names). A line of bare numbers is named ``P<i>`` by its index.
    Matrices ``P*``/``Tr*`` must have 12 numbers, ``R0_rect``/``R_rect`` 9.
    """
    return _read_calib_lines(Path(path))[0]


def _read_calib_lines(path: Path) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    """``({name: values}, {name: line})`` of a KITTI calib file (see :func:`read_kitti_calib`)."""
    out: dict[str, np.ndarray] = {}
    first_line: dict[str, int] = {}
    for lineno, line in numbered_lines(path, "calibration file", comment=None):
        if ":" in line:
            name, _, rest = line.partition(":")
            name = name.strip()
            tokens = rest.split()
        else:
            name = f"P{len(out)}"
            tokens = line.split()
        if name in out:
            raise InputFileError(
                path,
                f"second '{name}:' line (the first is line {first_line[name]})",
                line=lineno,
                field=name,
            )
        out[name] = _calib_values(path, lineno, name, tokens)
        first_line[name] = lineno
    if not out:
        raise InputFileError(path, "file is empty")
    return out, first_line


def _calib_values(path: Path, lineno: int, name: str, tokens: list[str]) -> np.ndarray:
    """The numbers of one calib line: 9 for ``R*`` names, else 12, all finite."""
    values = []
    for i, tok in enumerate(tokens):
        try:
            values.append(float(tok))
        except ValueError:
            raise InputFileError(
                path, f"'{tok}' is not a number", line=lineno, field=f"{name}[{i}]"
            ) from None
    expected = 9 if name.startswith("R") else 12
    if len(values) != expected:
        raise InputFileError(
            path, f"expected {expected} numbers, found {len(values)}", line=lineno, field=name
        )
    arr = np.asarray(values)
    if not np.all(np.isfinite(arr)):
        raise InputFileError(path, "non-finite value", line=lineno, field=name)
    return arr
