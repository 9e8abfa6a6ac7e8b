"""Decoding the output tensors of exported 2D detectors into candidate boxes.

Every decoder returns :class:`Candidates`: boxes ``(left, top, right, bottom)`` in pixels of the
network input (the letterboxed image, origin top-left), one score in ``[0, 1]`` and one class
index (the model's, e.g. COCO's) per candidate, before any score threshold or NMS. The layouts:

- :attr:`OutputLayout.YOLOV8` — YOLOv8 / YOLO11 exports: one tensor ``[1, 4 + C, N]`` of
  ``cx, cy, w, h`` (input pixels) then ``C`` class scores (already sigmoid), no objectness;
- :attr:`OutputLayout.YOLOV5` — YOLOv5 / YOLOX exports: one tensor ``[1, N, 5 + C]`` of
  ``cx, cy, w, h, objectness`` then ``C`` class probabilities; score = objectness × class;
- :attr:`OutputLayout.END_TO_END` — exports with NMS inside (YOLOv10, ``yolo export nms=True``):
  ``[1, N, 6]`` of ``x1, y1, x2, y2, score, class`` (input pixels);
- :attr:`OutputLayout.DETR` — DETR-style pairs (RT-DETR, DETR): boxes ``[1, N, 4]`` as
  ``cx, cy, w, h`` normalised to ``[0, 1]`` of the input, and logits ``[1, N, C]`` (sigmoid per
  class, or softmax with a trailing no-object class, see :class:`LogitKind`);
- :attr:`OutputLayout.DETR_FUSED` — ultralytics' RT-DETR export: one tensor ``[1, N, 4 + C]`` of
  normalised ``cx, cy, w, h`` then ``C`` class scores in ``[0, 1]``. Its shape is that of the
  YOLOv5 layout, so it is never guessed: choose it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum

import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import ConfigurationError, DataMismatchError

FloatArray = NDArray[np.float64]


MAX_END_TO_END_DETECTIONS = 1000
"""Most rows an end-to-end output ``[1, N, 6]`` is taken to have (exports keep 100–300); more
rows of 6 are a one-class YOLOv5 output."""


class OutputLayout(str, Enum):
    """How a detector's outputs are laid out (see the module docstring)."""

    AUTO = "auto"
    """Choose from the output shapes (:func:`guess_layout`)."""
    YOLOV8 = "yolov8"
    YOLOV5 = "yolov5"
    END_TO_END = "end2end"
    DETR = "detr"
    DETR_FUSED = "detr-fused"


class LogitKind(str, Enum):
    """How DETR-style class logits become scores."""

    SIGMOID = "sigmoid"
    """One sigmoid per class (RT-DETR, Deformable DETR)."""
    SOFTMAX = "softmax"
    """Softmax over the classes, the last one being "no object" (the original DETR)."""


@dataclass(frozen=True)
class Candidates:
    """Decoded detections before thresholding and NMS.

    Attributes:
        boxes: ``(N, 4)`` float (left, top, right, bottom), pixels of the network input.
        scores: ``(N,)`` float in ``[0, 1]``.
        class_ids: ``(N,)`` int, the model's class index.
    """

    boxes: FloatArray
    scores: FloatArray
    class_ids: NDArray[np.int64]

    def select(self, mask: NDArray[np.bool_] | NDArray[np.int64]) -> Candidates:
        """Candidates where ``mask`` is true (or at the given indices)."""
        return Candidates(self.boxes[mask], self.scores[mask], self.class_ids[mask])


def _squeeze_batch(tensor: NDArray, layout: OutputLayout) -> NDArray:
    """A 3-D ``[1, a, b]`` or 2-D ``[a, b]`` output as the 2-D ``[a, b]`` array."""
    arr = np.asarray(tensor)
    if arr.ndim == 3 and arr.shape[0] == 1:
        arr = arr[0]
    if arr.ndim != 2:
        raise DataMismatchError(
            f"detector output of shape {np.shape(tensor)} does not fit the '{layout.value}' "
            "layout (expected one image, [1, a, b])"
        )
    return arr


def _centre_to_corners(cxcywh: NDArray) -> FloatArray:
    c = np.asarray(cxcywh, dtype=np.float64)
    half = c[:, 2:4] / 2.0
    return np.concatenate([c[:, 0:2] - half, c[:, 0:2] + half], axis=1)


