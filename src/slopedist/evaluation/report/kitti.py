"""The report's data from a KITTI tracking folder: the runs of :mod:`slopedist.evaluation.kitti`."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import ConfigurationError
from slopedist.estimators import ESTIMATORS, available_methods, causal_methods
from slopedist.evaluation.kitti import (
    KittiEvalConfig,
    KittiEvaluation,
    SequenceRun,
    run_kitti_tracking,
)
from slopedist.evaluation.learned_peer import PEER_METHOD, PEER_PROTOCOL
from slopedist.evaluation.report.data import (
    RECORD_COLUMNS,
    THETA_COLUMNS,
    Columns,
    ReportData,
    ReportOptions,
    SourceKind,
    default_title,
)
from slopedist.io.kitti.tracking import BoxSource, RotationSource, load_sequence
from slopedist.streaming.step import ego_gradients

FRAME_PERIOD_S = 0.1
"""KITTI tracking frames are 0.1 s apart (frame k at k × 0.1 s)."""


def default_kitti_methods(depth: bool) -> list[str]:
    """Every registered method that can run on KITTI tracking (``depthmap`` with depth only)."""
    return [
        m for m in causal_methods() if depth or not getattr(ESTIMATORS[m], "needs_depth", False)
    ]


def _add_records(records: Columns, name: str, run: SequenceRun, methods: list[str]) -> None:
    """One row per scored pair (box matched to a truth) and method that ran on ``run``."""
    gt_z = run.gt.extra["z"][run.gt_rows]
    frames = run.boxes.frame[run.det_rows]
    tids = run.gt.track_id[run.gt_rows]
    for m in methods:
        mr = run.runs[m]
        if mr.missing:
            continue
        d = mr.distance_m[run.det_rows]
        ok = mr.scorable[run.det_rows]
        th = np.degrees(mr.theta_rad[run.det_rows])
        reasons = mr.reason[run.det_rows]
        for i in range(len(run.det_rows)):
            records.add(
                sequence=name,
                frame=int(frames[i]),
                timestamp_s=FRAME_PERIOD_S * int(frames[i]),
                track_id=int(tids[i]),
                method=m,
                rotation=mr.rotation or "",
                distance_m=float(d[i]) if ok[i] else math.nan,
                gt_distance_m=float(gt_z[i]),
                scored=bool(ok[i]),
                reason=reasons[i],
                theta_deg=float(th[i]),
            )


def _add_theta(theta: Columns, name: str, run: SequenceRun) -> None:
    """The ego gradient per frame of every rotation source loaded for ``run`` (degrees)."""
    for source, values in run.theta_rad.items():
        for k, v in enumerate(values):
            theta.add(
                sequence=name,
                frame=k,
                timestamp_s=FRAME_PERIOD_S * k,
                source=source,
                theta_deg=math.degrees(v),
            )


def _oxts_theta(root: Path, name: str, cfg: KittiEvalConfig) -> NDArray[np.float64] | None:
    """The ego gradient θ per frame (radians) from sequence ``name``'s OXTS poses, the report's
    θ truth when no method was fed them (None: the sequence has no OXTS file)."""
    seq = load_sequence(root, name, cfg.height_m, cfg.mount_angle_rad)
    if not seq.has_rotations(RotationSource.OXTS):
        return None
    track = seq.rotations(RotationSource.OXTS)
    return ego_gradients(track, seq.camera.mount_angle_rad, cfg.lookback_s)[: seq.n_frames]


def _timing(evaluation: KittiEvaluation, method: str) -> dict[str, float]:
    """Table 2's times of ``method`` (ms per frame over the sequences it ran on); the
    rotations are precomputed pose files, so the odometry is not timed."""
    present = [r for r in evaluation.runs.values() if not r.runs[method].missing]
    frames = sum(r.n_frames for r in present)
    seconds = sum(r.runs[method].seconds for r in present)
    depth_s = sum(r.runs[method].depth_seconds for r in present)
    needs_depth = getattr(ESTIMATORS.get(method), "needs_depth", False)
    return {
        "odometry_ms": math.nan,
        "estimation_ms": 1000 * seconds / frames if frames else math.nan,
        "depth_ms": 1000 * depth_s / frames if frames and needs_depth else math.nan,
        "frames": float(frames),
    }


def _notes(protocol: dict[str, Any], boxes: BoxSource) -> list[str]:
    boxes_kind = (
        "ground-truth boxes"
        if boxes is BoxSource.GT
        else f"{'PointRCNN' if boxes is BoxSource.POINTRCNN else 'RRC'} detections matched to "
        "the truth by IoU"
    )
    rotations: dict[str, str | None] = protocol["rotation_per_method"]
    truth = protocol["ground_truth"]
    notes = [
        f"Protocol: {boxes_kind}; "
        f"ground truth = KITTI label z of Car/Van, truncated 0, occluded <= 1, 0 < z <= 80 m, "
        f"referring to the vehicle's {truth['reference']}, methods compared at "
        f"{truth['methods_compared_at']}; {protocol['cap_rule']}.",
        "Rotation per method: "
        + ", ".join(f"{m} = {r or 'none'}" for m, r in rotations.items())
        + ".",
        "Odometry time is not measured on KITTI tracking: the rotations are precomputed pose "
        "files (ORB-SLAM3, OXTS). Estimation = the estimator's own time; depth = reading the "
        "depth maps (file read, not network inference). The 2D detector is excluded.",
    ]
    if protocol.get("learned_peer"):
        notes.append(f"{PEER_METHOD} (not an estimator: a yardstick): {PEER_PROTOCOL}.")
    return notes


def kitti_report_data(
    root: str | Path, opts: ReportOptions, on_sequence: Callable[[str], None] | None = None
) -> ReportData:
    """Run the methods on the KITTI tracking sequences under ``root``
    (:func:`~slopedist.evaluation.kitti.run_kitti_tracking`) and collect the data.

    Raises:
        ConfigurationError: an unknown method, or depth maps needed and not given.
        MissingInputError: a named sequence is not under ``root``.
    """
    root = Path(root)
    cfg = opts.eval
    methods = list(cfg.methods) or default_kitti_methods(cfg.depth_dir is not None)
    unknown = [m for m in methods if m not in ESTIMATORS and m != PEER_METHOD]
    if unknown:
        raise ConfigurationError(
            f"unknown method(s) {', '.join(unknown)}; choose from "
            f"{', '.join([*available_methods(), PEER_METHOD])}"
        )
    evaluation = run_kitti_tracking(root, replace(cfg, methods=tuple(methods)), on_sequence)
    records = Columns(RECORD_COLUMNS)
    theta = Columns(THETA_COLUMNS)
    oxts = RotationSource.OXTS.value
    for name, run in evaluation.runs.items():
        if oxts not in run.theta_rad:  # the θ truth, also when no method was fed OXTS
            truth = _oxts_theta(root, name, cfg)
            if truth is not None:
                run.theta_rad[oxts] = truth
        _add_records(records, name, run, methods)
        _add_theta(theta, name, run)
    protocol = evaluation.config.protocol()
    return ReportData(
        title=opts.title or default_title(SourceKind.KITTI_TRACKING, [], methods),
        source=root,
        kind=SourceKind.KITTI_TRACKING,
        scores=evaluation.scores(),
        timing={m: _timing(evaluation, m) for m in methods},
        records=records,
        theta=theta,
        protocol=protocol,
        notes=_notes(protocol, BoxSource(cfg.boxes)),
        truth_source=oxts if any(oxts in r.theta_rad for r in evaluation.runs.values()) else None,
    )
