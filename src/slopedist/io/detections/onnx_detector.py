"""A 2D vehicle detector given as an ONNX file, run with onnxruntime (optional extra ``onnx``).

Nothing is downloaded: the user exports their own weights (see ``docs/detectors.md``). Per frame:

1. **letterbox**: the BGR ``H×W×3`` frame is scaled by ``r = min(w_in/W, h_in/H)`` to the network
   input ``w_in × h_in`` keeping its aspect ratio, and padded (grey 114, centred, as ultralytics
   does; top-left with ``pad_centre=False``, as YOLOX does);
2. converted to ``1×3×h_in×w_in`` float32, RGB (``bgr_input`` keeps BGR), times ``pixel_scale``
   (1/255 by default; YOLOX wants 1);
3. the outputs are decoded by :mod:`slopedist.io.detections.layouts` (layout chosen from the output
   shapes, or forced), thresholded by score, reduced by class-aware NMS (``cv2.dnn``, IoU), the
   letterbox is undone (boxes in pixels of the original frame, clipped to it), and the model's
   class indices are mapped to slopedist class names (:data:`COCO_VEHICLES` by default; classes
   not in the map are dropped).
"""

from __future__ import annotations

import ast
import math
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

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
from slopedist.io.detections.boxes import BoxTable, concat_boxes
from slopedist.io.detections.layouts import (
    Candidates,
    LogitKind,
    OutputLayout,
    decode,
    guess_layout,
)

COCO_VEHICLES: dict[int, str] = {2: "Car", 3: "Motorcycle", 5: "Bus", 7: "Truck"}
"""Default class map: COCO class index (as in YOLO/RT-DETR exports) → slopedist class name.
``Bus`` uses the ``Truck`` size prior of the ``ours`` estimator."""

LETTERBOX_FILL = 114
"""Grey level of the letterbox padding (ultralytics' and YOLOX's value)."""


@dataclass(frozen=True)
class DetectionTiming:
    """Wall-clock seconds spent on one frame: pre-processing, inference, post-processing."""

    preprocess_s: float = 0.0
    inference_s: float = 0.0
    postprocess_s: float = 0.0

    @property
    def total_s(self) -> float:
        """All three, seconds."""
        return self.preprocess_s + self.inference_s + self.postprocess_s


class Detector(Protocol):
    """Anything that finds vehicles in one frame.

    ``detect`` returns the frame's boxes (pixels of ``image_bgr``; ``frame`` fills the table's
    frame column); ``last_timing`` is the time the last call took.
    """

    last_timing: DetectionTiming

    def detect(self, image_bgr: NDArray[np.uint8], frame: int = 0) -> BoxTable: ...


@dataclass(frozen=True)
class Letterbox:
    """How a frame was fitted into the network input: ``x_in = x · sx + pad_x`` (pixels)."""

    sx: float
    sy: float
    pad_x: int
    pad_y: int

    def to_image(self, boxes: NDArray, width: int, height: int) -> NDArray[np.float64]:
        """Boxes in network-input pixels → pixels of the ``width × height`` frame, clipped."""
        b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        offset = np.array([self.pad_x, self.pad_y, self.pad_x, self.pad_y], float)
        out = (b - offset) / np.array([self.sx, self.sy, self.sx, self.sy])
        np.clip(out[:, 0::2], 0.0, float(width), out=out[:, 0::2])
        np.clip(out[:, 1::2], 0.0, float(height), out=out[:, 1::2])
        return out


def fit_letterbox(
    image_size: tuple[int, int], size: tuple[int, int], centre: bool = True
) -> tuple[tuple[int, int], Letterbox]:
    """How an image of ``image_size = (width, height)`` fits into ``size``: its scaled size
    (``r = min(w_in/W, h_in/H)``, aspect kept) and the :class:`Letterbox` that places it."""
    w, h = image_size
    in_w, in_h = size
    r = min(in_w / w, in_h / h)
    new_w, new_h = max(1, round(w * r)), max(1, round(h * r))
    dw, dh = (in_w - new_w) / 2.0, (in_h - new_h) / 2.0
    left, top = (round(dw - 0.1), round(dh - 0.1)) if centre else (0, 0)
    return (new_w, new_h), Letterbox(new_w / w, new_h / h, left, top)


