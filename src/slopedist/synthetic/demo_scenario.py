"""One scenario of the demo (``slopedist demo``): what each method is fed, the frame loop and
the per-method scores. :mod:`slopedist.synthetic.demo` runs the suite and writes the tables.

Convention: radians inside, degrees in files; distances in metres; times in seconds.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError, SlopedistError
from slopedist.estimators import (
    DEFAULT_METHOD,
    EstimatorConfig,
    build_estimator,
)
from slopedist.estimators.base import FrameEstimates
from slopedist.estimators.imu import IMU_ROTATION_SOURCE
from slopedist.evaluation.metrics import (
    AT_CAP_REASONS,
    ScoredSet,
    cap_estimates,
    distance_metrics,
    reported_sigma,
)
from slopedist.io.formatting import CsvStreamWriter
from slopedist.io.overlay import GifWriter, OverlayWriter, open_overlay_video
from slopedist.odometry.base import LOOKBACK_S, RotationOdometry
from slopedist.odometry.jumps import shown_state
from slopedist.streaming import drawing as viz
from slopedist.streaming.step import (
    RECORD_FIELDS,
    EgoGradientTracker,
    FrameStep,
    close_records,
    iter_records,
    open_records,
)
from slopedist.synthetic.export import true_theta
from slopedist.synthetic.scenarios import SUITE
from slopedist.synthetic.scene import Scenario
from slopedist.synthetic.sensors import (
    DepthNoise,
    TrueRotationOdometry,
    imu_rotations,
)
from slopedist.synthetic.sequence import SyntheticFrame, SyntheticSequence

FloatArray = NDArray[np.float64]

DEFAULT_OUT = Path("slopedist-demo")
DEMO_FRAME_FIELDS = (
    "frame",
    "timestamp_s",
    "odometry_state",
    "theta_deg",
    "theta_true_deg",
    "odometry_ms",
)
"""Columns of a scenario's ``frames.csv`` (θ of eq. 4 in degrees, 1 s look-back)."""
CAP_M = 80.0
"""Cap of the published protocol, metres."""


def visual_odometry(camera: Camera) -> RotationOdometry:
    """The built-in visual odometry for ``camera``."""
    try:
        from slopedist.odometry.visual import BuiltinVisualOdometry
    except ImportError:
        raise ConfigurationError(
            "the built-in visual odometry (slopedist.odometry.visual) is "
            "not part of this build; use --odometry truth"
        ) from None
    return BuiltinVisualOdometry(camera)


@dataclass(frozen=True)
class DemoConfig:
    """Options of a demo run.

    Attributes:
        out_dir: output folder.
        scenarios: built-in names or TOML paths.
        methods: method names (None = every available one).
        odometry: ``"visual"`` (the built-in visual odometry on the rendered pixels) or
            ``"truth"`` (the true rotations; a diagnostic).
        video: write the overlay videos; plots: write the plots.
        max_frames: only the first frames of each scenario (None = all).
        progress: show a progress bar.
        estimator: the methods' options (its method is set per method).
        jobs: scenarios run at once, each in a process of its own (None: one per usable
            core, at most one per scenario; 1: one after the other in this process; with
            more than one, each scenario's plots are a task of their own in the same pool).
            Every scenario's figures are the same either way.
    """

    out_dir: Path = DEFAULT_OUT
    scenarios: tuple[str, ...] = SUITE
    methods: tuple[str, ...] | None = None
    odometry: str = "visual"
    video: bool = True
    plots: bool = True
    max_frames: int | None = None
    progress: bool = True
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)
    jobs: int | None = None

    def __post_init__(self) -> None:
        if self.odometry not in ("visual", "truth"):
            raise ConfigurationError(f"odometry must be 'visual' or 'truth', got '{self.odometry}'")
        if self.jobs is not None and self.jobs < 1:
            raise ConfigurationError(f"demo jobs must be ≥ 1, got {self.jobs}")


@dataclass
class MethodPlan:
    """How one method is fed in the demo, or why it is skipped."""

    name: str
    rotation: str = "odometry"  # "odometry", "imu" or "none"
    depth: bool = False
    skipped: str = ""


def plan_methods(
    names: list[str], camera: Camera, config: EstimatorConfig | None = None
) -> list[MethodPlan]:
    """Decide for each method what it is fed; methods that need something the demo cannot give
    are kept with a ``skipped`` reason. ``config`` holds the methods' options."""
    config = config if config is not None else EstimatorConfig()
    plans = []
    for name in names:
        plan = MethodPlan(name)
        try:
            est = build_estimator(config.with_method(name), camera)
        except (SlopedistError, TypeError) as exc:
            plan.skipped = f"cannot be built with default options ({exc})"
            plans.append(plan)
            continue
        source = getattr(est, "rotation_source", None)
        if not est.needs_rotation:
            plan.rotation = "none"
        elif source == IMU_ROTATION_SOURCE:
            plan.rotation = "imu"
        elif source is not None:
            plan.skipped = f"needs rotations from '{source}', which the demo does not simulate"
        plan.depth = bool(est.needs_depth)
        plans.append(plan)
    return plans


