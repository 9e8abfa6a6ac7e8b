"""The KITTI tracking evaluation (``slopedist eval kitti-tracking``, ``slopedist report``):
protocol, the per-sequence runs, the JSON report.

Protocol (the default): ground truth = label rows of type Car or Van with truncated = 0,
occluded ≤ 1 and 0 < z ≤ 80 m, distance = the label's z. f = P2[0,0], c_y = P2[1,2];
camera height 1.65 m; θ0 = 0; look-back 1 s, frame k at k × 0.1 s. Estimates are capped at 80 m
and a target whose box bottom is at or above the vanishing line counts as 80 m.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.batch.engine import map_tasks
from slopedist.core.camera import KITTI_CAMERA_HEIGHT_M
from slopedist.core.errors import ConfigurationError, MissingInputError
from slopedist.estimators import ESTIMATORS, make_estimator, takes_ours_options
from slopedist.estimators.base import MIN_RESOLVED_PX, MissingReason, ReferencePoint, image_size
from slopedist.estimators.depthmap import TRUTH_COLUMN
from slopedist.estimators.references import own_half_extent_m, to_reference
from slopedist.evaluation.learned_peer import (
    PEER_METHOD,
    PEER_PROTOCOL,
    LeaveOneSequenceOut,
    PeerSamples,
    box_features,
    regressor_class,
)
from slopedist.evaluation.metrics import (
    PooledScores,
    ScoredSet,
    Stopwatch,
    cap_estimates,
    match_by_frame,
    pool_methods,
)
from slopedist.io.depth.files import FileDepthSource
from slopedist.io.detections.boxes import BoxTable, box_problems
from slopedist.io.detections.sizes import DEFAULT_SIZE_SIGMA_PCT, SIZE_COLUMNS, SIZE_SIGMA_COLUMN
from slopedist.io.kitti.tracking import (
    DETECTOR_CLASSES,
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
from slopedist.odometry.base import LOOKBACK_S, RotationTrack
from slopedist.streaming.step import ego_gradients, estimate_sequence


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
    depth_dir: Path | None = None
    """Depth maps of methods that need them: ``depth_dir/<sequence>/<frame>.png|.npy``."""
    gt_reference: ReferencePoint | None = None
    """The point of the vehicle the truth's distance refers to, when declared (KITTI's label z
    is the centre): every method's distance is then moved to that point
    (:func:`~slopedist.estimators.references.to_reference`; ``ours`` reports it itself, option
    ``reference``, unless its options say otherwise), so that the evaluation compares like with
    like. None (the published protocol): the truth is the label z and each method is scored
    at its own point (ground-contact methods: the contact row; ``ours``: the centre)."""
    generic_detector_class: bool = False
    """With detector boxes (every box ``Car``), ``ours`` reads the class as generic: a mixture
    of vehicle types (option ``generic_classes``), unless its options say otherwise."""
    box_sizes: bool = False
    """Feed the vehicle sizes the boxes know (PointRCNN's ``h, w, l``, LiDAR-derived; the
    labels' own with ground-truth boxes; RRC knows none) as box columns
    (:mod:`slopedist.io.detections.sizes`): ``ours`` then uses them in place of its class
    prior. Off in the published protocol."""
    box_size_sigma_pct: float | None = None
    """The 1σ of those sizes, percent of each dimension (None:
    :data:`~slopedist.io.detections.sizes.DEFAULT_SIZE_SIGMA_PCT`)."""
    workers: int = 1
    """CPUs to run the sequences on: above 1, one Ray task per sequence
    (:func:`slopedist.batch.engine.map_tasks`, the batch extra); the results are those of 1."""

    def options_of(self, method: str) -> dict[str, Any]:
        """Constructor options of ``method`` on this evaluation's boxes."""
        options = dict(self.method_options.get(method, {}))
        if method not in ESTIMATORS or not takes_ours_options(method):
            return options
        if self.generic_detector_class and BoxSource(self.boxes).is_detector:
            options.setdefault("generic_classes", DETECTOR_CLASSES)
        if self.gt_reference is not None:
            options.setdefault("reference", ReferencePoint(self.gt_reference).value)
        return options

    def rotation_of(self, method: str) -> str | None:
        """Rotation source ``method`` is fed: the one it declares, else :attr:`rotation`; None
        for methods that use no rotation."""
        factory = ESTIMATORS.get(method)
        if factory is None or not getattr(factory, "needs_rotation", True):
            return None
        return getattr(factory, "rotation_source", None) or RotationSource(self.rotation).value

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
                "reference": ReferencePoint(self.gt_reference or ReferencePoint.CENTRE).value,
                "methods_compared_at": (
                    "each method's own point (published protocol)"
                    if self.gt_reference is None
                    else "the truth's reference (every method's distance moved to it)"
                ),
            },
            "camera": {
                "f": "P2[0,0]",
                "c_y": "P2[1,2]",
                "height_m": self.height_m,
                "mount_angle_deg": math.degrees(self.mount_angle_rad),
            },
            "lookback_s": self.lookback_s,
            "frame_period_s": 0.1,
            "rotation": RotationSource(self.rotation).value,
            "boxes": BoxSource(self.boxes).value,
            "min_score": self.min_score,
            "matching": (
                f"greedy one-to-one by 2D IoU >= {self.min_iou}, best pair first"
                if BoxSource(self.boxes).is_detector
                else None
            ),
            "detector_classes": (
                "generic: ours reads Car as a mixture of vehicle types"
                if self.generic_detector_class and BoxSource(self.boxes).is_detector
                else None
            ),
            **self._box_sizes_protocol(),
            "cap_m": self.cap_m,
            "cap_rule": (
                f"estimates above {self.cap_m:g} m are set to {self.cap_m:g} m; a target "
                f"whose box bottom is at or above the vanishing line (u <= v) or less than "
                f"{MIN_RESOLVED_PX:g} px below it, or whose distance the image does not resolve "
                f"(a box under {MIN_RESOLVED_PX:g} px tall, a distance beyond f*h/"
                f"{MIN_RESOLVED_PX:g} m, f in px and h in m), counts as {self.cap_m:g} m"
            ),
            "overall": (
                "pooled over all targets of the sequences each method ran on "
                "(pooled_sequences); overall_common pools every method over the "
                "sequences all of them ran on, when those differ"
            ),
            "rotation_per_method": {m: self.rotation_of(m) for m in self.methods},
            "learned_peer": PEER_PROTOCOL if PEER_METHOD in self.methods else None,
            "depth_dir": str(self.depth_dir) if self.depth_dir is not None else None,
            "sequences": list(self.sequences) if self.sequences is not None else None,
            "methods": list(self.methods),
        }

    def _box_sizes_protocol(self) -> dict[str, Any]:
        """The protocol's ``box_sizes`` entry, only when the sizes are fed (the published
        protocol's report stays as it was)."""
        if not self.box_sizes:
            return {}
        sigma = self.box_size_sigma_pct
        source = "labels" if BoxSource(self.boxes) is BoxSource.GT else BoxSource(self.boxes).value
        return {
            "box_sizes": {
                "from": f"{source} (height, width, length)",
                "sigma_pct": DEFAULT_SIZE_SIGMA_PCT if sigma is None else sigma,
            }
        }


