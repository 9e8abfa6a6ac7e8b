"""ONNX detectors: small test-built models that emit known tensors in each output layout."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from slopedist.core.errors import ConfigurationError, InputFileError, MissingInputError
from slopedist.io.detections.layouts import (
    Candidates,
    LogitKind,
    OutputLayout,
    decode_end_to_end,
    guess_layout,
)
from slopedist.io.detections.onnx_detector import (
    DetectionTiming,
    DetectorSettings,
    OnnxDetector,
    class_aware_nms,
    detect_frames,
    letterbox,
)

onnx = pytest.importorskip("onnx", reason="the 'onnx' package (test extra) builds the models")
pytest.importorskip("onnxruntime", reason="onnxruntime (extra 'onnx') runs the models")

IMAGE_W, IMAGE_H = 640, 360
IN_W, IN_H = 320, 320
N_CLASSES = 8
# 640×360 into 320×320: scale 0.5, 320×180 image, 70 px of padding above and below.
SCALE, PAD_Y = 0.5, 70

# Candidates in network-input pixels (left, top, right, bottom), model class, score.
CANDIDATES = [
    ((100.0, 150.0, 160.0, 190.0), 2, 0.90),  # car: kept
    ((102.0, 151.0, 161.0, 191.0), 2, 0.80),  # same car, worse: suppressed by NMS
    ((101.0, 150.0, 160.0, 190.0), 7, 0.70),  # truck on the car: other class, kept
    ((200.0, 120.0, 260.0, 170.0), 5, 0.60),  # bus: kept
    ((10.0, 100.0, 30.0, 140.0), 0, 0.95),  # person: not a vehicle, dropped
    ((250.0, 200.0, 300.0, 240.0), 2, 0.10),  # car below the score threshold
]
EXPECTED = [  # frame pixels: (x_in − 0) / 0.5, (y_in − 70) / 0.5
    ((200.0, 160.0, 320.0, 240.0), "Car", 0.90),
    ((202.0, 160.0, 320.0, 240.0), "Truck", 0.70),
    ((400.0, 100.0, 520.0, 200.0), "Bus", 0.60),
]


def _cxcywh(box: tuple[float, float, float, float]) -> list[float]:
    left, top, right, bottom = box
    return [(left + right) / 2, (top + bottom) / 2, right - left, bottom - top]


def yolov8_tensor(n_pad: int = 14) -> np.ndarray:
    rows = np.zeros((4 + N_CLASSES, len(CANDIDATES) + n_pad))
    for j, (box, cls, score) in enumerate(CANDIDATES):
        rows[:4, j] = _cxcywh(box)
        rows[4 + cls, j] = score
        rows[4 + (cls + 1) % N_CLASSES, j] = score / 3  # a weaker second class
    return rows[None]


def yolov5_tensor(n_pad: int = 14) -> np.ndarray:
    rows = np.zeros((len(CANDIDATES) + n_pad, 5 + N_CLASSES))
    for i, (box, cls, score) in enumerate(CANDIDATES):  # more candidates than columns
        rows[i, :4] = _cxcywh(box)
        rows[i, 4] = 0.5 + score / 2  # objectness
        rows[i, 5 + cls] = score / (0.5 + score / 2)  # objectness × class = score
    return rows[None]


def end_to_end_tensor() -> np.ndarray:
    kept = [c for i, c in enumerate(CANDIDATES) if i != 1]  # NMS was done inside the model
    rows = [[*box, score, cls] for box, cls, score in kept] + [[0, 0, 0, 0, 0, 0]] * 3
    return np.asarray(rows, float)[None]


def detr_tensors() -> tuple[np.ndarray, np.ndarray]:
    boxes = np.array([_cxcywh(b) for b, _, _ in CANDIDATES]) / [IN_W, IN_H, IN_W, IN_H]
    logits = np.full((len(CANDIDATES), N_CLASSES), -20.0)
    for i, (_, cls, score) in enumerate(CANDIDATES):
        logits[i, cls] = np.log(score / (1 - score))
    return boxes[None], logits[None]


def detr_fused_tensor() -> np.ndarray:
    boxes, logits = detr_tensors()
    rows = np.concatenate([boxes, 1 / (1 + np.exp(-logits))], axis=2)
    return np.concatenate([rows, np.zeros((1, 14, rows.shape[2]))], axis=1)  # 300 queries in life


LAYOUT_OUTPUTS = {
    OutputLayout.YOLOV8: lambda: {"output0": yolov8_tensor()},
    OutputLayout.YOLOV5: lambda: {"output": yolov5_tensor()},
    OutputLayout.END_TO_END: lambda: {"output0": end_to_end_tensor()},
    OutputLayout.DETR: lambda: dict(zip(("pred_boxes", "pred_logits"), detr_tensors())),
}


def _frame() -> np.ndarray:
    return np.full((IMAGE_H, IMAGE_W, 3), 90, np.uint8)


def _check(table, frame: int = 0) -> None:
    assert len(table) == len(EXPECTED)
    np.testing.assert_allclose(table.boxes, [b for b, _, _ in EXPECTED], atol=1e-3)
    assert list(table.cls) == [c for _, c, _ in EXPECTED]
    np.testing.assert_allclose(table.score, [s for _, _, s in EXPECTED], atol=1e-5)
    assert np.all(table.frame == frame) and np.all(table.track_id == -1)


@pytest.mark.parametrize("layout", list(LAYOUT_OUTPUTS))
def test_each_layout_detected_from_shapes_and_decoded_to_frame_pixels(
    tmp_path: Path, constant_model: Callable[..., Path], layout: OutputLayout
) -> None:
    path = constant_model(tmp_path / f"{layout.value}.onnx", LAYOUT_OUTPUTS[layout]())
    det = OnnxDetector(path, DetectorSettings(score_threshold=0.25, iou_threshold=0.5))
    assert det.layout is layout and det.input_size == (IN_W, IN_H)
    _check(det.detect(_frame(), frame=7), frame=7)
    t = det.last_timing
    assert t.inference_s > 0 and t.total_s == pytest.approx(
        t.preprocess_s + t.inference_s + t.postprocess_s
    )


def test_forced_layout_and_custom_class_map(
    tmp_path: Path, constant_model: Callable[..., Path]
) -> None:
    path = constant_model(tmp_path / "v8.onnx", LAYOUT_OUTPUTS[OutputLayout.YOLOV8]())
    det = OnnxDetector(path, DetectorSettings(class_map={0: "Pedestrian"}, layout="yolov8"))
    table = det.detect(_frame())
    assert list(table.cls) == ["Pedestrian"]
    np.testing.assert_allclose(table.boxes, [[20.0, 60.0, 60.0, 140.0]])
    with pytest.raises(Exception, match="end-to-end output needs 6 columns"):
        OnnxDetector(path, DetectorSettings(layout=OutputLayout.END_TO_END)).detect(_frame())


def test_fused_detr_layout_must_be_chosen(
    tmp_path: Path, constant_model: Callable[..., Path]
) -> None:
    path = constant_model(tmp_path / "rtdetr.onnx", {"output0": detr_fused_tensor()})
    assert OnnxDetector(path).layout is OutputLayout.YOLOV5  # same shape: not guessable
    det = OnnxDetector(path, DetectorSettings(layout="detr-fused"))
    _check(det.detect(_frame()))


def test_detr_softmax_with_no_object_class(
    tmp_path: Path, constant_model: Callable[..., Path]
) -> None:
    boxes, _ = detr_tensors()
    logits = np.full((len(CANDIDATES), N_CLASSES + 1), 0.0)
    for i, (_, cls, score) in enumerate(CANDIDATES):  # softmax over (cls, no-object) = score
        logits[i, cls] = 10.0
        logits[i, -1] = 10.0 - np.log(score / (1 - score))
        logits[i, :-1][np.arange(N_CLASSES) != cls] = -50.0
    path = constant_model(tmp_path / "detr.onnx", {"boxes": boxes, "logits": logits[None]})
    det = OnnxDetector(path, DetectorSettings(logit_kind=LogitKind.SOFTMAX))
    _check(det.detect(_frame()))


def test_dynamic_input_size_needs_an_explicit_size(
    tmp_path: Path, constant_model: Callable[..., Path]
) -> None:
    path = constant_model(tmp_path / "dyn.onnx", {"output0": yolov8_tensor()}, (1, 3, "h", "w"))
    with pytest.raises(InputFileError, match="dynamic"):
        OnnxDetector(path)
    _check(OnnxDetector(path, DetectorSettings(input_size=(IN_W, IN_H))).detect(_frame()))


@pytest.mark.parametrize("in_shape", [(1, 320, 320, 3), (1, 1, 320, 320), (3, 320, 320)])
def test_a_model_input_that_is_not_colour_nchw_is_refused(
    tmp_path: Path, constant_model: Callable[..., Path], in_shape: tuple[int, ...]
) -> None:
    """A channels-last, grey or unbatched input failed inside onnxruntime on the first frame
    (an internal error) instead of naming the model."""
    path = constant_model(tmp_path / "m.onnx", {"output0": yolov8_tensor()}, in_shape)
    with pytest.raises(InputFileError, match=r"expected N×3×H×W"):
        OnnxDetector(path).detect(_frame())
    with pytest.raises(InputFileError, match=r"expected N×3×H×W"):
        OnnxDetector(path, DetectorSettings(input_size=(IN_W, IN_H))).detect(_frame())


def test_an_input_size_other_than_the_models_fixed_one_is_refused(
    tmp_path: Path, constant_model: Callable[..., Path]
) -> None:
    path = constant_model(tmp_path / "m.onnx", {"output0": yolov8_tensor()}, (1, 3, IN_H, IN_W))
    with pytest.raises(ConfigurationError, match="input is 320×320 px, not the given input size"):
        OnnxDetector(path, DetectorSettings(input_size=(640, 640)))
    _check(OnnxDetector(path, DetectorSettings(input_size=(IN_W, IN_H))).detect(_frame()))


def test_letterbox_and_its_inverse() -> None:
    img = np.zeros((360, 640, 3), np.uint8)
    padded, box = letterbox(img, (320, 320))
    assert padded.shape == (320, 320, 3) and (box.pad_x, box.pad_y) == (0, PAD_Y)
    assert padded[0, 0, 0] == 114 and padded[160, 160, 0] == 0
    np.testing.assert_allclose(
        box.to_image(np.array([[0, 70, 320, 250]]), 640, 360), [[0, 0, 640, 360]]
    )
    _, tl = letterbox(img, (320, 320), centre=False)
    assert (tl.pad_x, tl.pad_y) == (0, 0)


def test_nms_is_class_aware_and_orders_by_score() -> None:
    cand = Candidates(
        np.array([[0, 0, 10, 10], [1, 0, 11, 10], [0, 0, 10, 10], [50, 50, 60, 60]], float),
        np.array([0.5, 0.9, 0.8, 0.3]),
        np.array([2, 2, 7, 2]),
    )
    assert class_aware_nms(cand, 0.5).tolist() == [1, 2, 3]
    assert class_aware_nms(cand, 0.95).tolist() == [1, 2, 0, 3]


def test_guess_layout_from_shapes() -> None:
    assert guess_layout([[1, 84, 8400]]) is OutputLayout.YOLOV8
    assert guess_layout([[1, 84, "anchors"]]) is OutputLayout.YOLOV8
    assert guess_layout([[1, 25200, 85]]) is OutputLayout.YOLOV5
    assert guess_layout([[1, 300, 6]]) is OutputLayout.END_TO_END
    assert guess_layout([[1, "n", 6]]) is OutputLayout.END_TO_END
    assert guess_layout([[1, 25200, 6]]) is OutputLayout.YOLOV5  # one-class YOLOv5
    assert guess_layout([[1, 5, 8400]]) is OutputLayout.YOLOV8  # one-class YOLOv8
    assert guess_layout([[1, 300, 4], [1, 300, 80]]) is OutputLayout.DETR
    # candidates first: 4 + classes columns is a YOLOv8, 5 + classes a YOLOv5
    assert guess_layout([[1, 8400, 84]]) is OutputLayout.YOLOV8  # COCO's 80, no names
    assert guess_layout([[1, 8400, 12]], n_classes=8) is OutputLayout.YOLOV8
    assert guess_layout([[1, 25200, 13]], n_classes=8) is OutputLayout.YOLOV5
    assert guess_layout([[1, 25200, 12]]) is OutputLayout.YOLOV5
    with pytest.raises(ConfigurationError, match="cannot tell"):
        guess_layout([[1, "a", "b"]])


def test_a_yolov8_exported_candidates_first_is_read_by_its_class_names(
    tmp_path: Path, constant_model: Callable[..., Path]
) -> None:
    """``[1, N, 4 + C]`` with the model's ``names`` metadata (as ultralytics writes it): read
    as YOLOv8 (it was taken for a YOLOv5 of C − 1 classes, objectness from class 0)."""
    names = str({k: f"class{k}" for k in range(N_CLASSES)})
    outputs = {"output0": yolov8_tensor().transpose(0, 2, 1)}
    path = constant_model(tmp_path / "v8t.onnx", outputs, metadata={"names": names})
    det = OnnxDetector(path, DetectorSettings(score_threshold=0.25, iou_threshold=0.5))
    assert det.layout is OutputLayout.YOLOV8
    _check(det.detect(_frame(), frame=3), frame=3)
    unnamed = constant_model(tmp_path / "v8t_unnamed.onnx", outputs)
    assert OnnxDetector(unnamed).layout is OutputLayout.YOLOV5  # 12 = 5 + 7 classes: as before


def test_errors_missing_model_and_bad_thresholds(tmp_path: Path) -> None:
    with pytest.raises(MissingInputError, match="not found"):
        OnnxDetector(tmp_path / "none.onnx")
    bad = tmp_path / "bad.onnx"
    bad.write_text("not a model")
    with pytest.raises(InputFileError, match="cannot load"):
        OnnxDetector(bad)
    with pytest.raises(ConfigurationError, match="threshold"):
        DetectorSettings(score_threshold=1.5)
    for scale in (float("nan"), 0.0, -1 / 255, float("inf")):  # no detection, silently
        with pytest.raises(ConfigurationError, match="pixel_scale"):
            DetectorSettings(pixel_scale=scale)
    with pytest.raises(ConfigurationError, match="threads"):
        DetectorSettings(threads=0)


def test_missing_onnxruntime_is_a_clear_error(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    import sys

    from slopedist.core.errors import OptionalDependencyError

    monkeypatch.setitem(sys.modules, "onnxruntime", None)
    with pytest.raises(OptionalDependencyError, match=r"slopedist\[onnx\]"):
        OnnxDetector(tmp_path / "m.onnx")


def test_detect_frames_concatenates_and_times(
    tmp_path: Path, constant_model: Callable[..., Path]
) -> None:
    path = constant_model(tmp_path / "v8.onnx", {"output0": yolov8_tensor()})
    table, timings = detect_frames(OnnxDetector(path), [(3, _frame()), (4, _frame())])
    assert table.frame.tolist() == [3, 3, 3, 4, 4, 4]
    assert len(timings) == 2 and all(isinstance(t, DetectionTiming) for t in timings)


@pytest.mark.parametrize(("bgr", "scale", "centre"), [(False, 1 / 255, True), (True, 1.0, False)])
def test_preprocess_equals_letterbox_then_blob(
    tmp_path: Path, constant_model: Callable[..., Path], bgr: bool, scale: float, centre: bool
) -> None:
    import cv2

    path = constant_model(tmp_path / "v8.onnx", {"output0": yolov8_tensor()})
    det = OnnxDetector(path, DetectorSettings(bgr_input=bgr, pixel_scale=scale, pad_centre=centre))
    rng = np.random.default_rng(0)
    for shape in [(360, 640, 3), (300, 200, 3), (360, 640, 3)]:  # the buffer is refilled
        img = rng.integers(0, 256, shape, dtype=np.uint8)
        blob, box = det.preprocess(img)
        padded, ref_box = letterbox(img, (IN_W, IN_H), centre)
        ref = cv2.dnn.blobFromImage(padded, scale, swapRB=not bgr)
        assert box == ref_box
        np.testing.assert_allclose(blob, ref, rtol=1e-6)


def test_an_end_to_end_row_without_a_finite_class_is_dropped() -> None:
    """Its class cast to an integer was garbage (and numpy warned about the cast on stderr)."""
    out = np.array(
        [[[10, 20, 50, 60, 0.9, 2], [1, 2, 3, 4, 0.8, np.nan], [5, 6, 7, 8, 0.7, np.inf]]]
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        found = decode_end_to_end(out)
    assert found.class_ids.tolist() == [2] and found.scores.tolist() == [0.9]
