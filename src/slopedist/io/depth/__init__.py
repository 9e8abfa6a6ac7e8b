"""Dense depth maps for the depth-map baselines: files per frame and ONNX depth models.

Convention: a depth map is a float32 ``H×W`` array in metres along the camera's z axis, on the
pixel grid of the camera image (origin top-left, rows downwards); NaN where there is no value.
"""

from __future__ import annotations

from slopedist.io.depth.base import DepthSource
from slopedist.io.depth.files import (
    DEPTH_FILE_SUFFIXES,
    FileDepthSource,
    read_depth_file,
    read_kitti_depth_png,
    read_npy_depth,
    write_kitti_depth_png,
)
from slopedist.io.depth.onnx_model import (
    DepthOutputKind,
    OnnxDepthConfig,
    OnnxDepthModel,
    OnnxDepthSource,
)

__all__ = [
    "DEPTH_FILE_SUFFIXES",
    "DepthOutputKind",
    "DepthSource",
    "FileDepthSource",
    "OnnxDepthConfig",
    "OnnxDepthModel",
    "OnnxDepthSource",
    "read_depth_file",
    "read_kitti_depth_png",
    "read_npy_depth",
    "write_kitti_depth_png",
]