def _boxes_for(seq: KittiTrackingSequence, cfg: KittiEvalConfig, gt: BoxTable) -> BoxTable:
    """The boxes the methods are fed: the labels, or the detector's boxes of the labelled
    frames (a detection after the last labelled frame has no truth to be scored against);
    with ``cfg.box_sizes`` their vehicle sizes as box columns."""
    source = BoxSource(cfg.boxes)
    if source is BoxSource.GT:
        return _with_size_sigma(_label_sizes(gt), cfg) if cfg.box_sizes else gt
    detections = seq.detections(cfg.min_score, source, sizes=cfg.box_sizes)
    detections = detections.select(detections.frame < seq.n_frames)
    return _with_size_sigma(detections, cfg) if cfg.box_sizes else detections


def _label_sizes(labels: BoxTable) -> BoxTable:
    """``labels`` with their dimensions (``dims_hwl``) as the size columns."""
    dims = np.asarray(labels.extra["dims_hwl"], dtype=float).reshape(-1, 3)
    extra = {**labels.extra, **{c: dims[:, k] for k, c in enumerate(SIZE_COLUMNS)}}
    return replace(labels, extra=extra)


def _with_size_sigma(boxes: BoxTable, cfg: KittiEvalConfig) -> BoxTable:
    """``boxes`` with ``cfg.box_size_sigma_pct`` as every box's size σ (when given)."""
    if cfg.box_size_sigma_pct is None:
        return boxes
    sigma = np.full(len(boxes), float(cfg.box_size_sigma_pct))
    return replace(boxes, extra={**boxes.extra, SIZE_SIGMA_COLUMN: sigma})


