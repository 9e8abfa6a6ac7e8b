"""A detector run over a video or image folder, boxes written as the slopedist box CSV.

The box CSV (:data:`~slopedist.io.detections.readers.CSV_BOX_COLUMNS`; track id −1, as detectors
give none) is written and flushed frame by frame, so that ``slopedist run FRAMES --boxes`` can
read it; the optional timing CSV has one row per frame: ``frame, frame_status, boxes,
preprocess_ms, inference_ms, postprocess_ms, detection_ms`` (empty times for frames that were
not readable).
"""

from __future__ import annotations

from collections.abc import Iterable
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.onnx_detector import DetectionTiming, Detector
from slopedist.io.detections.readers import CSV_BOX_COLUMNS
from slopedist.io.detections.writers import box_values
from slopedist.io.formatting import CsvStreamWriter
from slopedist.io.frames import Frame

TIMING_COLUMNS = (
    "frame",
    "frame_status",
    "boxes",
    "preprocess_ms",
    "inference_ms",
    "postprocess_ms",
    "detection_ms",
)


@dataclass(frozen=True)
class DetectionSummary:
    """What :func:`detect_video` did: frames seen and detected, boxes written, mean times (ms)."""

    frames: int
    detected_frames: int
    boxes: int
    mean_inference_ms: float
    mean_detection_ms: float


def _timing_row(frame: Frame, n: int, t: DetectionTiming | None) -> dict[str, object]:
    row: dict[str, object] = {"frame": frame.index, "frame_status": frame.status, "boxes": n}
    if t is not None:
        row.update(
            preprocess_ms=t.preprocess_s * 1e3,
            inference_ms=t.inference_s * 1e3,
            postprocess_ms=t.postprocess_s * 1e3,
            detection_ms=t.total_s * 1e3,
        )
    return row


def detect_video(
    detector: Detector,
    frames: Iterable[Frame],
    boxes_csv: str | Path,
    timing_csv: str | Path | None = None,
) -> DetectionSummary:
    """Run ``detector`` on every readable frame; write the boxes (and per-frame times)."""
    n_frames = n_detected = n_boxes = 0
    inference_ms = detection_ms = 0.0
    with ExitStack() as stack:
        writer = stack.enter_context(CsvStreamWriter.open(boxes_csv, CSV_BOX_COLUMNS))
        timing = (
            None
            if timing_csv is None
            else stack.enter_context(CsvStreamWriter.open(timing_csv, TIMING_COLUMNS))
        )
        for frame in frames:
            n_frames += 1
            table, t = BoxTable.empty(), None
            if frame.ok and frame.image is not None:
                table = detector.detect(frame.image, frame.index)
                t = detector.last_timing
                n_detected += 1
                inference_ms += t.inference_s * 1e3
                detection_ms += t.total_s * 1e3
            n_boxes += writer.write_values(box_values(table))
            if timing is not None:
                timing.write_row(_timing_row(frame, len(table), t))
    mean = 1.0 / n_detected if n_detected else float("nan")
    return DetectionSummary(n_frames, n_detected, n_boxes, inference_ms * mean, detection_ms * mean)
