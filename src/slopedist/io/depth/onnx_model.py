"""A monocular depth network given as an ONNX file, run with onnxruntime (optional extra
``onnx``). Nothing is downloaded: the user supplies the model file and how to feed it.

Pre-processing (the user states each step, matching how the model was trained):

1. the BGR ``H×W×3`` uint8 frame is converted to RGB (unless ``bgr_input``),
2. resized to ``input_width × input_height`` (bilinear),
3. scaled to ``[0, 1]`` (÷255), then normalised per channel: ``(x − mean) / std``,
4. laid out as ``1×3×H×W`` float32 (NCHW) and fed to the model's first input.

Post-processing: the first output, of shape ``1×1×h×w``, ``1×h×w`` or ``h×w``, is resized to the
frame size (bilinear) and turned into metres according to ``output_kind``:

- ``depth``: ``depth_m = output_scale × output`` (metric depth, or relative depth to be
  median-scaled by the estimator),
- ``inverse_depth`` (disparity-like outputs, e.g. Monodepth2's or MiDaS'):
  ``depth_m = output_scale / output``.

Outputs that are ≤ 0 or non-finite become NaN (no value).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import (
    ConfigurationError,
    DataMismatchError,
    InputFileError,
    MissingInputError,
    import_optional,
)
from slopedist.io.depth.base import DepthSource


class DepthOutputKind(str, Enum):
    """What a depth network's output means."""

    DEPTH = "depth"
    """Depth along z: ``metres = output_scale × output``."""
    INVERSE_DEPTH = "inverse_depth"
    """Inverse depth / disparity: ``metres = output_scale / output``."""


@dataclass(frozen=True)
class OnnxDepthConfig:
    """How to run an ONNX depth model (see the module docstring for each step).

    Attributes:
        model_path: the ``.onnx`` file.
        input_width, input_height: network input size, pixels.
        mean, std: per-channel normalisation in RGB order (or BGR with ``bgr_input``), applied
            to values in ``[0, 1]``; ``(0, 0, 0)`` / ``(1, 1, 1)`` = none (e.g. Monodepth2),
            ImageNet = ``(0.485, 0.456, 0.406)`` / ``(0.229, 0.224, 0.225)``.
        output_kind: :class:`DepthOutputKind`.
        output_scale: factor of the output (``depth``) or numerator (``inverse_depth``).
        bgr_input: feed channels in BGR order instead of RGB.
        threads: onnxruntime intra-op threads (None = its default).
    """

    model_path: Path
    input_width: int
    input_height: int
    mean: tuple[float, float, float] = (0.0, 0.0, 0.0)
    std: tuple[float, float, float] = (1.0, 1.0, 1.0)
    output_kind: DepthOutputKind = DepthOutputKind.DEPTH
    output_scale: float = 1.0
    bgr_input: bool = False
    threads: int | None = None

    def __post_init__(self) -> None:
        if self.input_width <= 0 or self.input_height <= 0:
            raise ConfigurationError(
                f"ONNX depth model input size must be positive, got "
                f"{self.input_width}×{self.input_height}"
            )
        if len(self.mean) != 3 or len(self.std) != 3:
            raise ConfigurationError("ONNX depth model mean and std need three values each")
        if any(not np.isfinite(s) or s == 0 for s in self.std):
            raise ConfigurationError(
                f"ONNX depth model std must be finite and non-zero: {self.std}"
            )
        if not np.isfinite(self.output_scale) or self.output_scale <= 0:
            raise ConfigurationError(
                f"ONNX depth model output scale must be > 0, got {self.output_scale}"
            )


def _check_input_size(path: Path, shape: list[Any], height: int, width: int) -> None:
    """A model with a fixed input size must be fed that size (``--depth-input-size``)."""
    fixed_h, fixed_w = shape[2], shape[3]
    if (
        isinstance(fixed_h, int)
        and isinstance(fixed_w, int)
        and (fixed_h, fixed_w)
        != (
            height,
            width,
        )
    ):
        raise ConfigurationError(
            f"{path}: the model's input is {fixed_w}x{fixed_h} pixels but --depth-input-size "
            f"is {width}x{height}; give --depth-input-size {fixed_w}x{fixed_h}"
        )