def letterbox(
    image: NDArray[np.uint8], size: tuple[int, int], centre: bool = True
) -> tuple[NDArray[np.uint8], Letterbox]:
    """``image`` scaled into ``size = (width, height)`` keeping its aspect ratio, padded."""
    h, w = image.shape[:2]
    (new_w, new_h), box = fit_letterbox((w, h), size, centre)
    resized = image if (new_w, new_h) == (w, h) else cv2.resize(image, (new_w, new_h))
    right, bottom = size[0] - new_w - box.pad_x, size[1] - new_h - box.pad_y
    padded = cv2.copyMakeBorder(
        resized,
        box.pad_y,
        bottom,
        box.pad_x,
        right,
        cv2.BORDER_CONSTANT,
        value=(LETTERBOX_FILL,) * 3,
    )
    return np.asarray(padded, np.uint8), box


def class_aware_nms(cand: Candidates, iou_threshold: float) -> NDArray[np.int64]:
    """Indices of ``cand`` kept by per-class NMS (IoU > ``iou_threshold`` suppresses), best
    score first."""
    if len(cand.scores) == 0:
        return np.zeros(0, np.int64)
    xywh = np.concatenate([cand.boxes[:, :2], cand.boxes[:, 2:] - cand.boxes[:, :2]], axis=1)
    keep = cv2.dnn.NMSBoxesBatched(
        xywh.tolist(), cand.scores.tolist(), cand.class_ids.tolist(), 0.0, float(iou_threshold)
    )
    idx = np.asarray(keep, dtype=np.int64).reshape(-1)
    return idx[np.argsort(-cand.scores[idx], kind="stable")]


@dataclass(frozen=True)
class DetectorSettings:
    """How an :class:`OnnxDetector` reads its model and filters its boxes.

    Attributes:
        score_threshold: minimum score in ``[0, 1]`` of a kept box.
        iou_threshold: NMS suppresses a box overlapping a better one of its class above this IoU.
        class_map: model class index → slopedist class name; others are dropped (None: COCO
            vehicles).
        layout: :class:`OutputLayout` (AUTO: from the output shapes).
        input_size: network input ``(width, height)``, pixels (None: from the model's input).
        bgr_input, pixel_scale, pad_centre: pre-processing (see the module docstring).
        logit_kind: DETR logits as sigmoid or softmax.
        max_detections: keep at most this many boxes per frame (best first).
        threads: onnxruntime intra-op threads (None = its default).

    Raises:
        ConfigurationError: thresholds outside their ranges, fewer than one detection, a
            pixel scale that is not a finite positive number or fewer than one thread.
    """

    score_threshold: float = 0.25
    iou_threshold: float = 0.45
    class_map: Mapping[int, str] | None = None
    layout: OutputLayout | str = OutputLayout.AUTO
    input_size: tuple[int, int] | None = None
    bgr_input: bool = False
    pixel_scale: float = 1.0 / 255.0
    pad_centre: bool = True
    logit_kind: LogitKind | str = LogitKind.SIGMOID
    max_detections: int = 300
    threads: int | None = None

    def __post_init__(self) -> None:
        if not 0.0 <= self.score_threshold <= 1.0 or not 0.0 < self.iou_threshold <= 1.0:
            raise ConfigurationError(
                f"detector score threshold must be in [0, 1] and IoU threshold in (0, 1], got "
                f"{self.score_threshold} and {self.iou_threshold}"
            )
        if self.max_detections < 1:
            raise ConfigurationError(f"max_detections must be ≥ 1, got {self.max_detections}")
        if not (math.isfinite(self.pixel_scale) and self.pixel_scale > 0.0):
            raise ConfigurationError(
                f"pixel_scale must be a finite number > 0, got {self.pixel_scale}"
            )
        if self.threads is not None and self.threads < 1:
            raise ConfigurationError(f"threads must be ≥ 1, got {self.threads}")