@dataclass
class MethodRun:
    """One method on one sequence, per fed box (rows of :attr:`SequenceRun.boxes`).

    Attributes:
        method: method name.
        rotation: rotation source it was fed (``"orbslam3"``, ``"oxts"``), None if none.
        distance_m: capped estimate per box (metres; NaN where not scorable).
        scorable: per box, whether the estimate counts (see ``cap_rule``).
        theta_rad: ego gradient per box, radians (NaN without rotation).
        reason: missing reason per box (``""`` when estimated).
        seconds: estimation wall time (depth-map loading excluded), seconds.
        depth_seconds: time spent producing depth maps (file reading or inference), seconds.
        missing: why the method has no result on this sequence (``""`` when it ran).
        sigma_m: the method's own 1σ per box (metres; its ``sigma_m`` column, of its own
            reference point), None when it reports none.
    """

    method: str
    rotation: str | None
    distance_m: NDArray[np.float64]
    scorable: NDArray[np.bool_]
    theta_rad: NDArray[np.float64]
    reason: NDArray[np.object_]
    seconds: float = 0.0
    depth_seconds: float = 0.0
    missing: str = ""
    sigma_m: NDArray[np.float64] | None = None


@dataclass
class SequenceRun:
    """Every method on one sequence, with what is needed to score them and plot them.

    Attributes:
        name: sequence name.
        n_frames: frames of the sequence.
        gt: ground-truth boxes kept by the protocol (``extra["z"]`` = distance, metres).
        boxes: the boxes fed to the estimators (``gt`` itself, or detections).
        det_rows, gt_rows: pairs of rows of ``boxes`` and ``gt`` that are scored together.
        runs: per method.
        theta_rad: ego gradient θ per frame (radians) of each rotation source that was loaded.
    """

    name: str
    n_frames: int
    gt: BoxTable
    boxes: BoxTable
    det_rows: NDArray[np.intp]
    gt_rows: NDArray[np.intp]
    runs: dict[str, MethodRun]
    theta_rad: dict[str, NDArray[np.float64]]

    def scored(self, method: str) -> ScoredSet:
        """The :class:`ScoredSet` of ``method`` (``info["missing"]`` says why, if absent)."""
        run = self.runs[method]
        if run.missing:
            return ScoredSet(
                np.zeros(0), np.zeros(0), n_gt=len(self.gt), frames=0, info={"missing": run.missing}
            )
        ok = run.scorable[self.det_rows]
        return ScoredSet(
            pred_m=run.distance_m[self.det_rows][ok],
            gt_m=self.gt.extra["z"][self.gt_rows][ok],
            n_gt=len(self.gt),
            n_unscored=int((~ok).sum()),
            seconds=run.seconds,
            frames=self.n_frames,
            info={"depth_seconds": run.depth_seconds},
            sigma_m=run.sigma_m[self.det_rows][ok] if run.sigma_m is not None else None,
        )


def check_run(root: str | Path, cfg: KittiEvalConfig) -> list[str]:
    """The sequences ``cfg`` names (all under ``root`` when none; each once, in the order first
    named), after checking that they exist, that there are methods, and that methods needing
    depth maps have a depth folder.

    Raises:
        MissingInputError: a named sequence is not under ``root``.
        ConfigurationError: no methods, depth maps needed and ``cfg.depth_dir`` not given,
            or vehicle sizes asked of boxes that have none (:func:`_check_box_sizes`).
    """
    available = list_sequences(root)
    names = list(dict.fromkeys(cfg.sequences)) if cfg.sequences else available
    unknown = [s for s in names if s not in available]
    if unknown:
        raise MissingInputError(
            f"sequence(s) {', '.join(unknown)} not found under {root} "
            f"(available: {', '.join(available)})"
        )
    if not cfg.methods:
        raise ConfigurationError("no methods to evaluate")
    needing = [m for m in cfg.methods if getattr(ESTIMATORS.get(m), "needs_depth", False)]
    if needing and cfg.depth_dir is None:
        raise ConfigurationError(
            f"method(s) {', '.join(needing)} need depth maps: give a depth folder "
            f"(--depth-dir DIR with DIR/<sequence>/<frame>.png or .npy)"
        )
    _check_box_sizes(cfg)
    return names


