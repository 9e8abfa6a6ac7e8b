"""The drives of a batch: CSV and TOML manifests, folder layout, errors naming line and field."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from slopedist.batch.manifest import (
    DriveDefaults,
    check_drive_name,
    load_drives,
    read_csv_manifest,
)
from slopedist.errors import InputFileError, MissingInputError

HEADER = "drive,frames,calib,boxes,method,height,mount_angle,timestamps"


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def test_csv_manifest_paths_are_relative_to_the_manifest(tmp_path: Path) -> None:
    manifest = write(
        tmp_path / "m" / "drives.csv",
        f"{HEADER}\na,da/image_02,da/calib.txt,da/boxes.csv,flat,1.5,-2,da/times.txt\n"
        "b,/abs/video.mp4,c.txt,b.csv,,,,\n\n",
    )
    a, b = read_csv_manifest(manifest, DriveDefaults(method="ego", height_m=1.7))
    assert a.name == "a" and a.frames == tmp_path / "m" / "da" / "image_02"
    assert a.timestamps == tmp_path / "m" / "da" / "times.txt"
    assert (a.method, a.height_m, a.mount_angle_deg) == ("flat", 1.5, -2.0)
    assert b.frames == Path("/abs/video.mp4") and b.timestamps is None
    assert (b.method, b.height_m, b.mount_angle_deg) == ("ego", 1.7, 0.0)  # batch defaults
    assert a.origin.endswith("drives.csv:2")


@pytest.mark.parametrize(
    ("text", "line", "field"),
    [
        ("drive,frames,calib\n", 1, "boxes"),
        ("drive,frames,calib,boxes,speed\n", 1, "speed"),
        ("drive,frames,calib,boxes\na,f,c,\n", 2, "boxes"),
        ("drive,frames,calib,boxes,detector\na,f,c,b,d.onnx\n", 2, "boxes"),
        ("drive,frames,calib,boxes,method\na,f,c,b,flat\nb,f,c,b,magic\n", 3, "method"),
        ("drive,frames,calib,boxes,height\na,f,c,b,tall\n", 2, "height"),
        ("drive,frames,calib,boxes,height\na,f,c,b,-1\n", 2, "height"),
        ("drive,frames,calib,boxes,odometry\na,f,c,b,gps\n", 2, "odometry"),
        ("drive,frames,calib,boxes\n../up,f,c,b\n", 2, "drive"),
        ("drive,frames,calib,boxes\na,f,c,b\n\na,g,c,b\n", 4, "drive"),
        # calib: required for image folders and videos, optional for a drive log
        ("drive,frames,boxes\na,f,b\n", 2, "calib"),
        ("drive,frames,calib,boxes,image_topic\na,l.bag,,b,/c\nb,v.mp4,,b,\n", 3, "calib"),
        # a drive log needs its image topic and takes no timestamps file
        ("drive,frames,boxes,image_topic\na,l.bag,b,/cam\nb,l.mcap,b,\n", 3, "image_topic"),
        ("drive,frames,boxes,image_topic,timestamps\na,l.db3,b,/cam,t.txt\n", 2, "timestamps"),
        # topics are for drive logs only
        ("drive,frames,calib,boxes,speed_topic\na,f,c,b,/odom\n", 2, "speed_topic"),
        ("drive,frames,calib,boxes,rotation_topic\na,v.mp4,c,b,/imu\n", 2, "rotation_topic"),
        ("drive,frames,calib,boxes,image_topic\na,f,c,b,/cam\n", 2, "image_topic"),
    ],
)
def test_csv_manifest_errors_name_line_and_field(
    tmp_path: Path, text: str, line: int, field: str
) -> None:
    manifest = write(tmp_path / "drives.csv", text)
    with pytest.raises(InputFileError) as err:
        read_csv_manifest(manifest)
    assert (err.value.line, err.value.field) == (line, field)
    assert f"line {line}, field '{field}'" in str(err.value)


@pytest.mark.parametrize(
    ("name", "content", "line", "message"),
    [
        ("drives.csv", b"drive,frames,calib,boxes\n\xffa,f,c,b\n", 2, "not UTF-8"),
        ("drives.csv", b"drive,frames,calib,boxes\na," + b"9" * 200_000 + b",c,b\n", 2, "CSV row"),
        ("drives.toml", b'[[drive]]\ndrive = "a"\n# \xff\n', 3, "not UTF-8"),
    ],
)
def test_manifests_read_as_strict_text(
    tmp_path: Path, name: str, content: bytes, line: int, message: str
) -> None:
    manifest = tmp_path / name
    manifest.write_bytes(content)
    with pytest.raises(InputFileError, match=message) as err:
        load_drives(manifest)
    assert err.value.line == line


def test_toml_manifest(tmp_path: Path) -> None:
    manifest = write(
        tmp_path / "drives.toml",
        '[[drive]]\ndrive = "a"\nframes = "a/image_02"\ncalib = "a/calib.txt"\n'
        'boxes = "a/boxes.csv"\nmethod = "paper"\nfps = 5\n\n'
        '[[drive]]\ndrive = "b"\nframes = "v.mp4"\ncalib = "c.txt"\nboxes = "b.csv"\n',
    )
    a, b = load_drives(manifest)
    assert (a.method, a.fps, a.frames) == ("paper", 5.0, tmp_path / "a" / "image_02")
    assert b.name == "b"
    bad = write(tmp_path / "bad.toml", manifest.read_text() + '\n[[drive]]\ndrive = "c"\n')
    with pytest.raises(InputFileError, match=r"entry 3: is empty") as err:
        load_drives(bad)
    assert err.value.field == "frames"


def test_drive_logs_name_their_topics_and_may_leave_out_calib(tmp_path: Path) -> None:
    bag_dir = tmp_path / "logs" / "ros2_bag"  # a ROS 2 bag folder is a log too
    write(bag_dir / "metadata.yaml", "rosbag2_bagfile_information: {}\n")
    csv_manifest = write(
        tmp_path / "logs" / "drives.csv",
        "drive,frames,boxes,method,image_topic,rotation_topic,speed_topic\n"
        "a,a.bag,a.csv,imu,/cam/image_raw,/imu/data,/odom\n"
        "b,ros2_bag,b.csv,,/cam/image_rect,,\n",
    )
    a, b = read_csv_manifest(csv_manifest)
    assert (a.frames, a.calib) == (tmp_path / "logs" / "a.bag", None)
    assert (a.image_topic, a.rotation_topic, a.speed_topic) == (
        "/cam/image_raw",
        "/imu/data",
        "/odom",
    )
    assert (b.frames, b.image_topic, b.rotation_topic, b.speed_topic) == (
        bag_dir,
        "/cam/image_rect",
        None,
        None,
    )
    toml_manifest = write(
        tmp_path / "logs" / "drives.toml",
        '[[drive]]\ndrive = "a"\nframes = "a.bag"\nboxes = "a.csv"\nmethod = "imu"\n'
        'image_topic = "/cam/image_raw"\nrotation_topic = "/imu/data"\nspeed_topic = "/odom"\n'
        '\n[[drive]]\ndrive = "c"\nframes = "c.mcap"\ncalib = "c.txt"\nboxes = "c.csv"\n'
        'image_topic = "/front"\n',
    )
    from_toml, c = load_drives(toml_manifest)
    assert from_toml == a.__class__(**{**a.__dict__, "origin": from_toml.origin})
    assert (c.calib, c.image_topic) == (tmp_path / "logs" / "c.txt", "/front")
    with pytest.raises(InputFileError, match=r"entry 2: is empty: frames 'c.mcap' is a drive log"):
        load_drives(
            write(tmp_path / "bad.toml", toml_manifest.read_text().replace('"/front"', '""'))
        )


def test_folder_layout(tmp_path: Path) -> None:
    for name, frames in (("d1", "image_02"), ("d2", "video.mp4")):
        target = tmp_path / name / frames
        target.mkdir(parents=True) if frames == "image_02" else write(target, "x")
        write(tmp_path / name / "calib.txt", "P2: 1")
        write(tmp_path / name / "boxes.csv", "frame")
    write(tmp_path / "d1" / "times.txt", "0\n")
    (tmp_path / "notes").mkdir()
    (tmp_path / ".cache" / "image_02").mkdir(parents=True)
    d1, d2 = load_drives(tmp_path, DriveDefaults(method="flat"))
    assert (d1.name, d1.frames.name, d1.timestamps) == ("d1", "image_02", tmp_path / "d1/times.txt")
    assert (d2.name, d2.frames.name, d2.timestamps, d2.method) == ("d2", "video.mp4", None, "flat")
    with pytest.raises(MissingInputError, match="no drives"):
        load_drives(tmp_path / "notes")
    with pytest.raises(MissingInputError, match="not found"):
        load_drives(tmp_path / "absent.csv")


@given(st.text(max_size=12))
def test_drive_names_are_plain_folder_names(name: str) -> None:
    problem = check_drive_name(name)
    plain = bool(name) and name == name.strip() and not name.startswith(".")
    plain = plain and "/" not in name and "\\" not in name
    assert (problem is None) == plain