class OnnxDetector:
    """An exported 2D detector (YOLOv5/v8/v10/11, YOLOX, RT-DETR, ...) as a :class:`Detector`.

    Args:
        model_path: the ``.onnx`` file.
        settings: thresholds, class map, layout and pre-processing (defaults: COCO vehicles,
            score 0.25, IoU 0.45, layout from the output shapes).

    Raises (at construction):
        OptionalDependencyError: onnxruntime is not installed.
        MissingInputError: the model file does not exist.
        InputFileError: onnxruntime cannot load it, its input is not ``N×3×H×W``, or its input
            size is dynamic and ``input_size`` is not given.
        ConfigurationError: a layout that the outputs cannot have, or an ``input_size``
            other than the model's fixed one.
    """

    def __init__(self, model_path: str | Path, settings: DetectorSettings | None = None) -> None:
        cfg = settings or DetectorSettings()
        self.model_path = Path(model_path)
        self.settings = cfg
        self.score_threshold = cfg.score_threshold
        self.iou_threshold = cfg.iou_threshold
        self.class_map = dict(COCO_VEHICLES if cfg.class_map is None else cfg.class_map)
        self.bgr_input, self.pixel_scale, self.pad_centre = (
            cfg.bgr_input,
            cfg.pixel_scale,
            cfg.pad_centre,
        )
        self.logit_kind = LogitKind(cfg.logit_kind)
        self.max_detections = cfg.max_detections
        threads, input_size, layout = cfg.threads, cfg.input_size, cfg.layout
        self.session = self._load(threads)
        inp = self.session.get_inputs()[0]
        self.input_name = inp.name
        self._check_input(inp.shape, input_size)
        self.input_size = input_size or self._model_input_size(inp.shape)
        self.output_names = [o.name for o in self.session.get_outputs()]
        requested = OutputLayout(layout)
        self.layout = (
            guess_layout([o.shape for o in self.session.get_outputs()], self._named_class_count())
            if requested is OutputLayout.AUTO
            else requested
        )
        self.last_timing = DetectionTiming()
        self._buffer: NDArray[np.float32] | None = None
        self._buffer_box: Letterbox | None = None

    def _named_class_count(self) -> int | None:
        """How many classes the model names in its metadata (ultralytics' ``names``, a dict
        or list literal), or None."""
        try:
            names = self.session.get_modelmeta().custom_metadata_map.get("names")
            parsed = ast.literal_eval(names) if isinstance(names, str) else None
        except (ValueError, SyntaxError, AttributeError, MemoryError, RecursionError):
            return None
        return len(parsed) if isinstance(parsed, (dict, list)) and parsed else None

    def _load(self, threads: int | None) -> Any:
        ort = import_optional("onnxruntime", "onnx", "running an ONNX detector")
        if not self.model_path.is_file():
            raise MissingInputError(f"ONNX detector model not found: {self.model_path}")
        options = ort.SessionOptions()
        if threads is not None:
            options.intra_op_num_threads = int(threads)
        try:
            return ort.InferenceSession(
                str(self.model_path), sess_options=options, providers=["CPUExecutionProvider"]
            )
        except Exception as exc:  # onnxruntime raises its own exception types
            raise InputFileError(
                self.model_path, f"onnxruntime cannot load the model: {exc}"
            ) from None

    def _check_input(self, shape: list[Any], input_size: tuple[int, int] | None) -> None:
        """Refuse a model input that is not ``N×3×H×W`` (channels-last ``N×H×W×3``, grey
        ``N×1×H×W``) or whose fixed size is not ``input_size`` (``(width, height)``, pixels):
        onnxruntime would refuse every frame's input."""
        channels = shape[1] if len(shape) == 4 else None
        if len(shape) != 4 or (isinstance(channels, int) and channels != 3):
            raise InputFileError(
                self.model_path, f"model input has shape {shape}; expected N×3×H×W"
            )
        if input_size is None:
            return
        width, height = input_size
        if any(isinstance(d, int) and d != n for d, n in zip(shape[2:], (height, width))):
            raise ConfigurationError(
                f"{self.model_path}: the model's input is {shape[3]}×{shape[2]} px, not the "
                f"given input size {width}×{height}"
            )

    def _model_input_size(self, shape: list[Any]) -> tuple[int, int]:
        h, w = shape[2], shape[3]
        if not (isinstance(h, int) and isinstance(w, int) and h > 0 and w > 0):
            raise InputFileError(
                self.model_path,
                f"model input size is dynamic ({shape}); give the input size "
                "(e.g. --detector-input-size 640x640)",
            )
        return int(w), int(h)

    def preprocess(self, image_bgr: NDArray[np.uint8]) -> tuple[NDArray[np.float32], Letterbox]:
        """The network input ``1×3×h×w`` float32 of a BGR frame, and its letterbox.

        The input is one buffer reused by every call (only the image region is rewritten), so
        it is valid until the next call.
        """
        frame = np.asarray(image_bgr)
        if frame.ndim == 2:
            frame = np.asarray(cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR))
        if frame.ndim != 3 or frame.shape[2] != 3:
            raise DataMismatchError(f"detector needs an H×W×3 colour frame, got {frame.shape}")
        h, w = frame.shape[:2]
        (new_w, new_h), box = fit_letterbox((w, h), self.input_size, self.pad_centre)
        resized = frame if (new_w, new_h) == (w, h) else cv2.resize(frame, (new_w, new_h))
        blob = self._input_buffer(box)
        region = blob[0, :, box.pad_y : box.pad_y + new_h, box.pad_x : box.pad_x + new_w]
        scale = np.float32(self.pixel_scale)
        for channel, source in enumerate((0, 1, 2) if self.bgr_input else (2, 1, 0)):
            np.multiply(resized[:, :, source], scale, out=region[channel], casting="unsafe")
        return blob, box

    def _input_buffer(self, box: Letterbox) -> NDArray[np.float32]:
        """The reused input buffer, its padding filled for this letterbox geometry."""
        if self._buffer is None or self._buffer_box != box:
            w, h = self.input_size
            self._buffer = np.full((1, 3, h, w), LETTERBOX_FILL * self.pixel_scale, np.float32)
            self._buffer_box = box
        return self._buffer

    def postprocess(
        self, outputs: list[NDArray], box: Letterbox, width: int, height: int, frame: int
    ) -> BoxTable:
        """Decoded, thresholded, NMS-reduced, class-mapped boxes in frame pixels."""
        cand = decode(self.layout, outputs, self.input_size, self.score_threshold, self.logit_kind)
        ids = np.array(sorted(self.class_map), dtype=np.int64)
        cand = cand.select((cand.scores >= self.score_threshold) & np.isin(cand.class_ids, ids))
        if self.layout is not OutputLayout.END_TO_END:
            cand = cand.select(class_aware_nms(cand, self.iou_threshold))
        else:
            cand = cand.select(np.argsort(-cand.scores, kind="stable"))
        cand = cand.select(np.arange(min(len(cand.scores), self.max_detections)))
        names = np.array([self.class_map[int(c)] for c in cand.class_ids], dtype=object)
        return BoxTable.build(
            np.full(len(names), frame, np.int64),
            box.to_image(cand.boxes, width, height),
            None,
            cand.scores,
            names,
        )

    def detect(self, image_bgr: NDArray[np.uint8], frame: int = 0) -> BoxTable:
        """Vehicles in one BGR frame; sets :attr:`last_timing`."""
        t0 = time.perf_counter()
        blob, box = self.preprocess(image_bgr)
        t1 = time.perf_counter()
        outputs = self.session.run(self.output_names, {self.input_name: blob})
        t2 = time.perf_counter()
        h, w = np.shape(image_bgr)[:2]
        table = self.postprocess([np.asarray(o) for o in outputs], box, w, h, frame)
        self.last_timing = DetectionTiming(t1 - t0, t2 - t1, time.perf_counter() - t2)
        return table


def detect_frames(
    detector: Detector, frames: Iterable[tuple[int, NDArray[np.uint8]]]
) -> tuple[BoxTable, list[DetectionTiming]]:
    """Run ``detector`` on ``(frame index, BGR image)`` pairs: all boxes and per-frame timing."""
    tables, timings = [], []
    for index, image in frames:
        tables.append(detector.detect(image, index))
        timings.append(detector.last_timing)
    return concat_boxes(tables), timings