def _check_box_sizes(cfg: KittiEvalConfig) -> None:
    """Fail for sizes asked of boxes that have none, or a size σ without the sizes.

    Raises:
        ConfigurationError: ``box_sizes`` with RRC's boxes, or ``box_size_sigma_pct``
            without ``box_sizes``.
    """
    if cfg.box_sizes and BoxSource(cfg.boxes) is BoxSource.RRC:
        raise ConfigurationError(
            "RRC's boxes carry no vehicle size: --box-sizes needs --boxes pointrcnn or gt"
        )
    if cfg.box_size_sigma_pct is not None and not cfg.box_sizes:
        raise ConfigurationError("--box-size-sigma is the σ of --box-sizes: give both")


class _SequenceRotations:
    """A sequence's rotation tracks and ego gradients θ, read once per source."""

    def __init__(self, seq: KittiTrackingSequence, cfg: KittiEvalConfig) -> None:
        self.seq, self.cfg = seq, cfg
        self.tracks: dict[str, RotationTrack | str] = {}
        self.theta: dict[str, NDArray[np.float64]] = {}

    def track(self, source: RotationSource, declared: bool) -> RotationTrack | str:
        """The track of ``source``, or why there is none: a source the method declares
        (``declared``) but the sequence lacks is missing; ``cfg.rotation``'s file must exist."""
        seq = self.seq
        if source.value not in self.tracks:
            if declared and not seq.has_rotations(source):
                self.tracks[source.value] = (
                    f"no {source.value} poses for sequence {seq.name} "
                    f"(expected {seq.rotation_path(source)})"
                )
            else:
                track = seq.rotations(source)
                self.tracks[source.value] = track
                self.theta[source.value] = ego_gradients(
                    track, seq.camera.mount_angle_rad, self.cfg.lookback_s
                )[: seq.n_frames]
        return self.tracks[source.value]


def _boxes_with_truth(
    seq: KittiTrackingSequence, cfg: KittiEvalConfig
) -> tuple[BoxTable, BoxTable, NDArray[np.int64], NDArray[np.int64]]:
    """The protocol's ground truth, the boxes to estimate (with their row and the matched
    truth z as columns) and the matched (box row, truth row) pairs."""
    gt = seq.labels.select(protocol_mask(seq.labels))
    boxes = _boxes_for(seq, cfg, gt)
    det_rows, gt_rows = (
        match_by_frame(boxes, gt, cfg.min_iou)
        if BoxSource(cfg.boxes).is_detector
        else (np.arange(len(gt)), np.arange(len(gt)))
    )
    truth = np.full(len(boxes), np.nan)
    truth[det_rows] = gt.extra["z"][gt_rows]
    extra = {**boxes.extra, "row": np.arange(len(boxes)), TRUTH_COLUMN: truth}
    return gt, replace(boxes, extra=extra), det_rows, gt_rows


def _depth_for(
    seq: KittiTrackingSequence, cfg: KittiEvalConfig
) -> tuple[FileDepthSource | None, str]:
    """The sequence's depth maps, or why there are none."""
    if cfg.depth_dir is None:
        return None, ""
    folder = Path(cfg.depth_dir) / seq.name
    if not folder.is_dir():
        return None, f"no depth maps for sequence {seq.name} (expected folder {folder})"
    return FileDepthSource(folder, missing_ok=True), ""


