"""The KITTI tracking evaluation (``slopedist eval kitti-tracking``): protocol, runner, JSON.

Protocol (the default): ground truth = label rows of type Car or Van with truncated = 0,
occluded ≤ 1 and 0 < z ≤ 80 m, distance = the label's z. f = P2[0,0], c_y = P2[1,2];
camera height 1.65 m; θ0 = 0; look-back 1 s, frame k at k × 0.1 s. Estimates are capped at 80 m
and a target whose box bottom is at or above the vanishing line counts as 80 m.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from slopedist.camera import KITTI_CAMERA_HEIGHT_M
from slopedist.datasets.kitti_tracking import (
    PROTOCOL_CLASSES,
    PROTOCOL_MAX_DISTANCE_M,
    PROTOCOL_MAX_OCCLUDED,
    PROTOCOL_MAX_TRUNCATED,
    BoxSource,
    KittiTrackingSequence,
    RotationSource,
    list_sequences,
    load_sequence,
    protocol_mask,
)
from slopedist.detections.boxes import BoxTable
from slopedist.errors import ConfigurationError, MissingInputError
from slopedist.estimators import make_estimator
from slopedist.evaluation import ScoredSet, Stopwatch, cap_estimates, match_by_frame, pool
from slopedist.odometry.base import LOOKBACK_S
from slopedist.pipeline import estimate_sequence


@dataclass
class KittiEvalConfig:
    """Options of a KITTI tracking evaluation (defaults = the published protocol)."""

    sequences: Sequence[str] | None = None
    methods: Sequence[str] = ("flat", "ego", "paper")
    rotation: RotationSource = RotationSource.ORBSLAM3
    boxes: BoxSource = BoxSource.GT
    min_score: float | None = None
    height_m: float = KITTI_CAMERA_HEIGHT_M
    mount_angle_rad: float = 0.0
    cap_m: float = PROTOCOL_MAX_DISTANCE_M
    lookback_s: float = LOOKBACK_S
    min_iou: float = 0.5
    method_options: dict[str, dict[str, Any]] = field(default_factory=dict)

    def protocol(self) -> dict[str, Any]:
        """The protocol block of the JSON report."""
        return {
            "dataset": "kitti_tracking",
            "ground_truth": {
                "classes": list(PROTOCOL_CLASSES),
                "max_truncated": PROTOCOL_MAX_TRUNCATED,
                "max_occluded": PROTOCOL_MAX_OCCLUDED,
                "max_distance_m": PROTOCOL_MAX_DISTANCE_M,
                "distance": "label z (longitudinal, camera 2)",
            },
            "camera": {"f": "P2[0,0]", "c_y": "P2[1,2]", "height_m": self.height_m,
                       "mount_angle_deg": math.degrees(self.mount_angle_rad)},
            "lookback_s": self.lookback_s,
            "frame_period_s": 0.1,
            "rotation": RotationSource(self.rotation).value,
            "boxes": BoxSource(self.boxes).value,
            "min_score": self.min_score,
            "matching": (f"greedy one-to-one by 2D IoU >= {self.min_iou}, best pair first"
                         if BoxSource(self.boxes) is BoxSource.POINTRCNN else None),
            "cap_m": self.cap_m,
            "cap_rule": (f"estimates above {self.cap_m:g} m are set to {self.cap_m:g} m; a target "
                         f"whose box bottom is at or above the vanishing line (u <= v) counts as "
                         f"{self.cap_m:g} m"),
            "overall": "pooled over all targets of all sequences",
            "sequences": list(self.sequences) if self.sequences is not None else None,
            "methods": list(self.methods),
        }


def _boxes_for(seq: KittiTrackingSequence, cfg: KittiEvalConfig, gt: BoxTable) -> BoxTable:
    if BoxSource(cfg.boxes) is BoxSource.GT:
        return gt
    return seq.detections(cfg.min_score)


def evaluate_sequence(
    seq: KittiTrackingSequence, cfg: KittiEvalConfig
) -> dict[str, ScoredSet]:
    """Score every method of ``cfg`` on one sequence."""
    gt = seq.labels.select(protocol_mask(seq.labels))
    boxes = _boxes_for(seq, cfg, gt)
    boxes = BoxTable(boxes.frame, boxes.boxes, boxes.track_id, boxes.score, boxes.cls,
                     {**boxes.extra, "row": np.arange(len(boxes))})
    needs_track = any(make_estimator(m, seq.camera).needs_rotation for m in cfg.methods)
    track = seq.rotations(cfg.rotation) if needs_track else None
    with_detections = BoxSource(cfg.boxes) is BoxSource.POINTRCNN
    det_rows, gt_rows = (match_by_frame(boxes, gt, cfg.min_iou) if with_detections
                         else (np.arange(len(gt)), np.arange(len(gt))))
    out: dict[str, ScoredSet] = {}
    for name in cfg.methods:
        estimator = make_estimator(name, seq.camera, **cfg.method_options.get(name, {}))
        with Stopwatch() as watch:
            result = estimate_sequence(estimator, boxes, seq.timestamps_s, track, cfg.lookback_s)
        capped, scorable = cap_estimates(result.estimates.distance_m, result.estimates.reason,
                                         cfg.cap_m)
        by_row = np.empty(len(boxes))
        ok_by_row = np.empty(len(boxes), dtype=bool)
        by_row[result.boxes.extra["row"]] = capped
        ok_by_row[result.boxes.extra["row"]] = scorable
        ok = ok_by_row[det_rows]
        out[name] = ScoredSet(
            pred_m=by_row[det_rows][ok], gt_m=gt.extra["z"][gt_rows][ok], n_gt=len(gt),
            n_unscored=int((~ok).sum()), seconds=watch.seconds, frames=seq.n_frames,
        )
    return out


def evaluate_kitti_tracking(
    root: str | Path,
    cfg: KittiEvalConfig,
    on_sequence: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run the evaluation; returns the JSON-ready report
    ``{"protocol": {...}, "methods": {name: {"overall": {...}, "sequences": {...}}}}``."""
    available = list_sequences(root)
    names = list(cfg.sequences) if cfg.sequences else available
    unknown = [s for s in names if s not in available]
    if unknown:
        raise MissingInputError(
            f"sequence(s) {', '.join(unknown)} not found under {root} "
            f"(available: {', '.join(available)})"
        )
    if not cfg.methods:
        raise ConfigurationError("no methods to evaluate")
    per_seq: dict[str, dict[str, ScoredSet]] = {}
    for name in names:
        if on_sequence is not None:
            on_sequence(name)
        per_seq[name] = evaluate_sequence(load_sequence(root, name, cfg.height_m,
                                                        cfg.mount_angle_rad), cfg)
    with_recall = BoxSource(cfg.boxes) is BoxSource.POINTRCNN
    cfg_for_json = KittiEvalConfig(**{**asdict(cfg), "sequences": names})
    report: dict[str, Any] = {"protocol": cfg_for_json.protocol(), "methods": {}}
    for method in cfg.methods:
        sets = [per_seq[s][method] for s in names]
        report["methods"][method] = {
            "overall": pool(sets).summary(with_recall),
            "sequences": {s: per_seq[s][method].summary(with_recall) for s in names},
        }
    return report
