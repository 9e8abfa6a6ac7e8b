"""``slopedist convert``: round trips through every layout, and user mistakes as exit code 2."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from slopedist.cli import main

CSV = (
    "frame,left,top,right,bottom,track_id,score,class\n"
    "0,100,200,300,260,3,0.9,Car\n"
    "0,640.5,300.25,700,350,-1,0.75,Truck\n"
    "4,10,20,30,40,8,0.25,Bus\n"
)


@pytest.mark.parametrize(
    ("fmt", "name", "extra"),
    [
        ("mot", "det.txt", []),
        ("coco", "res.json", []),
        ("yolo", "labels", ["--image-size", "1280x720"]),
    ],
)
def test_csv_round_trip(
    tmp_path: Path, fmt: str, name: str, extra: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    src = tmp_path / "boxes.csv"
    src.write_text(CSV)
    mid, back = tmp_path / name, tmp_path / "back.csv"
    assert main(["convert", str(src), str(mid), "--to", fmt, *extra]) == 0
    unkept = [e for e in capsys.readouterr().err.splitlines() if e.startswith("not kept: ")]
    assert unkept == (
        ["not kept: class: MOT det.txt has none; 2 boxes of class Bus, Truck read back as Car"]
        if fmt == "mot"
        else []
    )
    assert main(["convert", str(mid), str(back), "--from", fmt, *extra]) == 0
    lines = back.read_text().splitlines()
    expected = CSV.splitlines()
    if fmt == "mot":  # MOT det.txt has no class
        expected = [e.rsplit(",", 1)[0] + ",Car" for e in expected[1:]]
        lines = lines[1:]
    assert lines == expected


def test_coco_image_map_and_auto_detection(tmp_path: Path) -> None:
    res = tmp_path / "res.json"
    res.write_text(
        json.dumps([{"image_id": 42, "category_id": 8, "bbox": [1, 2, 3, 4], "score": 0.5}])
    )
    images = tmp_path / "images.json"
    images.write_text(json.dumps({"images": [{"id": 42, "file_name": "f7.png", "frame_id": 7}]}))
    out = tmp_path / "out.csv"
    assert main(["convert", str(res), str(out), "--coco-images", str(images)]) == 0
    assert out.read_text().splitlines()[1] == "7,1,2,4,6,-1,0.5,Truck"


def test_errors_exit_2_with_file_line_field(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    bad = tmp_path / "det.txt"
    bad.write_text("1,-1,10,20,30,40,0.9,-1,-1,-1\n2,-1,10,x,30,40,0.9,-1,-1,-1\n")
    assert main(["convert", str(bad), str(tmp_path / "o.csv")]) == 2
    assert "det.txt, line 2, field 'top'" in capsys.readouterr().err
    assert main(["convert", str(bad), str(tmp_path / "y"), "--to", "yolo"]) == 2
    assert "image size" in capsys.readouterr().err
    assert main(["convert", str(bad), str(tmp_path / "y"), "--image-size", "12"]) == 2


def test_target_that_is_the_source_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """`convert boxes.csv boxes.csv --to mot` replaced the CSV (its classes and columns lost)."""
    src = tmp_path / "boxes.csv"
    src.write_text(CSV)
    assert main(["convert", str(src), str(src), "--to", "mot"]) == 2
    assert "would be overwritten" in capsys.readouterr().err
    assert src.read_text() == CSV
    (tmp_path / "link.csv").symlink_to(src)
    assert main(["convert", str(src), str(tmp_path / "link.csv")]) == 2
    assert src.read_text() == CSV


def test_a_json_target_is_coco_and_json_is_coco_alone(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """`convert boxes.csv out.json` wrote a CSV into the .json file (the default was CSV)."""
    src = tmp_path / "boxes.csv"
    src.write_text(CSV)
    out = tmp_path / "out.json"
    assert main(["convert", str(src), str(out)]) == 0
    assert json.loads(out.read_text())[0]["bbox"] == [100, 200, 200, 60]
    for fmt, name in (("csv", "x.json"), ("mot", "x.json"), ("coco", "x.csv")):
        assert main(["convert", str(src), str(tmp_path / name), "--to", fmt]) == 2
        assert "JSON is COCO's" in capsys.readouterr().err
        assert not (tmp_path / name).exists()


def test_yolo_out_refuses_an_image_size_the_boxes_do_not_fit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--image-size 100x100`` for boxes of a 1242×375 image wrote YOLO files with centres at
    3.8 image widths, silently."""
    source = tmp_path / "boxes.csv"
    source.write_text("frame,left,top,right,bottom\n0,10,10,20,20\n3,600,150,700,250\n")
    args = ["convert", str(source), str(tmp_path / "yolo"), "--to", "yolo"]
    assert main([*args, "--image-size", "100x100"]) == 2
    err = capsys.readouterr().err
    assert "1 boxes have their centre outside the 100×100 px image, e.g. frame 3" in err
    assert not (tmp_path / "yolo").exists()
    assert main([*args, "--image-size", "1242x375"]) == 0


@pytest.mark.parametrize("base", ["-5", "2000000000"])
def test_a_frame_base_beyond_the_frame_indices_is_a_usage_error(tmp_path: Path, base: str) -> None:
    """``--to mot --frame-base -5`` wrote frame -5, which no reader (this one included) takes."""
    source = tmp_path / "boxes.csv"
    source.write_text("frame,left,top,right,bottom\n0,10,10,20,20\n")
    target = tmp_path / "det.txt"
    assert main(["convert", str(source), str(target), "--to", "mot", "--frame-base", base]) == 2
    assert not target.exists()
