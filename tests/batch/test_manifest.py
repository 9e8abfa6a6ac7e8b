"""The drives of a batch: CSV and TOML manifests, folder layout, errors naming line and field."""

from __future__ import annotations

import csv
import io
from dataclasses import replace
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from slopedist.batch.manifest import (
    DriveDefaults,
    check_drive_name,
    load_drives,
    read_csv_manifest,
    spec_summary,
)
from slopedist.batch.settings import SETTING_COLUMNS, RunSettings
from slopedist.core.errors import ConfigurationError, InputFileError, MissingInputError
from slopedist.estimators.base import ReferencePoint

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


def test_a_score_threshold_may_be_zero_or_a_negative_logit(tmp_path: Path) -> None:
    manifest = write(
        tmp_path / "drives.csv",
        "drive,frames,calib,boxes,score\na,a.mp4,c.txt,b.csv,0\nb,a.mp4,c.txt,b.csv,-1.5\n",
    )
    a, b = read_csv_manifest(manifest)
    assert (a.score, b.score) == (0.0, -1.5)


@pytest.mark.parametrize(
    ("text", "line", "field"),
    [
        ("drive,frames,calib\n", 1, "boxes"),
        ("drive,frames,calib,boxes,speed\n", 1, "speed"),
        # a column named twice: the last cell would win silently
        ("drive,frames,calib,boxes,method,method\na,f,c,b,flat,paper\n", 1, "method"),
        ("drive,frames,calib,boxes\na,f,c,\n", 2, "boxes"),
        ("drive,frames,calib,boxes,detector\na,f,c,b,d.onnx\n", 2, "boxes"),
        ("drive,frames,calib,boxes,method\na,f,c,b,flat\nb,f,c,b,magic\n", 3, "method"),
        ("drive,frames,calib,boxes,height\na,f,c,b,tall\n", 2, "height"),
        ("drive,frames,calib,boxes,height\na,f,c,b,-1\n", 2, "height"),
        ("drive,frames,calib,boxes,odometry\na,f,c,b,gps\n", 2, "odometry"),
        ("drive,frames,calib,boxes\n../up,f,c,b\n", 2, "drive"),
        ("drive,frames,calib,boxes\na,f,c,b\n\na,g,c,b\n", 4, "drive"),
        # one output folder on macOS and Windows: the second would overwrite the first
        ("drive,frames,calib,boxes\nLead,f,c,b\nlead,g,c,b\n", 3, "drive"),
        ("drive,frames,calib,boxes\n\u00e4,f,c,b\na\u0308,g,c,b\n", 3, "drive"),
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


@pytest.mark.parametrize(
    ("name", "text"), [("m.csv", "drive,frames,calib,boxes\n"), ("m.toml", "drive = []\n")]
)
def test_a_manifest_that_lists_no_drive_is_an_error(tmp_path: Path, name: str, text: str) -> None:
    write(tmp_path / name, text)
    with pytest.raises(InputFileError, match=rf"{name}: lists no drives"):
        load_drives(tmp_path / name)


@given(st.text(max_size=12))
def test_drive_names_are_plain_folder_names(name: str) -> None:
    problem = check_drive_name(name)
    plain = bool(name) and name == name.strip() and not name.startswith(".")
    plain = plain and "/" not in name and "\\" not in name
    assert (problem is None) == plain


SETTINGS_HEADER = "drive,frames,calib,boxes,method," + ",".join(SETTING_COLUMNS)


def settings_row(name: str, method: str = "", **cells: str) -> str:
    """A manifest row of ``SETTINGS_HEADER`` with the given setting cells (others empty)."""
    values = [cells.get(c, "") for c in SETTING_COLUMNS]
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerow([name, "f", "c", "b", method, *values])
    return out.getvalue()


def test_run_settings_columns_and_batch_wide_values(tmp_path: Path) -> None:
    """Each setting column parsed; an empty cell takes the batch-wide value, which applies
    only to the methods that take it (ours options: ours-family; offline: a method with an
    offline mode; reference: every method)."""
    batch = RunSettings(
        reference="contact",
        ours_options=(("use_width", False),),
        vehicle_classes=("Car",),
        offline=True,
        export=("tum",),
    )
    manifest = write(
        tmp_path / "drives.csv",
        SETTINGS_HEADER
        + "\n"
        + settings_row(
            "a",
            "ours",
            reference=" nearest_face ",
            ours_options="size_learning=true; odd_object_weight=0;",
            vehicle_classes="Car;Van ; Truck",
            offline="no",
            overlay="YES",
            overlay_format="png",
            export="tum;mcap;tum",
        )
        + settings_row("b", "ours-selfcal")
        + settings_row("c", "paper", overlay="1")
        + settings_row("d", "ours-offline", offline="false"),
    )
    a, b, c, d = read_csv_manifest(manifest, DriveDefaults(settings=batch))
    assert a.settings == RunSettings(
        reference="nearest_face",
        ours_options=(("odd_object_weight", 0.0), ("size_learning", True)),
        vehicle_classes=("Car", "Van", "Truck"),
        offline=False,
        overlay=True,
        overlay_format="png",
        export=("mcap", "tum"),
    )
    assert a.settings.run_method(a.method) == "ours"
    # every cell empty: the batch-wide values, but offline (ours-selfcal has no offline mode)
    assert b.settings == replace(batch, offline=False)
    assert b.settings.run_method(b.method) == "ours-selfcal"
    assert c.settings == RunSettings(
        reference="contact", vehicle_classes=("Car",), overlay=True, export=("tum",)
    )
    assert c.settings.shown_reference() is ReferencePoint.CONTACT
    assert RunSettings().shown_reference() is ReferencePoint.NEAREST_FACE  # the gap
    assert c.settings.estimator("paper").ours_options == ()
    assert d.settings.run_method(d.method) == "ours-offline"
    assert spec_summary(a)["ours_options"] == {"odd_object_weight": 0.0, "size_learning": True}
    assert spec_summary(c, changed_only=True).keys() >= {"overlay", "export", "vehicle_classes"}
    assert spec_summary(c, changed_only=True)["reference"] == "contact"  # every method's


def test_generic_classes_column_and_batch_wide_value(tmp_path: Path) -> None:
    """A ``generic_classes`` cell (``--generic-class``) reaches the drive's ``ours``; an empty
    one takes the batch-wide classes, which a ``paper`` drive does not take; a batch-wide
    ``generic_sigma_only=true`` is refused on a drive left without a generic class."""
    batch = RunSettings(generic_classes=("Car",))
    manifest = write(
        tmp_path / "drives.csv",
        SETTINGS_HEADER
        + "\n"
        + settings_row("a", "ours", generic_classes="car ;", ours_options="generic_sigma_only=1")
        + settings_row("b", "ours-selfcal")
        + settings_row("c", "paper"),
    )
    a, b, c = read_csv_manifest(manifest, DriveDefaults(settings=batch))
    assert a.settings.estimator(a.method).options()["generic_classes"] == ("car",)
    assert a.settings.ours_options == (("generic_sigma_only", True),)
    assert b.settings.estimator(b.method).options()["generic_classes"] == ("Car",)
    assert c.settings == RunSettings()
    assert spec_summary(a)["generic_classes"] == ["car"]
    sigma_only = RunSettings(ours_options=(("generic_sigma_only", True),))
    text = SETTINGS_HEADER + "\n" + settings_row("a", "ours")
    with pytest.raises(InputFileError, match="--generic-class NAME") as err:
        read_csv_manifest(write(tmp_path / "d.csv", text), DriveDefaults(settings=sigma_only))
    assert err.value.field == "ours_options"


@pytest.mark.parametrize(
    ("cells", "field", "message"),
    [
        ({"reference": "rear"}, "reference", "choose from centre, nearest_face, contact"),
        ({"ours_options": "odd_object_weight=0,size_learning=true"}, "ours_options", "';'"),
        ({"ours_options": "bogus=1"}, "ours_options", "choose from .*odd_object_weight"),
        ({"ours_options": "min_iou=2"}, "ours_options", r"min_iou must be in \[0, 1\]"),
        ({"ours_options": "use_width=maybe"}, "ours_options", "'maybe' is not a bool"),
        ({"ours_options": "use_width=0;use_width=1"}, "ours_options", "more than once"),
        (
            {"ours_options": "odd_object_weight=0.6;atypical_height_weight=0.5"},
            "ours_options",
            "sum below 1",
        ),
        ({"vehicle_classes": ";"}, "vehicle_classes", "at least one vehicle class"),
        ({"vehicle_classes": "Car;Van,Truck"}, "vehicle_classes", "';'"),
        ({"offline": "maybe"}, "offline", "'maybe' is not true or false"),
        ({"overlay": "2"}, "overlay", "'2' is not true or false"),
        ({"overlay": "true", "overlay_format": "gif"}, "overlay_format", "mp4, png"),
        ({"overlay_format": "png"}, "overlay_format", "drives with an overlay"),
        ({"export": "mcap;bag"}, "export", "'bag' is not one of mcap, tum"),
        ({"generic_classes": " ; "}, "generic_classes", "names no class"),
        ({"generic_classes": "Tram"}, "generic_classes", "'Tram' is not one of the vehicle"),
        ({"ours_options": "generic_sigma_only=true"}, "ours_options", "column generic_classes"),
    ],
)
def test_run_settings_cell_errors_name_line_and_field(
    tmp_path: Path, cells: dict[str, str], field: str, message: str
) -> None:
    text = SETTINGS_HEADER + "\n" + settings_row("a", "ours") + settings_row("b", "ours", **cells)
    with pytest.raises(InputFileError, match=message) as err:
        read_csv_manifest(write(tmp_path / "drives.csv", text))
    assert (err.value.path, err.value.line, err.value.field) == (tmp_path / "drives.csv", 3, field)
    assert f"drives.csv, line 3, field '{field}'" in str(err.value)


@pytest.mark.parametrize(
    ("method", "cells", "field", "message"),
    [
        ("paper", {"ours_options": "use_width=false"}, "ours_options", "is for methods ours,"),
        ("paper", {"offline": "true"}, "offline", "method 'paper' has no offline mode"),
        ("paper", {"generic_classes": "car"}, "generic_classes", "is for methods ours,"),
    ],
)
def test_run_settings_for_a_method_that_does_not_take_them(
    tmp_path: Path, method: str, cells: dict[str, str], field: str, message: str
) -> None:
    text = SETTINGS_HEADER + "\n" + settings_row("a", method, **cells)
    with pytest.raises(InputFileError, match=message) as err:
        read_csv_manifest(write(tmp_path / "drives.csv", text))
    assert (err.value.line, err.value.field) == (2, field)
    defaults = DriveDefaults(method=method)  # the same through the batch-wide method
    text = SETTINGS_HEADER + "\n" + settings_row("a", "", **cells)
    with pytest.raises(InputFileError, match=message):
        read_csv_manifest(write(tmp_path / "drives.csv", text), defaults)


def test_run_settings_in_a_toml_manifest(tmp_path: Path) -> None:
    """TOML takes the settings as booleans, lists and (``ours_options``) a table or a list of
    ``KEY=VALUE`` texts; errors name the ``[[drive]]`` entry and the key."""
    head = 'frames = "f"\ncalib = "c"\nboxes = "b"\n'
    manifest = write(
        tmp_path / "drives.toml",
        f'[[drive]]\ndrive = "a"\n{head}method = "ours"\nreference = "contact"\n'
        "ours_options = { odd_object_weight = 0, size_learning = true }\n"
        'vehicle_classes = ["Car", "Van"]\noffline = true\noverlay = true\n'
        'overlay_format = "png"\nexport = ["mcap", "tum"]\n\n'
        f'[[drive]]\ndrive = "b"\n{head}ours_options = ["use_width=false", "min_iou=0.5"]\n\n'
        f'[[drive]]\ndrive = "c"\n{head}ours_options = "use_width=false;min_iou=0.5"\n',
    )
    a, b, c = load_drives(manifest)
    assert a.settings == RunSettings(
        "contact",
        (("odd_object_weight", 0.0), ("size_learning", True)),
        ("Car", "Van"),
        offline=True,
        overlay=True,
        overlay_format="png",
        export=("mcap", "tum"),
    )
    assert (
        b.settings.ours_options
        == c.settings.ours_options
        == (
            ("min_iou", 0.5),
            ("use_width", False),
        )
    )
    for bad, field, message in (
        ("ours_options = { bogus = 1 }", "ours_options", "choose from"),
        ('ours_options = { use_width = "perhaps" }', "ours_options", "'perhaps' is not a bool"),
        ("offline = 3", "offline", "'3' is not true or false"),
        ("reference = [1, 2]", "reference", "not a reference point"),
        ("reference = { a = 1 }", "reference", "expected a string, number or boolean"),
        ("export = [[1]]", "export", "expected a string, number or boolean"),
    ):
        text = manifest.read_text() + f'\n[[drive]]\ndrive = "d"\n{head}{bad}\n'
        with pytest.raises(InputFileError, match=f"entry 4: .*{message}") as err:
            load_drives(write(tmp_path / "bad.toml", text))
        assert err.value.field == field and "bad.toml" in str(err.value)


def test_folder_layout_with_drive_logs(tmp_path: Path) -> None:
    """A drive folder whose frames are a drive log (a log file, a ROS 2 bag sub-folder, or the
    folder itself a ROS 2 bag): the log is the frames, ``calib.txt`` optional, the image topic
    batch-wide; image frames win over a log."""
    write(tmp_path / "a_bag" / "drive.bag", "x")
    write(tmp_path / "a_bag" / "boxes.csv", "frame")
    write(tmp_path / "a_bag" / "times.txt", "0\n")  # a log's times are its stamps: not read
    write(tmp_path / "b_ros2" / "metadata.yaml", "rosbag2_bagfile_information: {}\n")
    write(tmp_path / "b_ros2" / "b_ros2_0.db3", "x")
    write(tmp_path / "c_sub" / "log" / "metadata.yaml", "rosbag2_bagfile_information: {}\n")
    write(tmp_path / "c_sub" / "calib.txt", "P2: 1")
    write(tmp_path / "c_sub" / ".old.mcap", "x")  # hidden: ignored
    (tmp_path / "d_images" / "image_02").mkdir(parents=True)
    write(tmp_path / "d_images" / "d.mcap", "x")
    defaults = DriveDefaults(method="ours", image_topic="/cam", settings=RunSettings(offline=True))
    a, b, c, d = load_drives(tmp_path, defaults)
    assert (a.frames, a.calib, a.timestamps) == (tmp_path / "a_bag" / "drive.bag", None, None)
    assert (a.image_topic, a.boxes) == ("/cam", tmp_path / "a_bag" / "boxes.csv")
    assert (b.frames, b.calib) == (tmp_path / "b_ros2", None)
    assert (c.frames, c.calib) == (tmp_path / "c_sub" / "log", tmp_path / "c_sub" / "calib.txt")
    assert (d.frames, d.image_topic) == (tmp_path / "d_images" / "image_02", None)
    assert all(s.settings.offline for s in (a, b, c, d))
    with pytest.raises(ConfigurationError, match=r"a_bag: frames 'drive.bag' are a drive log; "):
        load_drives(tmp_path, DriveDefaults())
    write(tmp_path / "a_bag" / "second.mcap", "x")
    with pytest.raises(ConfigurationError, match=r"several drive logs \(drive.bag, second.mcap\)"):
        load_drives(tmp_path, defaults)


def test_a_batch_wide_image_topic_fills_the_empty_cells_of_logs(tmp_path: Path) -> None:
    manifest = write(
        tmp_path / "drives.csv",
        "drive,frames,calib,boxes,image_topic\na,a.bag,,b,\nb,b.mcap,,b,/own\nc,f,c,b,\n",
    )
    a, b, c = read_csv_manifest(manifest, DriveDefaults(image_topic="/cam"))
    assert (a.image_topic, b.image_topic, c.image_topic) == ("/cam", "/own", None)
    with pytest.raises(InputFileError, match="or with batch --image-topic") as err:
        read_csv_manifest(manifest)
    assert (err.value.line, err.value.field) == (2, "image_topic")
