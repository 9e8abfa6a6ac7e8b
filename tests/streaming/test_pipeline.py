"""The streaming object users and ``slopedist run`` share: every box form gives the same
targets, the image size comes from the frames (no silent trap with a KITTI calibration), the
records equal those of ``slopedist run`` on the same frames and boxes, and the end of a stream
gives what the method has to give."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from slopedist.cli import main
from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError, DataMismatchError
from slopedist.estimators import make_estimator
from slopedist.estimators.base import EstimateStatus
from slopedist.io.calibration import read_calibration
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.readers import read_box_file
from slopedist.io.formatting import CsvStreamWriter
from slopedist.io.frames import open_frames
from slopedist.streaming.pipeline import Pipeline, Target
from slopedist.streaming.step import DEFAULT_RECORD_FIELDS, FrameStep

KITTI_P2 = (
    "P2: 7.215377e+02 0.000000e+00 6.095593e+02 4.485728e+01 0.000000e+00 7.215377e+02 "
    "1.728540e+02 2.163791e-01 0.000000e+00 0.000000e+00 1.000000e+00 2.745884e-03\n"
)
W, H = 1242, 375
IMAGE = np.zeros((H, W, 3), np.uint8)
BOXES = np.array(
    [[560.0, 185.0, 660.0, 255.0], [300.0, 190.0, 420.0, 270.0], [500.0, 250.0, 760.0, 375.0]]
)
"""Two vehicles ahead and one cut by the bottom of the 1242×375 image."""
SCORES = np.array([0.9, 0.8, 0.7])
COCO_CAR = 2


def kitti_calib(tmp_path: Path) -> Path:
    path = tmp_path / "calib.txt"
    path.write_text(KITTI_P2)
    return path


class FakeTensor:
    """Quacks like a torch tensor: ``.cpu().numpy()``."""

    def __init__(self, a: np.ndarray) -> None:
        self.a = a

    def cpu(self) -> FakeTensor:
        return self

    def numpy(self) -> np.ndarray:
        return self.a


def fake_ultralytics() -> list[SimpleNamespace]:
    """What ``YOLO(...)(image)`` returns: a list of one ``Results``."""
    boxes = SimpleNamespace(
        xyxy=FakeTensor(BOXES),
        conf=FakeTensor(SCORES),
        cls=FakeTensor(np.full(3, float(COCO_CAR))),
        id=None,
    )
    return [SimpleNamespace(boxes=boxes, names={COCO_CAR: "car"})]


def fake_supervision() -> SimpleNamespace:
    return SimpleNamespace(
        xyxy=BOXES, confidence=SCORES, class_id=np.full(3, COCO_CAR), tracker_id=None
    )


BOX_FORMS: dict[str, Any] = {
    "array (N, 5)": np.c_[BOXES, SCORES],
    "array (N, 6)": np.c_[BOXES, SCORES, np.full(3, COCO_CAR)],
    "tuples": [(*b, s) for b, s in zip(BOXES.tolist(), SCORES.tolist(), strict=True)],
    "tuples with a class name": [
        (*b, s, "Car") for b, s in zip(BOXES.tolist(), SCORES.tolist(), strict=True)
    ],
    "BoxTable": BoxTable.build(np.zeros(3), BOXES, score=SCORES),
    "ultralytics Results": fake_ultralytics(),
    "supervision Detections": fake_supervision(),
}


def flat_pipeline(tmp_path: Path, **options: Any) -> Pipeline:
    return Pipeline(kitti_calib(tmp_path), method="flat", odometry="none", **options)


def fields(t: Target) -> tuple[Any, ...]:
    return (t.cls, t.box, t.distance_m, t.status, t.reason, t.cut, t.score)


@pytest.mark.parametrize("form", list(BOX_FORMS))
def test_every_box_form_gives_the_same_targets(tmp_path: Path, form: str) -> None:
    expected = flat_pipeline(tmp_path).update(IMAGE, np.c_[BOXES, SCORES]).targets
    got = flat_pipeline(tmp_path).update(IMAGE, BOX_FORMS[form]).targets
    assert [fields(t) for t in got] == [fields(t) for t in expected]
    assert [t.status.value for t in got] == ["ok", "ok", "upper_bound"]
    assert got[0].distance_m == pytest.approx(721.5377 * 1.65 / (255.0 - 172.854))


def test_boxes_without_a_score_are_the_same_boxes(tmp_path: Path) -> None:
    plain = flat_pipeline(tmp_path).update(IMAGE, BOXES).targets
    scored = flat_pipeline(tmp_path).update(IMAGE, np.c_[BOXES, SCORES]).targets
    assert [fields(t)[:-1] for t in plain] == [fields(t)[:-1] for t in scored]
    assert all(math.isnan(t.score) for t in plain)


def test_a_class_index_outside_the_class_map_drops_the_box(tmp_path: Path) -> None:
    person = np.c_[BOXES[:1], SCORES[:1], [0.0]]  # COCO 0: person
    assert flat_pipeline(tmp_path).update(IMAGE, person).targets == ()
    named = flat_pipeline(tmp_path, class_map={0: "Pedestrian"}).update(IMAGE, person)
    assert (named.targets[0].status.value, named.targets[0].reason) == ("missing", "not_a_vehicle")


def test_boxes_of_no_known_form_are_refused(tmp_path: Path) -> None:
    pipe = flat_pipeline(tmp_path)
    with pytest.raises(DataMismatchError, match="3 values per box"):
        pipe.update(IMAGE, np.zeros((2, 3)))
    with pytest.raises(DataMismatchError, match="one frame"):
        pipe.update(IMAGE, BoxTable.build([0, 1], BOXES[:2]))


@pytest.mark.parametrize("method", ["flat", "paper"])
def test_kitti_calibration_and_a_bottom_cut_box_give_an_upper_bound(
    tmp_path: Path, method: str
) -> None:
    """A KITTI calibration states no image size: the first image gives it, so the box cut by
    the bottom is a bound, as ``slopedist run`` says (the estimator fed the calibration as read
    never learns the size and calls it ``ok``)."""
    calib = kitti_calib(tmp_path)
    bottom_cut = BOXES[2:]
    pipe = Pipeline(calib, method=method, odometry="none")
    target = pipe.update(IMAGE, bottom_cut, R_world_cam=np.eye(3)).targets[0]
    assert (target.status, target.reason, target.cut) == (
        EstimateStatus.UPPER_BOUND,
        "cut_bottom",
        "bottom",
    )
    unsized = FrameStep(make_estimator(method, read_calibration(calib).camera))
    trap = unsized.step(0, 0.0, np.eye(3), BoxTable.build([0], bottom_cut))
    assert trap.estimates.status[0] == "ok" and trap.estimates.cut[0] == ""


def test_ours_knows_the_border_of_a_kitti_calibration(tmp_path: Path) -> None:
    pipe = Pipeline(kitti_calib(tmp_path), odometry="none")
    targets = pipe.update(IMAGE, BOXES, R_world_cam=np.eye(3)).targets
    assert [t.cut for t in targets] == ["", "", "bottom"]
    assert targets[0].ok and targets[0].reference == "nearest_face"
    assert math.isfinite(targets[0].sigma_m) and targets[0].track_id >= 0


def test_images_of_another_size_are_refused(tmp_path: Path) -> None:
    pipe = flat_pipeline(tmp_path)
    pipe.update(IMAGE, BOXES)
    with pytest.raises(DataMismatchError, match="in a stream of 1242×375"):
        pipe.update(np.zeros((100, 200, 3), np.uint8), BOXES)
    sized = Pipeline(kitti_calib(tmp_path), method="flat", image_size=(W, H))
    with pytest.raises(DataMismatchError, match="calibration is for 1242×375"):
        sized.update(np.zeros((H, 1000, 3), np.uint8), BOXES)


def test_no_image_and_no_size_is_refused_not_guessed(tmp_path: Path) -> None:
    with pytest.raises(ConfigurationError, match="image_size"):
        flat_pipeline(tmp_path).update(None, BOXES)
    sized = flat_pipeline(tmp_path, image_size=(W, H))
    assert sized.update(None, BOXES).targets[2].status is EstimateStatus.UPPER_BOUND


def test_times_default_to_the_frame_rate_and_must_increase(tmp_path: Path) -> None:
    pipe = flat_pipeline(tmp_path, fps=5.0)
    assert [pipe.update(IMAGE, BOXES).t for _ in range(3)] == [0.0, 0.2, 0.4]
    with pytest.raises(DataMismatchError, match="does not follow"):
        pipe.update(IMAGE, BOXES, t=0.1)


def test_a_rotation_from_elsewhere_gives_theta(tmp_path: Path) -> None:
    pipe = Pipeline(kitti_calib(tmp_path), method="ego", odometry="none")
    pitch = 0.02
    c, s = math.cos(pitch), math.sin(pitch)
    R = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    pipe.update(IMAGE, BOXES, 0.0, R_world_cam=np.eye(3))
    res = pipe.update(IMAGE, BOXES, 1.0, R_world_cam=R)
    assert abs(res.theta_deg) == pytest.approx(math.degrees(pitch), rel=1e-6)
    with pytest.raises(ConfigurationError, match="odometry='none'"):
        Pipeline(kitti_calib(tmp_path)).update(IMAGE, BOXES, R_world_cam=R)


def test_an_imu_method_is_not_fed_the_visual_odometry(tmp_path: Path) -> None:
    with pytest.raises(ConfigurationError, match="'oxts' rotations"):
        Pipeline(kitti_calib(tmp_path), method="imu")


def test_the_offline_pass_comes_with_finish(tmp_path: Path) -> None:
    with Pipeline(kitti_calib(tmp_path), method="ours-offline", odometry="none") as pipe:
        causal = [pipe.update(IMAGE, BOXES[:2], R_world_cam=np.eye(3)) for _ in range(5)]
        end = pipe.finish()
    assert [r.frame for r in end.frames] == [r.frame for r in causal]
    assert all(r.method == "ours-offline" for r in end.frames)
    assert len(end.to_records()) == 10 and end.calibration is None
    with pytest.raises(ConfigurationError, match="closed"):
        pipe.update(IMAGE, BOXES)


def test_a_self_calibration_ends_with_its_estimate(tmp_path: Path) -> None:
    pipe = Pipeline(kitti_calib(tmp_path), method="ours-selfcal", odometry="none")
    pipe.update(IMAGE, BOXES[:2])  # no rotation: nothing to calibrate from
    end = pipe.finish()
    assert end.calibration is not None and end.calibration.height_m == pytest.approx(1.65)
    assert any("did not self-calibrate" in w for w in end.warnings)


def records_text(rows: list[dict[str, Any]]) -> str:
    buffer = io.StringIO()
    writer = CsvStreamWriter(buffer)
    writer.write_rows(rows)
    return buffer.getvalue()


def run_records(out: Path) -> list[dict[str, str]]:
    with (out / "records.csv").open(newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.parametrize("method", ["ours", "paper"])
def test_pipeline_gives_the_records_of_slopedist_run(
    tmp_path: Path, drive_files: Any, method: str
) -> None:
    """The same frames and boxes through :class:`Pipeline` and through ``slopedist run``
    (built-in odometry from the pixels): the same records, value for value."""
    pytest.importorskip("slopedist.odometry.visual")
    d = drive_files
    out = tmp_path / "run"
    args = ["run", str(d.frames), "--calib", str(d.calib), "--boxes", str(d.boxes)]
    assert main([*args, *d.run_options, "--method", method, "--out", str(out), "--quiet"]) == 0
    options = dict(zip(d.run_options[::2], d.run_options[1::2], strict=True))
    pipe = Pipeline(
        d.calib,
        method=method,
        height_m=float(options.get("--height", 1.65)),
        mount_angle_deg=float(options.get("--mount-angle", 0.0)),
    )
    frames = open_frames(d.frames, timestamps=options.get("--timestamps"))
    by_frame = read_box_file(d.boxes).frame_lookup()
    rows: list[dict[str, Any]] = []
    for frame in frames:
        boxes = by_frame.get(frame.index, BoxTable.empty())
        result = pipe.update(frame.image, boxes, frame.timestamp_s, frame=frame.index)
        rows += result.to_records()
    written = (out / "records.csv").read_text()
    assert records_text(rows) == written
    assert len(rows) == len(run_records(out)) > 0
    assert any(row["status"] == "ok" for row in rows)


def test_the_run_loop_steps_its_frames_through_the_pipeline(
    tmp_path: Path, drive_files: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``slopedist run`` has no frame step of its own: every frame goes through
    :meth:`Pipeline.process`."""
    seen: list[int] = []
    real = Pipeline.process

    def spy(self: Pipeline, frame_index: int, *args: Any, **kwargs: Any) -> Any:
        seen.append(frame_index)
        return real(self, frame_index, *args, **kwargs)

    monkeypatch.setattr(Pipeline, "process", spy)
    d = drive_files
    out = tmp_path / "run"
    args = ["run", str(d.frames), "--calib", str(d.calib), "--boxes", str(d.boxes), "--quiet"]
    assert (
        main([*args, *d.run_options, "--method", "flat", "--odometry", "none", "--out", str(out)])
        == 0
    )
    frames = {int(r["frame"]) for r in run_records(out)}
    assert frames <= set(seen) and len(seen) == len(list(open_frames(d.frames)))