def _best_class(scores: NDArray) -> tuple[FloatArray, NDArray[np.int64]]:
    """Per row of ``(N, C)`` scores: the best score and its class index."""
    if scores.shape[1] == 0:
        raise DataMismatchError("detector output has no class scores")
    cls = np.argmax(scores, axis=1)
    best = np.take_along_axis(scores, cls[:, None], axis=1)[:, 0]
    return best.astype(np.float64), cls.astype(np.int64)


def decode_yolov8(output: NDArray, min_score: float = 0.0) -> Candidates:
    """``[1, 4 + C, N]``: centre-size boxes then class scores (YOLOv8/YOLO11); also read
    candidates-first, ``[1, N, 4 + C]`` (more rows than columns: there are more candidates
    than classes).

    Candidates whose best class score is below ``min_score`` are dropped before the class search
    (the same result, less work on 8400 × 80 outputs).
    """
    arr = _squeeze_batch(output, OutputLayout.YOLOV8)
    if arr.shape[0] > arr.shape[1]:
        arr = arr.T
    if arr.shape[0] < 5:
        raise DataMismatchError(
            f"YOLOv8 output needs ≥ 5 rows (4 box + classes), got shape {np.shape(output)}"
        )
    cls_scores = arr[4:]
    keep = np.flatnonzero(cls_scores.max(axis=0) >= min_score)
    best, cls = _best_class(cls_scores[:, keep].T)
    return Candidates(_centre_to_corners(arr[:4, keep].T), best, cls)


def decode_yolov5(output: NDArray, min_score: float = 0.0) -> Candidates:
    """``[1, N, 5 + C]``: centre-size boxes, objectness, class probabilities (YOLOv5/YOLOX)."""
    arr = _squeeze_batch(output, OutputLayout.YOLOV5)
    if arr.shape[1] < 6:
        raise DataMismatchError(
            f"YOLOv5 output needs ≥ 6 columns (4 box, objectness, classes), "
            f"got shape {np.shape(output)}"
        )
    arr = arr[arr[:, 4] >= min_score]
    best, cls = _best_class(arr[:, 5:] * arr[:, 4:5])
    return Candidates(_centre_to_corners(arr[:, :4]), best, cls)


def decode_end_to_end(output: NDArray, min_score: float = 0.0) -> Candidates:
    """``[1, N, 6]``: ``x1, y1, x2, y2, score, class`` with NMS already done (YOLOv10); a row
    whose class is not a finite number names no class and is dropped."""
    arr = _squeeze_batch(output, OutputLayout.END_TO_END)
    if arr.shape[1] != 6:
        raise DataMismatchError(
            f"end-to-end output needs 6 columns (x1, y1, x2, y2, score, class), "
            f"got shape {np.shape(output)}"
        )
    arr = arr[(arr[:, 4] >= min_score) & np.isfinite(arr[:, 5])]
    return Candidates(
        arr[:, :4].astype(np.float64), arr[:, 4].astype(np.float64), arr[:, 5].astype(np.int64)
    )


def _sigmoid(x: NDArray) -> NDArray:
    return 0.5 * (1.0 + np.tanh(0.5 * np.asarray(x, dtype=np.float64)))


def decode_detr(
    boxes: NDArray,
    logits: NDArray,
    input_size: tuple[int, int],
    logit_kind: LogitKind = LogitKind.SIGMOID,
) -> Candidates:
    """DETR pairs: boxes ``[1, N, 4]`` normalised ``cx, cy, w, h`` and logits ``[1, N, C]``.

    ``input_size`` is the network input ``(width, height)`` in pixels, which the normalised
    boxes are scaled by.
    """
    b = _squeeze_batch(boxes, OutputLayout.DETR)
    z = _squeeze_batch(logits, OutputLayout.DETR).astype(np.float64)
    if b.shape[1] != 4 or b.shape[0] != z.shape[0]:
        raise DataMismatchError(
            f"DETR outputs must be boxes [1, N, 4] and logits [1, N, C], got "
            f"{np.shape(boxes)} and {np.shape(logits)}"
        )
    if logit_kind is LogitKind.SOFTMAX:
        e = np.exp(z - z.max(axis=1, keepdims=True))
        probs = (e / e.sum(axis=1, keepdims=True))[:, :-1]
    else:
        probs = _sigmoid(z)
    best, cls = _best_class(probs)
    w, h = input_size
    return Candidates(_centre_to_corners(b * np.array([w, h, w, h], float)), best, cls)


