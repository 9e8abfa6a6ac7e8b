"""slopedist: monocular inter-vehicle distance estimation with ego and target road gradients.

Implements Back et al., "Improved and efficient inter-vehicle distance estimation using road
gradients of both ego and target vehicles", its baselines, and improvements on top of it.

The names a user needs are here (:data:`__all__`; docs/python.md shows them end to end)::

    import slopedist

    pipe = slopedist.Pipeline("calib.txt")         # a calibration file or a slopedist.Camera
    result = pipe.update(image, boxes)             # BGR image, boxes in any detector's form
    for target in result.targets:                  # one per box: distance_m, status, ...
        print(target.track_id, target.distance_m, target.status)

Everything under the subpackages is internal. The names are imported when first used, so
``import slopedist`` stays fast.
"""

__version__ = "0.2.0"

_SOURCES: dict[str, tuple[str, str]] = {
    "Pipeline": ("slopedist.streaming.pipeline", "Pipeline"),
    "FrameResult": ("slopedist.streaming.pipeline", "FrameResult"),
    "Target": ("slopedist.streaming.pipeline", "Target"),
    "FinishResult": ("slopedist.streaming.pipeline", "FinishResult"),
    "Camera": ("slopedist.core.camera", "Camera"),
    "read_calibration": ("slopedist.io.calibration", "read_calibration"),
    "CameraCalibration": ("slopedist.io.calibration", "CameraCalibration"),
    "BoxTable": ("slopedist.io.detections.boxes", "BoxTable"),
    "read_boxes": ("slopedist.io.detections.readers", "read_box_file"),
    "as_box_table": ("slopedist.io.detections.adapters", "as_box_table"),
    "open_frames": ("slopedist.io.frames", "open_frames"),
    "Frame": ("slopedist.io.frames", "Frame"),
    "Method": ("slopedist.estimators", "Method"),
    "EstimatorConfig": ("slopedist.estimators", "EstimatorConfig"),
    "EstimateStatus": ("slopedist.estimators.base", "EstimateStatus"),
    "MissingReason": ("slopedist.estimators.base", "MissingReason"),
    "ReferencePoint": ("slopedist.estimators.base", "ReferencePoint"),
    "SelfCalibration": ("slopedist.estimators.base", "SelfCalibration"),
    "SlopedistError": ("slopedist.core.errors", "SlopedistError"),
    "RunOptions": ("slopedist.streaming.setup", "RunOptions"),
    "run_to_folder": ("slopedist.streaming.setup", "run_to_folder"),
    "RunResult": ("slopedist.streaming.config", "RunResult"),
    "distance_metrics": ("slopedist.evaluation.metrics", "distance_metrics"),
    "match_by_frame": ("slopedist.evaluation.metrics", "match_by_frame"),
    "KittiEvalConfig": ("slopedist.evaluation.kitti", "KittiEvalConfig"),
    "evaluate_kitti_tracking": ("slopedist.evaluation.kitti", "evaluate_kitti_tracking"),
}
"""Public name → (module, name there): imported on first use (:func:`__getattr__`)."""

__all__ = [
    "BoxTable",
    "Camera",
    "CameraCalibration",
    "EstimateStatus",
    "EstimatorConfig",
    "FinishResult",
    "Frame",
    "FrameResult",
    "KittiEvalConfig",
    "Method",
    "MissingReason",
    "Pipeline",
    "ReferencePoint",
    "RunOptions",
    "RunResult",
    "SelfCalibration",
    "SlopedistError",
    "Target",
    "as_box_table",
    "distance_metrics",
    "evaluate_kitti_tracking",
    "match_by_frame",
    "open_frames",
    "read_boxes",
    "read_calibration",
    "run_to_folder",
]
"""The public names (those of :data:`_SOURCES`)."""


TYPE_CHECKING = False
"""True for type checkers only (the ``typing`` module is not imported: it costs more than the
rest of ``import slopedist``)."""


def __getattr__(name: str) -> object:
    """The public name ``name``, imported from its module on first use."""
    if name not in _SOURCES:
        raise AttributeError(f"module 'slopedist' has no attribute {name!r}")
    from importlib import import_module

    module, attribute = _SOURCES[name]
    value = getattr(import_module(module), attribute)
    globals()[name] = value  # later uses skip this function
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])


if TYPE_CHECKING:  # what the names are, for type checkers and editors
    from slopedist.core.camera import Camera
    from slopedist.core.errors import SlopedistError
    from slopedist.estimators import EstimatorConfig, Method
    from slopedist.estimators.base import (
        EstimateStatus,
        MissingReason,
        ReferencePoint,
        SelfCalibration,
    )
    from slopedist.evaluation.kitti import KittiEvalConfig, evaluate_kitti_tracking
    from slopedist.evaluation.metrics import distance_metrics, match_by_frame
    from slopedist.io.calibration import CameraCalibration, read_calibration
    from slopedist.io.detections.adapters import as_box_table
    from slopedist.io.detections.boxes import BoxTable
    from slopedist.io.detections.readers import read_box_file as read_boxes
    from slopedist.io.frames import Frame, open_frames
    from slopedist.streaming.config import RunResult
    from slopedist.streaming.pipeline import FinishResult, FrameResult, Pipeline, Target
    from slopedist.streaming.setup import RunOptions, run_to_folder
