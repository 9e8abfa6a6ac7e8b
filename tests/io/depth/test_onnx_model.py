"""ONNX depth models: a tiny model built here (a 1×1 convolution) run through onnxruntime."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.core.errors import (
    ConfigurationError,
    InputFileError,
    MissingInputError,
    OptionalDependencyError,
)
from slopedist.estimators import DepthMapEstimator, FrameInput
from slopedist.io.depth import DepthOutputKind, OnnxDepthConfig, OnnxDepthModel, OnnxDepthSource
from slopedist.io.detections.boxes import BoxTable

onnx = pytest.importorskip("onnx", reason="the 'onnx' package (test extra) builds the model")
pytest.importorskip("onnxruntime", reason="onnxruntime (extra 'onnx') runs the model")

WEIGHTS_RGB = (2.0, 3.0, 5.0)
BIAS = 1.0


def build_model(path: Path, in_h: int = 16, in_w: int = 24) -> Path:
    """``out = 2·x_0 + 3·x_1 + 5·x_2 + 1`` per pixel, input 1×3×h×w, output 1×1×h×w."""
    from onnx import TensorProto, helper, numpy_helper

    w = numpy_helper.from_array(np.array(WEIGHTS_RGB, np.float32).reshape(1, 3, 1, 1), "W")
    b = numpy_helper.from_array(np.array([BIAS], np.float32), "B")
    node = helper.make_node("Conv", ["image", "W", "B"], ["depth"])
    graph = helper.make_graph(
        [node],
        "tiny_depth",
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, in_h, in_w])],
        [helper.make_tensor_value_info("depth", TensorProto.FLOAT, [1, 1, in_h, in_w])],
        initializer=[w, b],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


def _uniform_bgr(b: int, g: int, r: int, h: int = 30, w: int = 50) -> np.ndarray:
    img = np.empty((h, w, 3), np.uint8)
    img[...] = (b, g, r)
    return img


def _config(path: Path, **kw: object) -> OnnxDepthConfig:
    return OnnxDepthConfig(path, input_width=24, input_height=16, **kw)  # type: ignore[arg-type]


def test_metric_output_rgb_order_normalisation_and_resize(tmp_path: Path) -> None:
    path = build_model(tmp_path / "m.onnx")
    img = _uniform_bgr(0, 51, 255)  # RGB = (1.0, 0.2, 0.0) after ÷255
    mean, std = (0.5, 0.0, 0.0), (0.5, 1.0, 2.0)
    model = OnnxDepthModel(_config(path, mean=mean, std=std, output_scale=2.0))
    depth = model.predict(img)
    x = (np.array([1.0, 0.2, 0.0]) - mean) / std
    expected = 2.0 * (np.dot(WEIGHTS_RGB, x) + BIAS)
    assert depth.shape == (30, 50) and depth.dtype == np.float32
    np.testing.assert_allclose(depth, expected, rtol=1e-5)
    bgr = OnnxDepthModel(_config(path, bgr_input=True)).predict(img)
    np.testing.assert_allclose(bgr, np.dot(WEIGHTS_RGB, [0.0, 0.2, 1.0]) + BIAS, rtol=1e-5)


def test_inverse_depth_output_and_non_positive_values(tmp_path: Path) -> None:
    path = build_model(tmp_path / "m.onnx")
    model = OnnxDepthModel(
        _config(path, output_kind=DepthOutputKind.INVERSE_DEPTH, output_scale=12.0)
    )
    img = _uniform_bgr(0, 0, 255)  # out = 2·1 + 1 = 3 → 12 / 3 = 4 m
    np.testing.assert_allclose(model.predict(img), 4.0, rtol=1e-5)
    negative = OnnxDepthModel(
        _config(path, mean=(10.0, 0.0, 0.0), output_kind=DepthOutputKind.INVERSE_DEPTH)
    )
    assert np.all(np.isnan(negative.predict(img)))  # output < 0 → no value


def test_source_feeds_the_depthmap_estimator(tmp_path: Path) -> None:
    path = build_model(tmp_path / "m.onnx")
    source = OnnxDepthSource(_config(path, output_scale=2.5))
    camera = Camera(700.0, 25.0, 15.0).with_image_size(50, 30)
    img = _uniform_bgr(0, 0, 255)  # out = 3 → 7.5 m
    frame = FrameInput(
        0,
        0.0,
        float("nan"),
        BoxTable.build([0, 0], [[10, 5, 20, 15], [60, 5, 70, 15]]),
        image=img,
        depth_m=source.depth(0, img),
    )
    out = DepthMapEstimator(camera).estimate(frame)
    assert out.distance_m[0] == pytest.approx(7.5, rel=1e-5)
    assert out.reason[1] == "outside_image"
    assert source.calls == 1 and source.seconds > 0
    with pytest.raises(MissingInputError, match="needs the frame's image"):
        source.depth(1, None)


def test_bad_model_files_and_options(tmp_path: Path) -> None:
    with pytest.raises(MissingInputError, match="not found"):
        OnnxDepthModel(_config(tmp_path / "none.onnx"))
    (tmp_path / "bad.onnx").write_bytes(b"this is not a protobuf")
    with pytest.raises(InputFileError, match=r"bad\.onnx.*cannot load"):
        OnnxDepthModel(_config(tmp_path / "bad.onnx"))
    with pytest.raises(ConfigurationError, match="input size"):
        OnnxDepthConfig(tmp_path / "m.onnx", 0, 16)
    with pytest.raises(ConfigurationError, match="std"):
        _config(tmp_path / "m.onnx", std=(1.0, 0.0, 1.0))


def test_input_size_disagreeing_with_the_model_is_a_clean_error(tmp_path: Path) -> None:
    path = build_model(tmp_path / "m.onnx", in_h=16, in_w=24)
    with pytest.raises(ConfigurationError, match=r"input is 24x16 .* --depth-input-size is 48x32"):
        OnnxDepthModel(OnnxDepthConfig(path, input_width=48, input_height=32))
    OnnxDepthModel(_config(path))  # the model's own size is fine


def test_missing_onnxruntime_is_an_optional_dependency_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = build_model(tmp_path / "m.onnx")
    monkeypatch.setitem(sys.modules, "onnxruntime", None)
    with pytest.raises(OptionalDependencyError, match=r"slopedist\[onnx\]"):
        OnnxDepthModel(_config(path))