def decode_detr_fused(output: NDArray, input_size: tuple[int, int]) -> Candidates:
    """``[1, N, 4 + C]``: normalised ``cx, cy, w, h`` then class scores (ultralytics RT-DETR)."""
    arr = _squeeze_batch(output, OutputLayout.DETR_FUSED)
    if arr.shape[1] < 5:
        raise DataMismatchError(
            f"fused DETR output needs ≥ 5 columns (4 box + classes), got shape {np.shape(output)}"
        )
    best, cls = _best_class(arr[:, 4:])
    w, h = input_size
    return Candidates(_centre_to_corners(arr[:, :4] * np.array([w, h, w, h], float)), best, cls)


COCO_CLASS_COUNT = 80
"""Classes of the COCO-trained detectors: a ``[1, N, 84]`` output without class names is a
transposed YOLOv8 (4 + 80), not a YOLOv5 of 79 classes."""


def guess_layout(
    shapes: Sequence[Sequence[int | str | None]], n_classes: int | None = None
) -> OutputLayout:
    """The layout of a model from its output shapes (symbolic dimensions as str or None) and,
    when the model names them (ultralytics' ``names`` metadata), its number of classes.

    Two outputs, one ending in 4 → DETR; one output ``[1, a, 6]`` with ``a`` ≤
    :data:`MAX_END_TO_END_DETECTIONS` → end-to-end; one output
    ``[1, a, b]`` with ``a < b`` (classes × candidates) → YOLOv8, with ``a > b`` → YOLOv5,
    unless ``b`` is 4 + the classes (``n_classes``, else :data:`COCO_CLASS_COUNT`): a YOLOv8
    exported candidates-first, which :func:`decode_yolov8` reads too.
    """
    dims = [[d if isinstance(d, int) else None for d in s] for s in shapes]
    if len(dims) >= 2 and any(len(s) >= 2 and s[-1] == 4 for s in dims[:2]):
        return OutputLayout.DETR
    if len(dims) == 1 and len(dims[0]) in (2, 3):
        a, b = dims[0][-2], dims[0][-1]
        if b == 6 and (a is None or a <= MAX_END_TO_END_DETECTIONS):
            return OutputLayout.END_TO_END  # [1, 25200, 6] is a one-class YOLOv5
        if a is not None and b is not None and a != b:
            if a < b or b == 4 + (COCO_CLASS_COUNT if n_classes is None else n_classes):
                return OutputLayout.YOLOV8
            return OutputLayout.YOLOV5
        if a is not None and b is None:
            return OutputLayout.YOLOV8  # [1, 84, N] with a dynamic number of candidates
        if b is not None and a is None:
            return OutputLayout.YOLOV5
    raise ConfigurationError(
        f"cannot tell the detector's output layout from its output shapes {list(shapes)}; "
        f"choose one of {', '.join(v.value for v in OutputLayout if v is not OutputLayout.AUTO)}"
    )


def decode(
    layout: OutputLayout,
    outputs: Sequence[NDArray],
    input_size: tuple[int, int],
    min_score: float = 0.0,
    logit_kind: LogitKind = LogitKind.SIGMOID,
) -> Candidates:
    """Decode ``outputs`` (the model's outputs in order) laid out as ``layout`` (not AUTO)."""
    if layout is OutputLayout.YOLOV8:
        return decode_yolov8(outputs[0], min_score)
    if layout is OutputLayout.YOLOV5:
        return decode_yolov5(outputs[0], min_score)
    if layout is OutputLayout.END_TO_END:
        return decode_end_to_end(outputs[0], min_score)
    if layout is OutputLayout.DETR_FUSED:
        return decode_detr_fused(outputs[0], input_size)
    if layout is OutputLayout.DETR:
        if len(outputs) < 2:
            raise DataMismatchError("the DETR layout needs two outputs (boxes, logits)")
        first, second = outputs[0], outputs[1]
        if np.shape(first)[-1] != 4 and np.shape(second)[-1] == 4:
            first, second = second, first  # logits given first
        return decode_detr(first, second, input_size, logit_kind)
    raise ConfigurationError(f"layout '{layout.value}' must be resolved before decoding")
