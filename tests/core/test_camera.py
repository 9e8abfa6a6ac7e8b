"""Camera construction and the KITTI calib reader."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from slopedist.core.camera import Camera, read_kitti_calib
from slopedist.core.errors import ConfigurationError, InputFileError, MissingInputError

P2 = "7.2e+02 0 6.1e+02 44.8 0 7.2e+02 1.73e+02 0.2 0 0 1 0.003"


def test_from_kitti_calib_reads_p2(tmp_path: Path) -> None:
    path = tmp_path / "calib.txt"
    path.write_text(f"P0: {P2}\nP2: {P2}\nR0_rect: 1 0 0 0 1 0 0 0 1\n")
    cam = Camera.from_kitti_calib(path)
    assert (cam.f, cam.c_x, cam.c_y, cam.height_m) == (720.0, 610.0, 173.0, 1.65)


def test_odometry_calib_of_bare_numbers_uses_first_line(tmp_path: Path) -> None:
    path = tmp_path / "calib.txt"
    path.write_text(f"{P2}\n{P2}\n")
    assert Camera.from_kitti_calib(path).f == 720.0


def test_from_values_converts_degrees() -> None:
    cam = Camera.from_values(700, 600, 180, 1.2, mount_angle_deg=2.0)
    assert cam.mount_angle_rad == pytest.approx(math.radians(2.0))


def test_bad_field_names_file_line_and_field(tmp_path: Path) -> None:
    path = tmp_path / "calib.txt"
    path.write_text(f"P0: {P2}\nP2: 7.2e+02 0 abc 44.8 0 7.2e+02 1.73e+02 0.2 0 0 1 0.003\n")
    with pytest.raises(InputFileError, match=r"calib.txt, line 2, field 'P2\[2\]'"):
        read_kitti_calib(path)


def test_wrong_count_is_reported(tmp_path: Path) -> None:
    path = tmp_path / "calib.txt"
    path.write_text("P2: 1 2 3\n")
    with pytest.raises(InputFileError, match=r"line 1.*expected 12 numbers, found 3"):
        read_kitti_calib(path)


def test_missing_file_and_missing_key(tmp_path: Path) -> None:
    with pytest.raises(MissingInputError, match=r"nope\.txt"):
        Camera.from_kitti_calib(tmp_path / "nope.txt")
    path = tmp_path / "calib.txt"
    path.write_text(f"P1: {P2}\n")
    with pytest.raises(InputFileError, match=r"no .P2:. line"):
        Camera.from_kitti_calib(path)


@pytest.mark.parametrize("kwargs", [{"f": -1.0}, {"height_m": 0.0}, {"c_y": float("nan")}])
def test_invalid_values_rejected(kwargs: dict[str, float]) -> None:
    values = {"f": 700.0, "c_x": 600.0, "c_y": 180.0, **kwargs}
    with pytest.raises(ConfigurationError):
        Camera(**values)


def test_real_kitti_calib(kitti_tracking_dir: Path) -> None:
    cam = Camera.from_kitti_calib(kitti_tracking_dir / "calib" / "0000.txt")
    assert cam.f == pytest.approx(721.5377)
    assert cam.c_y == pytest.approx(172.854)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"f": 1e-9}, "focal length"),
        ({"f": 1e308}, "focal length"),
        ({"f": 49.0}, "focal length"),
        ({"f": float("inf")}, "must be finite"),
        ({"c_x": 1e300}, "principal point c_x"),
        ({"c_y": -2e5}, "principal point c_y"),
        ({"height_m": 1e308}, "height"),
        ({"height_m": -1.65}, "height"),
        ({"mount_angle_rad": 1.2}, "mount angle"),
        (
            {"c_y": 400.0, "image_width": 1242, "image_height": 375},
            "c_y = 400 px is outside 0..375",
        ),
        ({"image_width": 0, "image_height": 375}, "image size"),
    ],
)
def test_implausible_values_rejected(kwargs: dict[str, float], match: str) -> None:
    values = {"f": 721.5, "c_x": 609.6, "c_y": 172.9, **kwargs}
    with pytest.raises(ConfigurationError, match=match):
        Camera(**values)  # type: ignore[arg-type]


def test_plausible_extremes_accepted() -> None:
    assert Camera(50.0, 0.0, 375.0, 0.1, image_width=1242, image_height=375).f == 50.0
    assert Camera(20_000.0, -5e4, 5e4, 50.0, -1.0).height_m == 50.0


@pytest.mark.parametrize(
    ("p2", "match"),
    [
        ("1e-9 0 609.5 0 0 1e-9 172.8 0 0 0 1 0", r"line 2, field 'P2'.*focal length"),
        ("1e308 0 609.5 0 0 1e308 172.8 0 0 0 1 0", r"line 2, field 'P2'.*focal length"),
        ("721.5 0 609.5 0 0 721.5 1e9 0 0 0 1 0", r"line 2, field 'P2'.*c_y"),
    ],
)
def test_implausible_calib_names_file_line_and_key(tmp_path: Path, p2: str, match: str) -> None:
    path = tmp_path / "calib.txt"
    path.write_text(f"P0: {P2}\nP2: {p2}\n")
    with pytest.raises(InputFileError, match=match):
        Camera.from_kitti_calib(path)


def test_second_key_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "calib.txt"
    path.write_text(f"P2: {P2}\n\nR0_rect: 1 0 0 0 1 0 0 0 1\nP2: {P2}\n")
    with pytest.raises(
        InputFileError, match=r"line 4, field 'P2': second 'P2:' line \(the first is line 1\)"
    ):
        read_kitti_calib(path)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"f": "700"}, "camera f must be a number, got '700'"),
        ({"f": None}, "camera f must be a number, got None"),
        ({"mount_angle_rad": "0"}, "camera mount_angle_rad must be a number"),
        ({"height_m": True}, "camera height_m must be a number, got True"),
        ({"image_width": True, "image_height": 375}, "image size must be 1..1000000 px, got True"),
    ],
)
def test_values_that_are_not_numbers_are_configuration_errors(
    kwargs: dict[str, object], message: str
) -> None:
    """Text and None failed with math.isfinite's bare TypeError; a bool passed as 1."""
    values: dict[str, object] = {"f": 700.0, "c_x": 0.5, "c_y": 0.5} | kwargs
    with pytest.raises(ConfigurationError, match=message):
        Camera(**values)  # type: ignore[arg-type]
