"""The IMU baseline rows: the paper's estimator (and the ego-only form) fed OXTS rotations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.estimators import (
    EgoGradientEstimator,
    FrameInput,
    ImuEgoEstimator,
    ImuEstimator,
    PaperEstimator,
    make_estimator,
)
from slopedist.evaluation.accuracy_tables import format_report_tables
from slopedist.evaluation.kitti import KittiEvalConfig, evaluate_kitti_tracking
from slopedist.evaluation.metrics import compact_names
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.kitti.tracking import RotationSource

CAMERA = Camera(720.0, 620.0, 180.0)


def test_imu_rows_are_the_paper_and_ego_estimators_on_oxts() -> None:
    assert isinstance(make_estimator("imu", CAMERA), ImuEstimator)
    assert isinstance(make_estimator("imu-ego", CAMERA), ImuEgoEstimator)
    assert ImuEstimator.rotation_source == ImuEgoEstimator.rotation_source == "oxts"
    assert RotationSource(ImuEstimator.rotation_source) is RotationSource.OXTS
    assert PaperEstimator.rotation_source is None
    boxes = BoxTable.build(
        [0, 0, 0], [[600, 150, 640, 176], [500, 190, 560, 230], [700, 160, 720, 170]]
    )
    frame = FrameInput(0, 0.0, np.radians(1.5), boxes)
    for imu, vo in (
        (ImuEstimator(CAMERA), PaperEstimator(CAMERA)),
        (ImuEgoEstimator(CAMERA), EgoGradientEstimator(CAMERA)),
    ):
        a, b = imu.estimate(frame), vo.estimate(frame)
        np.testing.assert_array_equal(a.distance_m, b.distance_m)
        np.testing.assert_array_equal(a.theta_adj_rad, b.theta_adj_rad)


def test_imu_is_fed_oxts_beside_orbslam3_and_missing_without_it(
    kitti_tracking_dir: Path,
) -> None:
    seqs = ["0000", "0014"]
    report = evaluate_kitti_tracking(
        kitti_tracking_dir, KittiEvalConfig(sequences=seqs, methods=("paper", "imu", "imu-ego"))
    )
    oxts = evaluate_kitti_tracking(
        kitti_tracking_dir,
        KittiEvalConfig(sequences=["0000"], methods=("paper", "ego"), rotation=RotationSource.OXTS),
    )
    m = report["methods"]
    # on 0000 the imu rows are exactly the paper/ego rows run on OXTS rotations
    assert m["imu"]["sequences"]["0000"]["rmse"] == oxts["methods"]["paper"]["overall"]["rmse"]
    assert m["imu-ego"]["sequences"]["0000"]["rmse"] == oxts["methods"]["ego"]["overall"]["rmse"]
    assert m["imu"]["sequences"]["0000"]["rmse"] != m["paper"]["sequences"]["0000"]["rmse"]
    # 0014 has no OXTS: a missing row with the reason, not a crash, not pooled
    assert "no oxts poses for sequence 0014" in m["imu"]["sequences"]["0014"]["missing"]
    assert m["imu"]["sequences"]["0014"]["n"] == 0
    assert m["imu"]["pooled_sequences"] == ["0000"]
    assert m["paper"]["pooled_sequences"] == seqs
    assert m["imu"]["overall"]["rmse"] == m["imu"]["sequences"]["0000"]["rmse"]
    common = report["overall_common"]
    assert common["sequences"] == ["0000"]
    assert common["methods"]["paper"]["rmse"] == m["paper"]["sequences"]["0000"]["rmse"]
    assert report["protocol"]["rotation_per_method"] == {
        "paper": "orbslam3",
        "imu": "oxts",
        "imu-ego": "oxts",
    }
    text = format_report_tables(report)
    assert "imu: no result on 0014" in text and "common" in text


def test_no_common_row_when_every_method_ran_everywhere(kitti_tracking_dir: Path) -> None:
    report = evaluate_kitti_tracking(
        kitti_tracking_dir, KittiEvalConfig(sequences=["0000"], methods=("flat", "imu"))
    )
    assert "overall_common" not in report
    assert report["protocol"]["rotation_per_method"] == {"flat": None, "imu": "oxts"}


def test_depthmap_without_depth_folder_is_a_configuration_error(
    kitti_tracking_dir: Path,
) -> None:
    with pytest.raises(ConfigurationError, match="depthmap need depth maps"):
        evaluate_kitti_tracking(
            kitti_tracking_dir, KittiEvalConfig(sequences=["0000"], methods=("depthmap",))
        )


def test_compact_names() -> None:
    assert compact_names(["0000", "0001", "0002", "0005", "x", "0006"]) == (
        "0000-0002, 0005, x, 0006"
    )
    assert compact_names([]) == ""