class OnnxDepthModel:
    """An ONNX depth network: :meth:`predict` turns a BGR frame into metres.

    Raises (at construction):
        OptionalDependencyError: onnxruntime is not installed.
        MissingInputError: the model file does not exist.
        InputFileError: onnxruntime cannot load it, or its first input is not 4-D.
        ConfigurationError: the model's fixed input size differs from the configured one.
    """

    def __init__(self, config: OnnxDepthConfig) -> None:
        ort = import_optional("onnxruntime", "onnx", "running an ONNX depth model")
        self.config = config
        path = Path(config.model_path)
        if not path.is_file():
            raise MissingInputError(f"ONNX depth model not found: {path}")
        options = ort.SessionOptions()
        if config.threads is not None:
            options.intra_op_num_threads = int(config.threads)
        try:
            self.session = ort.InferenceSession(
                str(path), sess_options=options, providers=["CPUExecutionProvider"]
            )
        except Exception as exc:  # onnxruntime raises its own exception types
            raise InputFileError(path, f"onnxruntime cannot load the model: {exc}") from None
        inp = self.session.get_inputs()[0]
        if len(inp.shape) != 4:
            raise InputFileError(
                path, f"model input '{inp.name}' has shape {inp.shape}; expected N×3×H×W"
            )
        _check_input_size(path, inp.shape, config.input_height, config.input_width)
        self.input_name = inp.name
        self.output_name = self.session.get_outputs()[0].name
        self._mean = np.asarray(config.mean, dtype=np.float32).reshape(3, 1, 1)
        self._std = np.asarray(config.std, dtype=np.float32).reshape(3, 1, 1)

    def preprocess(self, image_bgr: NDArray[np.uint8]) -> NDArray[np.float32]:
        """The network input ``1×3×h×w`` float32 of a BGR ``H×W×3`` uint8 frame."""
        frame = np.asarray(image_bgr)
        if frame.ndim == 2:
            frame = np.asarray(cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR))
        if frame.ndim != 3 or frame.shape[2] != 3:
            raise DataMismatchError(
                f"depth model needs an H×W×3 colour frame, got shape {frame.shape}"
            )
        cfg = self.config
        img = frame if cfg.bgr_input else cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
        img = cv2.resize(img, (cfg.input_width, cfg.input_height), interpolation=cv2.INTER_LINEAR)
        x = img.astype(np.float32).transpose(2, 0, 1) / np.float32(255.0)
        x = (x - self._mean) / self._std
        return np.ascontiguousarray(x[None], dtype=np.float32)

    def predict(self, image_bgr: NDArray[np.uint8]) -> NDArray[np.float32]:
        """Depth in metres on the frame's pixel grid (float32 ``H×W``, NaN = no value)."""
        try:
            out = self.session.run(
                [self.output_name], {self.input_name: self.preprocess(image_bgr)}
            )
        except Exception as exc:  # onnxruntime raises its own exception types
            raise InputFileError(
                self.config.model_path, f"onnxruntime cannot run the model: {exc}"
            ) from None
        raw = np.asarray(out[0], dtype=np.float32)
        while raw.ndim > 2 and raw.shape[0] == 1:
            raw = raw[0]
        if raw.ndim != 2:
            raise DataMismatchError(
                f"{self.config.model_path}: output '{self.output_name}' has shape "
                f"{np.asarray(out[0]).shape}; expected 1×1×h×w, 1×h×w or h×w"
            )
        h, w = image_bgr.shape[:2]
        raw = np.asarray(cv2.resize(raw, (w, h), interpolation=cv2.INTER_LINEAR), np.float32)
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.config.output_kind is DepthOutputKind.INVERSE_DEPTH:
                depth = np.float32(self.config.output_scale) / raw
            else:
                depth = np.float32(self.config.output_scale) * raw
            depth[~(np.isfinite(depth) & (raw > 0))] = np.nan
        return depth.astype(np.float32, copy=False)


class OnnxDepthSource(DepthSource):
    """Depth maps computed from each frame's pixels by an :class:`OnnxDepthModel`."""

    kind = "onnx inference"

    def __init__(self, model: OnnxDepthModel | OnnxDepthConfig) -> None:
        super().__init__()
        self.model = model if isinstance(model, OnnxDepthModel) else OnnxDepthModel(model)

    def _depth(
        self, frame_index: int, image: NDArray[np.uint8] | None
    ) -> NDArray[np.float32] | None:
        if image is None:
            raise MissingInputError(
                f"frame {frame_index}: the ONNX depth model needs the frame's image, "
                "and none was given"
            )
        return self.model.predict(image)