def _run_method(
    name: str,
    seq: KittiTrackingSequence,
    cfg: KittiEvalConfig,
    boxes: BoxTable,
    rotations: _SequenceRotations,
) -> MethodRun:
    """One method over the sequence's boxes: capped distances, scorable flags, θ, reasons."""
    estimator = make_estimator(name, seq.camera, **cfg.options_of(name))
    source = RotationSource(estimator.rotation_source or cfg.rotation)
    source_name = source.value if estimator.needs_rotation else None
    declared = estimator.rotation_source is not None
    track = rotations.track(source, declared) if estimator.needs_rotation else None
    missing = track if isinstance(track, str) else ""
    depth_source = None
    if estimator.needs_depth and not missing:
        depth_source, missing = _depth_for(seq, cfg)
    n = len(boxes)
    if missing:
        nan = np.full(n, np.nan)
        reason = np.full(n, "missing", dtype=object)
        return MethodRun(name, source_name, nan, np.zeros(n, bool), nan, reason, missing=missing)
    with Stopwatch() as watch:
        result = estimate_sequence(
            estimator,
            boxes,
            seq.timestamps_s,
            track if isinstance(track, RotationTrack) else None,
            cfg.lookback_s,
            depth=depth_source.depth if depth_source is not None else None,
        )
    est = result.estimates
    distance = est.distance_m
    if cfg.gt_reference is not None:
        distance = to_reference(
            distance,
            est.reference,
            result.boxes.cls,
            ReferencePoint(cfg.gt_reference),
            own_half_extent_m(est.extra, len(distance)),
        )
    capped, scorable = cap_estimates(distance, est.reason, cfg.cap_m)
    rows = result.boxes.extra["row"]
    run = MethodRun(
        name,
        source_name,
        np.empty(n),
        np.empty(n, dtype=bool),
        np.empty(n),
        np.empty(n, dtype=object),
    )
    run.distance_m[rows] = capped
    run.scorable[rows] = scorable
    run.theta_rad[rows] = est.theta_rad
    run.reason[rows] = est.reason
    if "sigma_m" in est.extra:
        run.sigma_m = np.full(n, np.nan)
        run.sigma_m[rows] = est.extra["sigma_m"]
    run.depth_seconds = depth_source.seconds if depth_source is not None else 0.0
    run.seconds = watch.seconds - run.depth_seconds
    return run


def peer_samples(seq: KittiTrackingSequence, cfg: KittiEvalConfig) -> PeerSamples:
    """The learned peer's training pairs of one sequence: the features of the boxes ``cfg``
    feeds (its box source and score threshold) that are matched to a truth, with its z."""
    _, boxes, det_rows, _ = _boxes_with_truth(seq, cfg)
    features = box_features(boxes, seq.camera)[det_rows]
    return PeerSamples(features, boxes.extra[TRUTH_COLUMN][det_rows])


def learned_peer(root: str | Path, cfg: KittiEvalConfig) -> LeaveOneSequenceOut:
    """The learned peer of ``cfg``'s evaluation, with the training pairs of every sequence
    under ``root`` (scored or not; each is held out of its own model).

    Raises:
        OptionalDependencyError: scikit-learn (extra ``learned``) is not installed.
    """
    regressor_class()
    samples = {
        name: peer_samples(load_sequence(root, name, cfg.height_m, cfg.mount_angle_rad), cfg)
        for name in list_sequences(root)
    }
    return LeaveOneSequenceOut(samples)


def _run_peer(
    seq: KittiTrackingSequence, cfg: KittiEvalConfig, boxes: BoxTable, peer: LeaveOneSequenceOut
) -> MethodRun:
    """The learned peer over the sequence's boxes, from the model that never saw it (fitting
    not timed)."""
    n = len(boxes)
    if not peer.training_sequences(seq.name):
        nan = np.full(n, np.nan)
        missing = f"no other sequence to train the learned peer of {seq.name} on"
        reason = np.full(n, "missing", dtype=object)
        return MethodRun(PEER_METHOD, None, nan, np.zeros(n, bool), nan, reason, missing=missing)
    reason = box_problems(boxes.boxes, image_size(seq.camera))
    peer.model(seq.name)
    with Stopwatch() as watch:
        distance = peer.predict(seq.name, box_features(boxes, seq.camera))
    distance[reason != ""] = np.nan
    reason[(reason == "") & ~(distance > 0)] = MissingReason.INVALID_DISTANCE.value
    capped, scorable = cap_estimates(distance, reason, cfg.cap_m)
    theta = np.full(n, np.nan)
    return MethodRun(PEER_METHOD, None, capped, scorable, theta, reason, seconds=watch.seconds)