def test_a_camera_instead_of_a_file(tmp_path: Path) -> None:
    cam = Camera(721.5377, 609.5593, 172.854)
    by_camera = Pipeline(cam, method="flat").update(IMAGE, BOXES).targets
    by_file = flat_pipeline(tmp_path).update(IMAGE, BOXES).targets
    assert [fields(t)[:-1] for t in by_camera] == [fields(t)[:-1] for t in by_file]
    higher = Pipeline(cam, method="flat", height_m=2.0).update(IMAGE, BOXES).targets
    assert higher[0].distance_m == pytest.approx(by_file[0].distance_m * 2.0 / 1.65)


@pytest.mark.parametrize(
    ("options", "suggestion"),
    [
        ({"method": "our"}, "unknown method 'our'; did you mean 'ours'?"),
        ({"odometry": "builtn"}, "unknown odometry 'builtn'; did you mean 'builtin'?"),
        ({"reference": "nearest-face"}, "did you mean 'nearest_face'?"),
    ],
)
def test_a_mistyped_pipeline_option_says_did_you_mean(
    options: dict[str, str], suggestion: str
) -> None:
    with pytest.raises(ConfigurationError, match=suggestion.replace("?", r"\?")):
        Pipeline(Camera(f=721.5, c_x=609.6, c_y=172.9), **options)


def test_records_of_the_default_columns_or_all() -> None:
    """``to_records()`` gives the default columns, ``to_records("all")`` every column (the
    method's own included), a mistyped choice a suggestion."""
    pipe = Pipeline(
        Camera(f=721.5, c_x=609.6, c_y=172.9), method="flat", odometry="none",
        image_size=(1242, 375),
    )  # fmt: skip
    result = pipe.update(None, [(560, 190, 660, 260)])
    row = result.to_records()[0]
    assert list(row) == list(DEFAULT_RECORD_FIELDS) and row["status"] == "ok"
    full = result.to_records("all")[0]
    assert {"method", "theta_deg", "cut", "score"} <= set(full)
    assert full["distance_m"] == row["distance_m"]
    with pytest.raises(ConfigurationError, match=r"did you mean 'all'\?"):
        result.to_records("al")