@dataclass
class MethodScores:
    """Per-target results of one method on one scenario (parallel arrays)."""

    frame: list[int] = field(default_factory=list)
    track: list[int] = field(default_factory=list)
    distance: list[float] = field(default_factory=list)
    reason: list[str] = field(default_factory=list)
    truth: list[float] = field(default_factory=list)
    theta_adj: list[float] = field(default_factory=list)
    delta_y: list[float] = field(default_factory=list)
    sigma: list[float] = field(default_factory=list)
    seconds: float = 0.0
    failed: str = ""

    def add(
        self, frame: int, tracks: NDArray[np.int64], est: FrameEstimates, truth: FloatArray
    ) -> None:
        n = len(est)
        self.frame += [frame] * n
        self.track += tracks.tolist()
        self.distance += est.distance_m.tolist()
        self.reason += [str(r) for r in est.reason]
        self.truth += truth.tolist()
        self.theta_adj += est.theta_adj_rad.tolist()
        self.delta_y += est.delta_y_px.tolist()
        sigma = est.extra.get("sigma_m")
        self.sigma += sigma.tolist() if sigma is not None else [math.nan] * n

    def scored_set(self) -> ScoredSet:
        """The capped estimates against the truth (:meth:`metrics`'s rule) as a scored set, with
        the method's own σ when it reports one."""
        capped, ok = cap_estimates(np.asarray(self.distance, dtype=float), self.reason, CAP_M)
        truth = np.asarray(self.truth, dtype=float)
        return ScoredSet(
            capped[ok],
            truth[ok],
            len(truth),
            int(np.sum(~ok)),
            self.seconds,
            sigma_m=reported_sigma(self.sigma, ok),
        )

    def metrics(self) -> dict[str, Any]:
        """RMSE etc. under the cap protocol; ``n`` scored, ``below_horizon`` counted as 80 m
        (at or near the vanishing line, or unresolved:
        :data:`~slopedist.evaluation.metrics.AT_CAP_REASONS`), ``unscored`` (other missing
        reasons)."""
        d = np.asarray(self.distance, dtype=float)
        reason = np.asarray(self.reason, dtype=object)
        capped, ok = cap_estimates(d, reason, CAP_M)
        out: dict[str, Any] = dict(distance_metrics(capped[ok], np.asarray(self.truth)[ok]))
        out["below_horizon"] = int(np.count_nonzero(np.isin(reason, AT_CAP_REASONS)))
        out["unscored"] = int(np.sum(~ok))
        return out


@dataclass
class ScenarioRun:
    """Everything measured on one scenario."""

    name: str
    description: str
    frames: int
    scores: dict[str, MethodScores]
    render_s: float
    odometry_s: float
    odometry_states: dict[str, int]
    theta_est: FloatArray
    theta_true: FloatArray
    files: list[str]


DEMO_RECORD_FIELDS = (*RECORD_FIELDS, "truth_z_m")
"""Columns of a scenario's ``records.csv`` (one file for every method, so no method's extra
columns)."""


