"""2D vehicle boxes: the box table type and readers for box files."""

from slopedist.detections.boxes import BoxTable, box_problems, concat_boxes, iou_matrix
from slopedist.detections.readers import (
    CSV_BOX_COLUMNS,
    read_box_csv,
    read_box_file,
    read_kitti_labels,
    read_pointrcnn,
)

__all__ = [
    "CSV_BOX_COLUMNS",
    "BoxTable",
    "box_problems",
    "concat_boxes",
    "iou_matrix",
    "read_box_csv",
    "read_box_file",
    "read_kitti_labels",
    "read_pointrcnn",
]
