"""2D vehicle boxes: the box table type, readers and writers of box files, adapters for
detections in memory, and an ONNX detector."""

from slopedist.io.detections.adapters import as_box_table, from_supervision, from_ultralytics
from slopedist.io.detections.boxes import BoxTable, box_problems, concat_boxes, iou_matrix
from slopedist.io.detections.convert import BoxFileOptions, BoxFormat, read_boxes, write_boxes
from slopedist.io.detections.layouts import OutputLayout
from slopedist.io.detections.onnx_detector import (
    COCO_VEHICLES,
    DetectionTiming,
    Detector,
    OnnxDetector,
    detect_frames,
)
from slopedist.io.detections.readers import (
    CSV_BOX_COLUMNS,
    read_box_csv,
    read_box_file,
    read_kitti_labels,
    read_pointrcnn,
    read_rrc,
)

__all__ = [
    "COCO_VEHICLES",
    "CSV_BOX_COLUMNS",
    "BoxFileOptions",
    "BoxFormat",
    "BoxTable",
    "DetectionTiming",
    "Detector",
    "OnnxDetector",
    "OutputLayout",
    "as_box_table",
    "box_problems",
    "concat_boxes",
    "detect_frames",
    "from_supervision",
    "from_ultralytics",
    "iou_matrix",
    "read_box_csv",
    "read_box_file",
    "read_boxes",
    "read_kitti_labels",
    "read_pointrcnn",
    "read_rrc",
    "write_boxes",
]