class ScenarioLoop:
    """One scenario frame by frame: odometry, one look-back per rotation feed (θ computed once
    per frame and feed, never across an odometry restart), every method's frame step, outputs."""

    def __init__(
        self, scenario: Scenario, cfg: DemoConfig, plans: list[MethodPlan], folder: Path
    ) -> None:
        self.scenario, self.cfg, self.folder = scenario, cfg, folder
        self.seq = SyntheticSequence(scenario)
        camera = self.camera = self.seq.camera
        self.active = [p for p in plans if not p.skipped]
        self.n = len(self.seq) if cfg.max_frames is None else min(len(self.seq), cfg.max_frames)
        R_true = self.seq.truth.poses_cam0()[:, :3, :3]
        self.odometry: RotationOdometry = (
            visual_odometry(camera) if cfg.odometry == "visual" else TrueRotationOdometry(R_true)
        )
        self.R_imu = imu_rotations(R_true, scenario.seed)
        self.depth_noise = (
            DepthNoise(camera.image_height or 0, camera.image_width or 0, scenario.seed)
            if any(p.depth for p in self.active)
            else None
        )
        self.gradients = {
            feed: EgoGradientTracker(camera.mount_angle_rad, LOOKBACK_S)
            for feed in ("odometry", "imu")
        }
        self.steps = {
            p.name: FrameStep(build_estimator(cfg.estimator.with_method(p.name), camera))
            for p in self.active
        }
        self.scores = {p.name: MethodScores() for p in plans}
        self.overlay_method = (
            DEFAULT_METHOD if DEFAULT_METHOD in self.steps else next(iter(self.steps), None)
        )
        self.theta_true = true_theta(self.seq.truth, camera.mount_angle_rad)
        self.theta_est = np.full(self.n, np.nan)
        self.render_s = self.odometry_s = 0.0
        self.states: dict[str, int] = {}

    def run(self, bar: tqdm | None) -> list[str]:
        """Every frame; returns the files written."""
        records = open_records(self.folder / "records.csv", DEMO_RECORD_FIELDS)
        frame_log = CsvStreamWriter.open(self.folder / "frames.csv", DEMO_FRAME_FIELDS)
        painter = (
            open_overlay_video(self.folder, self.scenario.frame_rate_hz) if self.cfg.video else None
        )
        try:
            for k in range(self.n):
                self.frame(k, records, frame_log, painter)
                if bar is not None:
                    bar.update(1)
        finally:
            close_records(records)
            frame_log.close()
            if painter is not None:
                painter.close()
        files = [str(self.folder / "records.csv"), str(self.folder / "frames.csv")]
        if painter is not None:
            files.append(
                str(painter.target if isinstance(painter, OverlayWriter) else painter.path)
            )
        return files

    def frame(
        self,
        k: int,
        records: CsvStreamWriter,
        frame_log: CsvStreamWriter,
        painter: OverlayWriter | GifWriter | None,
    ) -> None:
        """Render frame ``k``, run the odometry and every method, write the outputs."""
        t0 = time.perf_counter()
        frame: SyntheticFrame = self.seq.frame(k)
        t1 = time.perf_counter()
        gray = np.asarray(cv2.cvtColor(frame.image, cv2.COLOR_BGR2GRAY), dtype=np.uint8)
        res = self.odometry.process(gray, frame.timestamp_s, frame.detections.boxes)
        t2 = time.perf_counter()
        self.render_s += t1 - t0
        self.odometry_s += t2 - t1
        t = frame.timestamp_s
        feeds = {
            "odometry": self._feed("odometry", t, res.R_world_cam, res.segment),
            "imu": self._feed("imu", t, self.R_imu[k]),
            "none": (None, math.nan, False),
        }
        state = shown_state(res.state.value, feeds["odometry"][2])
        self.states[state] = self.states.get(state, 0) + 1
        self.theta_est[k] = feeds["odometry"][1]
        frame_log.write_row(
            {
                "frame": k,
                "timestamp_s": t,
                "odometry_state": state,
                "theta_deg": math.degrees(self.theta_est[k]),
                "theta_true_deg": math.degrees(self.theta_true[k]),
                "odometry_ms": 1e3 * (t2 - t1),
            }
        )
        shown = self.estimate(k, frame, feeds, records)
        if painter is not None and shown is not None:
            painter.write(k, self.overlay(k, frame, shown, state))

    def _feed(
        self, name: str, t: float, R: FloatArray | None, segment: int = 0
    ) -> tuple[FloatArray | None, float, bool]:
        """A rotation feed's frame: the rotation its methods get (on an odometry jump the last
        trusted one), θ (radians) and whether the frame is a jump."""
        tracker = self.gradients[name]
        theta = tracker.update(t, R, segment)
        return tracker.given_rotation(R), theta, tracker.jump

    def estimate(
        self,
        k: int,
        frame: SyntheticFrame,
        feeds: dict[str, tuple[FloatArray | None, float, bool]],
        records: CsvStreamWriter,
    ) -> FrameEstimates | None:
        """Every method's estimates of frame ``k`` (scored and written); returns those of the
        overlay's method."""
        boxes = frame.detections
        truth_z = self.seq.truth.z_m[k, np.searchsorted(self.seq.truth.track_ids, boxes.track_id)]
        depth = self.depth_noise(frame.depth_m, k) if self.depth_noise is not None else None
        shown = None
        for p in self.active:
            score = self.scores[p.name]
            if score.failed:
                continue
            R, theta, jump = feeds[p.rotation]
            t3 = time.perf_counter()
            try:
                est = self.steps[p.name].estimate(
                    k,
                    frame.timestamp_s,
                    theta,
                    R,
                    boxes,
                    frame.image,
                    depth if p.depth else None,
                    jump,
                )
            except SlopedistError as exc:
                score.failed = f"frame {k}: {exc}"
                continue
            score.seconds += time.perf_counter() - t3
            score.add(k, boxes.track_id, est, truth_z)
            records.write_rows(
                {**{f: row[f] for f in RECORD_FIELDS}, "truth_z_m": float(z)}
                for row, z in zip(iter_records(boxes, frame.timestamp_s, est, p.name), truth_z)
            )
            if p.name == self.overlay_method:
                shown = est
        return shown

    def overlay(
        self, k: int, frame: SyntheticFrame, shown: FrameEstimates, state: str
    ) -> NDArray[np.uint8]:
        """The Fig. 3 style overlay of frame ``k`` with the overlay method's estimates."""
        th = self.theta_est[k]
        head = (
            f"{self.scenario.name}  frame {k}  t {frame.timestamp_s:4.1f} s  "
            f"{self.overlay_method}: theta {math.degrees(th):+.2f} deg (true "
            f"{math.degrees(self.theta_true[k]):+.2f})"
            if math.isfinite(th)
            else f"{self.scenario.name}  frame {k}  no rotation ({state})"
        )
        return viz.draw_fig3_overlay(frame.image, self.camera, frame.detections, shown, None, head)
