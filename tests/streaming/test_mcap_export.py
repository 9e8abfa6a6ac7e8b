"""The MCAP export read back: every frame's image reference, boxes, distances and θ."""

from __future__ import annotations

import base64
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

pytest.importorskip("mcap")

from slopedist.estimators.base import FrameEstimates
from slopedist.io.detections.boxes import BoxTable
from slopedist.streaming.mcap_export import (
    ANNOTATIONS_TOPIC,
    FRAME_TOPIC,
    GRADIENT_TOPIC,
    IMAGE_TOPIC,
    McapExportWriter,
    read_mcap_export,
)


def estimates(distances: list[float], reasons: list[str]) -> FrameEstimates:
    n = len(distances)
    return FrameEstimates(
        np.full(n, 0.01),
        np.full(n, 0.01),
        np.zeros(n),
        np.full(n, 100.0),
        np.array(distances, dtype=float),
        np.array(reasons, dtype=object),
        np.array(["contact"] * n, dtype=object),
    )


def test_export_holds_every_frame(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    writer = McapExportWriter(path, "ours", start_ns=1_000_000_000)
    image = np.zeros((48, 64, 3), np.uint8)
    image[10:20, 10:30] = (0, 0, 255)
    boxes = BoxTable.build([0, 0], [[5, 6, 25, 30], [30, 8, 60, 40]], [3, 7])
    for k in range(3):
        writer.write_frame(
            k,
            0.1 * k,
            f"{k:06d}.png",
            "ok" if k != 1 else "missing",
            image if k != 1 else None,
            boxes if k != 1 else boxes.select(np.zeros(2, bool)),
            estimates([12.5 + k, math.nan], ["", "below_horizon"]) if k != 1 else estimates([], []),
            math.radians(0.5 * k),
            lead=0 if k != 1 else None,
        )
    writer.close()
    data = read_mcap_export(path)
    frames = data[FRAME_TOPIC]
    assert [t for t, _ in frames] == [1_000_000_000, 1_100_000_000, 1_200_000_000]
    assert [f["image"] for _, f in frames] == ["000000.png", "000001.png", "000002.png"]
    assert [f["status"] for _, f in frames] == ["ok", "missing", "ok"]
    assert frames[2][1]["theta_deg"] == pytest.approx(1.0)
    targets = frames[2][1]["targets"]
    assert [t["track_id"] for t in targets] == [3, 7]
    assert targets[0]["box"] == [5.0, 6.0, 25.0, 30.0]
    assert targets[0]["distance_m"] == 14.5 and targets[1]["distance_m"] is None
    assert targets[1]["reason"] == "below_horizon"
    assert frames[1][1]["targets"] == []
    # the image of frames with pixels, decodable JPEG
    images = data[IMAGE_TOPIC]
    assert len(images) == 2
    jpeg = np.frombuffer(base64.b64decode(images[0][1]["data"]), np.uint8)
    decoded = cv2.imdecode(jpeg, cv2.IMREAD_COLOR)
    assert decoded.shape == image.shape and decoded[15, 20, 2] > 200
    # annotations: a closed line and a label per box
    ann = data[ANNOTATIONS_TOPIC][0][1]
    assert [p["type"] for p in ann["points"]] == [2, 2]
    assert ann["texts"][0]["text"] == "#3 12.5 m"
    assert ann["texts"][1]["text"] == "#7 missing: below_horizon"
    assert [g["lead_distance_m"] for _, g in data[GRADIENT_TOPIC]] == [12.5, None, 14.5]


def test_export_schemas_are_named_for_foxglove(tmp_path: Path) -> None:
    from mcap.reader import make_reader

    path = tmp_path / "e.mcap"
    McapExportWriter(path, "flat").close()
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    names = {s.name for s in summary.schemas.values()}
    assert {"foxglove.CompressedImage", "foxglove.ImageAnnotations"} <= names
    assert {s.encoding for s in summary.schemas.values()} == {"jsonschema"}
    assert {c.message_encoding for c in summary.channels.values()} == {"json"}


def test_upper_bound_and_withheld_rows_are_labelled_as_the_overlay_does(tmp_path: Path) -> None:
    """An upper bound is ``upper_bound`` with ``<=`` (not ``missing`` beside a number), a
    withheld distance shows no number, and a box with a non-finite corner has no annotation
    (a null coordinate is not a Foxglove point)."""
    path = tmp_path / "run.mcap"
    writer = McapExportWriter(path, "ours")
    boxes = BoxTable.build(
        [0] * 4, [[5, 6, 25, 30], [30, 8, 60, 47], [1, 1, 5, 5], [math.nan, 1, 2, 3]], [3, 7, -1, 2]
    )
    est = estimates(
        [10.0, 8.0, math.nan, math.nan], ["", "cut_bottom", "too_uncertain", "non_finite_box"]
    )
    est.status = np.array(["ok", "upper_bound", "missing", "missing"], dtype=object)
    writer.write_frame(0, 0.0, "000000.png", "ok", None, boxes, est, 0.01, lead=0)
    writer.close()
    data = read_mcap_export(path)
    targets = data[FRAME_TOPIC][0][1]["targets"]
    assert [t["status"] for t in targets] == ["ok", "upper_bound", "missing", "missing"]
    assert targets[1]["distance_m"] == 8.0
    ann = data[ANNOTATIONS_TOPIC][0][1]
    texts = [t["text"] for t in ann["texts"]]
    assert texts == ["#3 10.0 m", "#7 <= 8.0 m (cut_bottom)", "missing: too_uncertain"]
    assert len(ann["points"]) == 3
    for p in ann["points"]:
        assert all(math.isfinite(q["x"]) and math.isfinite(q["y"]) for q in p["points"])
    red = {"r": 1.0, "g": 0.0, "b": 0.0, "a": 1.0}
    assert [t["text_color"] == red for t in ann["texts"]] == [False, True, True]


def test_frame_times_before_zero_are_exported_and_the_file_is_whole(tmp_path: Path) -> None:
    """Frame times from -1 s (a timestamps file relative to a trigger): the negative log time
    was a struct.error, and the file could not even be closed (no summary). The first frame is
    now at log time 0, the bodies keep their times; a time in milliseconds read as seconds is a
    clean error."""
    from slopedist.core.errors import DataMismatchError

    path = tmp_path / "run.mcap"
    writer = McapExportWriter(path, "ours")
    empty = BoxTable.build([], np.zeros((0, 4)))
    for k in range(3):
        writer.write_frame(k, -1.0 + 0.1 * k, f"{k}", "ok", None, empty, estimates([], []), 0.0)
    with pytest.raises(DataMismatchError, match=r"frame 3: time 1700000000000\.0 s"):
        writer.write_frame(3, 1.7e12, "3", "ok", None, empty, estimates([], []), 0.0)
    writer.close()
    frames = read_mcap_export(path)[FRAME_TOPIC]
    assert [t for t, _ in frames] == [0, 100_000_000, 200_000_000]
    assert [f["timestamp_s"] for _, f in frames] == pytest.approx([-1.0, -0.9, -0.8])
