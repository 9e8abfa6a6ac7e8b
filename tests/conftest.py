"""Shared fixtures: the real KITTI data in ../shared/data (skipped when absent); hypothesis
without deadlines (no test is timed: a loaded machine must not fail one)."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings

settings.register_profile("untimed", deadline=None)
settings.load_profile("untimed")

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO_ROOT.parent / "shared" / "data"


KITTI_FIXTURES = frozenset(
    {"kitti_tracking_dir", "kitti_odometry_dir", "kitti_raw_lead_dir", "kitti_report"}
)
"""Fixtures that hand out real KITTI data; a test using one is marked ``kitti``."""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark each test that uses the real data ``kitti`` (``pytest -m "not kitti"`` skips them)."""
    for item in items:
        if KITTI_FIXTURES.intersection(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.kitti)


@pytest.fixture(scope="session")
def ray_instance() -> Iterator[Any]:
    """A local Ray instance with 2 CPUs for the session (skips when ray or pyarrow is absent);
    the engine's ``ray_session`` uses it instead of starting its own."""
    ray = pytest.importorskip("ray", reason="ray is not installed: pip install 'slopedist[batch]'")
    pytest.importorskip("pyarrow", reason="pyarrow is not installed")
    from slopedist.batch.engine import kept_signal_handlers

    with kept_signal_handlers():  # ray.init's SIGINT/SIGTERM handlers would outlive the tests
        ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    with kept_signal_handlers():
        ray.shutdown()


def shared_data_path(*parts: str) -> Path:
    """Path under ../shared/data, or skip the test with a message when it is absent."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"real KITTI data not found at {path} (a fresh clone has no ../shared)")
    return path


@pytest.fixture
def kitti_tracking_dir() -> Path:
    """../shared/data/kitti_tracking, or skip."""
    return shared_data_path("kitti_tracking")


@pytest.fixture
def kitti_odometry_dir() -> Path:
    """../shared/data/kitti_odometry, or skip."""
    return shared_data_path("kitti_odometry")


@pytest.fixture
def kitti_raw_lead_dir() -> Path:
    """../shared/data/kitti_raw_lead, or skip."""
    return shared_data_path("kitti_raw_lead")


def _constant_onnx_model(
    path: Path,
    outputs: Mapping[str, Any],
    in_shape: tuple[Any, ...] = (1, 3, 320, 320),
    metadata: Mapping[str, str] | None = None,
) -> Path:
    """Save an ONNX model whose outputs are the given constant arrays (float32) and whose one
    input, ``images`` of shape ``in_shape``, is ignored: a detector emitting known tensors
    (``metadata``: the model's custom metadata, e.g. ultralytics' ``names``)."""
    import numpy as np

    onnx = pytest.importorskip("onnx", reason="the 'onnx' package (test extra) builds models")
    from onnx import TensorProto, helper, numpy_helper

    arrays = {name: np.asarray(v, np.float32) for name, v in outputs.items()}
    nodes = [
        helper.make_node("Constant", [], [name], value=numpy_helper.from_array(v))
        for name, v in arrays.items()
    ]
    graph = helper.make_graph(
        nodes,
        "constant_detector",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, list(in_shape))],
        [
            helper.make_tensor_value_info(n, TensorProto.FLOAT, list(v.shape))
            for n, v in arrays.items()
        ],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    if metadata:
        helper.set_model_props(model, dict(metadata))
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


@pytest.fixture
def constant_model() -> Callable[..., Path]:
    """Builder of test ONNX models with constant outputs (see :func:`_constant_onnx_model`)."""
    return _constant_onnx_model


@dataclass(frozen=True)
class DriveFiles:
    """A short drive on disk as ``slopedist run`` reads it.

    Attributes:
        frames: the image folder.
        calib: its calibration file (KITTI layout: no image size in it).
        boxes: a slopedist box CSV of its vehicles (with ``gt_distance_m`` when known).
        run_options: the further ``slopedist run`` options of the drive (camera mount, times).
        real: whether it is KITTI raw (``kitti_raw_lead``) rather than a rendered scenario.
    """

    frames: Path
    calib: Path
    boxes: Path
    run_options: tuple[str, ...]
    real: bool


@pytest.fixture(scope="session")
def drive_files(tmp_path_factory: pytest.TempPathFactory) -> DriveFiles:
    """``kitti_raw_lead``'s frames, calibration and LiDAR vehicle boxes (truth: the LiDAR
    distance) when ../shared/data has them, else a rendered synthetic scenario
    (``slopedist simulate ego_crest``, 14 frames)."""
    root = tmp_path_factory.mktemp("drive")
    lead = SHARED_DATA / "kitti_raw_lead"
    if lead.is_dir():
        from slopedist.io.detections.readers import CSV_TRUTH_COLUMN
        from slopedist.io.detections.writers import write_box_csv
        from slopedist.io.kitti.raw import KittiRawDrive

        drive = KittiRawDrive.open(lead)
        boxes = drive.lidar_boxes((1242, 375))
        boxes.extra[CSV_TRUTH_COLUMN] = boxes.extra["z"]
        csv = write_box_csv(boxes, root / "boxes.csv", (CSV_TRUTH_COLUMN,))
        return DriveFiles(drive.image_dir, lead / "calib.txt", csv, (), True)
    from slopedist.cli import main

    sim = root / "sim"
    assert main(["simulate", "ego_crest", "--out", str(sim), "--frames", "14"]) == 0
    info = json.loads((sim / "info.json").read_text())
    options = (
        "--height",
        str(info["camera_height_m"]),
        "--mount-angle",
        str(info["mount_angle_deg"]),
        "--timestamps",
        str(sim / "times.txt"),
    )
    return DriveFiles(sim / "image_02", sim / "calib.txt", sim / "boxes.csv", options, False)