def run_sequence(
    seq: KittiTrackingSequence, cfg: KittiEvalConfig, peer: LeaveOneSequenceOut | None = None
) -> SequenceRun:
    """Run every method of ``cfg`` on one sequence.

    Each method is fed the rotation source it declares (``Estimator.rotation_source``, e.g. the
    IMU baseline's OXTS poses), else ``cfg.rotation``. A declared source, or a depth folder,
    that the sequence lacks makes that method missing for the sequence (with the reason); a
    missing ``cfg.rotation`` file is an error, as before. The learned peer
    (:data:`~slopedist.evaluation.learned_peer.PEER_METHOD`) needs ``peer`` (:func:`learned_peer`).

    Raises:
        ConfigurationError: the learned peer is asked for without ``peer``.
    """
    if PEER_METHOD in cfg.methods and peer is None:
        raise ConfigurationError(f"{PEER_METHOD} needs its leave-one-sequence-out training set")
    gt, boxes, det_rows, gt_rows = _boxes_with_truth(seq, cfg)
    rotations = _SequenceRotations(seq, cfg)
    runs = {
        name: (
            _run_peer(seq, cfg, boxes, peer)
            if name == PEER_METHOD and peer is not None
            else _run_method(name, seq, cfg, boxes, rotations)
        )
        for name in cfg.methods
    }
    return SequenceRun(seq.name, seq.n_frames, gt, boxes, det_rows, gt_rows, runs, rotations.theta)


@dataclass
class KittiEvaluation:
    """Every method run on every sequence of an evaluation (:func:`run_kitti_tracking`).

    Attributes:
        config: the configuration, ``sequences`` = the sequences run.
        runs: per sequence, in order.
    """

    config: KittiEvalConfig
    runs: dict[str, SequenceRun]

    def scores(self) -> PooledScores:
        """Every method scored per sequence and pooled (:func:`~slopedist.evaluation.metrics.
        pool_methods`), with the recall when the boxes are detections."""
        per_seq = {
            s: {m: run.scored(m) for m in self.config.methods} for s, run in self.runs.items()
        }
        with_recall = BoxSource(self.config.boxes).is_detector
        return pool_methods(per_seq, self.config.methods, with_recall)

    def report(self) -> dict[str, Any]:
        """The JSON-ready report ``{"protocol", "methods": {name: {"overall",
        "pooled_sequences", "sequences"}}}``, plus ``"overall_common"`` when the methods ran on
        different sequences (every method pooled over the sequences all of them ran on)."""
        scores = self.scores()
        report: dict[str, Any] = {
            "protocol": self.config.protocol(),
            "methods": scores.method_reports(),
        }
        if scores.common is not None:
            report["overall_common"] = scores.common
        return report


def load_and_run(
    root: str | Path, name: str, cfg: KittiEvalConfig, peer: LeaveOneSequenceOut | None = None
) -> SequenceRun:
    """Load sequence ``name`` under ``root`` and run every method of ``cfg`` on it, the learned
    peer from ``peer`` (one task of a parallel evaluation)."""
    return run_sequence(load_sequence(root, name, cfg.height_m, cfg.mount_angle_rad), cfg, peer)


def run_kitti_tracking(
    root: str | Path,
    cfg: KittiEvalConfig,
    on_sequence: Callable[[str], None] | None = None,
) -> KittiEvaluation:
    """Run every method of ``cfg`` on the sequences it names under ``root`` (all when none),
    calling ``on_sequence(name)`` before each; with ``cfg.workers`` > 1 on Ray, one task per
    sequence (``on_sequence`` as each is submitted).

    Raises:
        OptionalDependencyError: ``cfg.workers`` > 1 without the batch extra (Ray).
    """
    names = check_run(root, cfg)
    peer = learned_peer(root, cfg) if PEER_METHOD in cfg.methods else None
    if cfg.workers > 1:
        calls = [(Path(root).absolute(), name, cfg, peer) for name in names]
        announce = (lambda i: on_sequence(names[i])) if on_sequence is not None else None
        purpose = f"--workers {cfg.workers} (one Ray task per sequence)"
        results = map_tasks(load_and_run, calls, cfg.workers, purpose, announce)
        return KittiEvaluation(replace(cfg, sequences=list(names)), dict(zip(names, results)))
    runs: dict[str, SequenceRun] = {}
    for name in names:
        if on_sequence is not None:
            on_sequence(name)
        runs[name] = load_and_run(root, name, cfg, peer)
    return KittiEvaluation(replace(cfg, sequences=list(names)), runs)


def evaluate_kitti_tracking(
    root: str | Path,
    cfg: KittiEvalConfig,
    on_sequence: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run the evaluation; returns its JSON-ready :meth:`KittiEvaluation.report`.

    Example::

        report = evaluate_kitti_tracking(
            "kitti_tracking", KittiEvalConfig(methods=("flat", "paper", "ours"))
        )
        print(report["methods"]["ours"]["overall"]["rmse"])
    """
    return run_kitti_tracking(root, cfg, on_sequence).report()
