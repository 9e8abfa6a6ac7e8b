"""The built-in demo (``slopedist demo``): the synthetic-hill suite from rendered pixels.

For every scenario of the suite (:data:`~slopedist.datasets.synthetic.scenarios.SUITE`), frame
by frame: render the image and its true depth, run the built-in visual odometry on the grey
image (the noisy detector boxes masked out of its features), and feed every available method
its inputs — rotations from the odometry (or, for methods bound to an IMU, the true rotations
with IMU noise), the noisy boxes, and for depth-map methods the true depth with depth-network
noise. Estimates are matched to the truth by track id and scored against KITTI's z (camera z
of the box's bottom centre) with the published protocol's cap (estimates above 80 m count as
80 m, a box bottom at or above the vanishing line counts as 80 m).

Outputs (folder ``slopedist-demo/`` by default), written as the run goes:

- ``summary.txt``: the printed tables (Table-1-style RMSE per scenario × method, Table-2-style
  time per frame with odometry and estimation apart, odometry accuracy);
- ``results.json``: every figure behind the tables, and the noise models used;
- ``rmse.csv`` and ``timing.csv``: the two tables as CSV;
- per scenario ``<name>/records.csv`` (one row per target, frame and method, with the truth),
  ``<name>/frames.csv`` (per frame: odometry state, θ from the odometry and the true θ in
  degrees, odometry time in ms; :data:`DEMO_FRAME_FIELDS`),
  ``<name>/distance.png``, ``<name>/theta.png`` and ``<name>/overlay.mp4`` (the paper's Fig. 3
  style; an animated GIF when OpenCV cannot write MP4).

Convention: radians inside, degrees in files and tables; distances in metres; times in seconds
(milliseconds in the tables).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from slopedist import score_tables, viz
from slopedist.camera import Camera
from slopedist.datasets.synthetic.export import true_theta
from slopedist.datasets.synthetic.scenarios import SUITE, load_scenario
from slopedist.datasets.synthetic.sequence import SyntheticFrame, SyntheticSequence
from slopedist.errors import ConfigurationError, InputFileError, SlopedistError
from slopedist.estimators import DEFAULT_METHOD, available_methods, make_estimator
from slopedist.estimators.base import FrameEstimates, MissingReason
from slopedist.evaluation import ScoredSet, cap_estimates, distance_metrics, pool_methods
from slopedist.io.overlay import OverlayWriter
from slopedist.io.tables import CsvStreamWriter, write_csv, write_json
from slopedist.odometry.base import LOOKBACK_S, OdometryResult, OdometryState, RotationOdometry
from slopedist.pipeline import EgoGradientTracker, RecordWriter, StreamingEstimator, iter_records
from slopedist.tables import Table, format_texts

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
IMU_PITCH_NOISE_RAD = math.radians(0.03)
"""Standard deviation of the simulated IMU's pitch and roll error per frame (an OXTS RT3000 is
specified at 0.03°), radians."""
DEPTH_SCALE_SIGMA = 0.05
"""Simulated depth network: per-frame log-scale error (5 %)."""
DEPTH_PIXEL_SIGMA = 0.03
"""Simulated depth network: per-pixel log error (3 %)."""
IMU_SOURCE = "oxts"
"""``Estimator.rotation_source`` of methods bound to an IMU."""


class TrueRotationOdometry:
    """Rotation source that returns the scene's true camera rotations (a diagnostic: it
    separates odometry error from method error; ``slopedist demo --odometry truth``)."""

    def __init__(self, R_world_cam: FloatArray) -> None:
        self._R = R_world_cam
        self._k = 0

    def process(
        self,
        image_gray: NDArray[np.uint8],
        timestamp_s: float,
        mask_boxes: NDArray[np.float64] | None = None,
    ) -> OdometryResult:
        R = self._R[self._k]
        self._k += 1
        return OdometryResult(R, OdometryState.OK, 0)

    def reset(self) -> None:
        self._k = 0


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
    """

    out_dir: Path = DEFAULT_OUT
    scenarios: tuple[str, ...] = SUITE
    methods: tuple[str, ...] | None = None
    odometry: str = "visual"
    video: bool = True
    plots: bool = True
    max_frames: int | None = None
    progress: bool = True

    def __post_init__(self) -> None:
        if self.odometry not in ("visual", "truth"):
            raise ConfigurationError(f"odometry must be 'visual' or 'truth', got '{self.odometry}'")


@dataclass
class MethodPlan:
    """How one method is fed in the demo, or why it is skipped."""

    name: str
    rotation: str = "odometry"  # "odometry", "imu" or "none"
    depth: bool = False
    skipped: str = ""


def plan_methods(names: list[str], camera: Camera) -> list[MethodPlan]:
    """Decide for each method what it is fed; methods that need something the demo cannot give
    are kept with a ``skipped`` reason."""
    plans = []
    for name in names:
        plan = MethodPlan(name)
        try:
            est = make_estimator(name, camera)
        except (SlopedistError, TypeError) as exc:
            plan.skipped = f"cannot be built with default options ({exc})"
            plans.append(plan)
            continue
        source = getattr(est, "rotation_source", None)
        if not est.needs_rotation:
            plan.rotation = "none"
        elif source == IMU_SOURCE:
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

    def scored_set(self) -> ScoredSet:
        """The capped estimates against the truth (:meth:`metrics`'s rule) as a scored set."""
        capped, ok = cap_estimates(np.asarray(self.distance, dtype=float), self.reason, CAP_M)
        truth = np.asarray(self.truth, dtype=float)
        return ScoredSet(capped[ok], truth[ok], len(truth), int(np.sum(~ok)), self.seconds)

    def metrics(self) -> dict[str, Any]:
        """RMSE etc. under the cap protocol; ``n`` scored, ``below_horizon`` counted as 80 m,
        ``unscored`` (other missing reasons)."""
        d = np.asarray(self.distance, dtype=float)
        reason = np.asarray(self.reason, dtype=object)
        capped, ok = cap_estimates(d, reason, CAP_M)
        out: dict[str, Any] = dict(distance_metrics(capped[ok], np.asarray(self.truth)[ok]))
        out["below_horizon"] = int(np.sum(reason == MissingReason.BELOW_HORIZON.value))
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


def _imu_rotations(R_true: FloatArray, seed: int) -> FloatArray:
    """True camera rotations with IMU-like pitch and roll noise (radians, per frame)."""
    rng = np.random.default_rng([seed, 0x1A1])
    eps = rng.normal(0.0, IMU_PITCH_NOISE_RAD, (len(R_true), 3)) * np.array([1.0, 0.0, 1.0])
    return np.asarray(R_true @ Rotation.from_rotvec(eps).as_matrix())


class _DepthNoise:
    """Simulated metric depth network: true depth × per-frame scale × per-pixel noise."""

    def __init__(self, height: int, width: int, seed: int) -> None:
        rng = np.random.default_rng([seed, 0xDE9])
        self._field = np.exp(rng.normal(0.0, DEPTH_PIXEL_SIGMA, (2 * height, 2 * width))).astype(
            np.float32
        )
        self._seed = seed
        self._h, self._w = height, width

    def __call__(self, depth: NDArray[np.float32], k: int) -> NDArray[np.float32]:
        scale = math.exp(
            np.random.default_rng([self._seed, k, 0xDE9]).normal(0.0, DEPTH_SCALE_SIGMA)
        )
        oy, ox = (k * 131) % self._h, (k * 977) % self._w
        out = depth * self._field[oy : oy + self._h, ox : ox + self._w] * np.float32(scale)
        out[~np.isfinite(depth)] = np.nan
        return np.asarray(out, dtype=np.float32)


class _GifWriter:
    """Animated GIF fallback for the overlay (half resolution)."""

    def __init__(self, path: Path, fps: float) -> None:
        self.path = path
        self.fps = fps
        self.frames: list[Any] = []

    def write(self, index: int, image: NDArray[np.uint8]) -> None:
        from PIL import Image

        small = cv2.resize(image, (image.shape[1] // 2, image.shape[0] // 2))
        self.frames.append(Image.fromarray(cv2.cvtColor(small, cv2.COLOR_BGR2RGB)))

    def close(self) -> None:
        if self.frames:
            self.frames[0].save(
                self.path,
                save_all=True,
                append_images=self.frames[1:],
                duration=int(1000 / self.fps),
                loop=0,
            )


def _overlay_writer(folder: Path, fps: float) -> OverlayWriter | _GifWriter:
    try:
        writer = OverlayWriter(folder / "overlay.mp4", fps)
        probe = cv2.VideoWriter(
            str(folder / "overlay.mp4"), cv2.VideoWriter.fourcc(*"mp4v"), fps, (16, 16)
        )
        ok = probe.isOpened()
        probe.release()
        if ok:
            return writer
    except InputFileError:
        pass
    return _GifWriter(folder / "overlay.gif", fps)


def run_scenario(
    name: str, cfg: DemoConfig, method_names: list[str], bar: tqdm | None = None
) -> tuple[ScenarioRun, list[MethodPlan]]:
    """Run every method on one scenario (see the module docstring)."""
    scenario = load_scenario(name)
    seq = SyntheticSequence(scenario)
    camera = seq.camera
    plans = plan_methods(method_names, camera)
    active = [p for p in plans if not p.skipped]
    n = len(seq) if cfg.max_frames is None else min(len(seq), cfg.max_frames)
    folder = cfg.out_dir / scenario.name
    folder.mkdir(parents=True, exist_ok=True)
    R_true = seq.truth.poses_cam0()[:, :3, :3]
    odometry: RotationOdometry = (
        visual_odometry(camera) if cfg.odometry == "visual" else TrueRotationOdometry(R_true)
    )
    R_imu = _imu_rotations(R_true, scenario.seed)
    depth_noise = (
        _DepthNoise(camera.image_height or 0, camera.image_width or 0, scenario.seed)
        if any(p.depth for p in active)
        else None
    )
    streams = {
        p.name: StreamingEstimator(make_estimator(p.name, camera), LOOKBACK_S) for p in active
    }
    scores = {p.name: MethodScores() for p in plans}
    overlay_method = DEFAULT_METHOD if DEFAULT_METHOD in streams else next(iter(streams), None)
    painter = _overlay_writer(folder, scenario.frame_rate_hz) if cfg.video else None
    theta_true = true_theta(seq.truth, camera.mount_angle_rad)
    theta_est = np.full(n, np.nan)
    render_s = odo_s = 0.0
    states: dict[str, int] = {}
    timestamps = seq.truth.timestamps_s
    gradient = EgoGradientTracker(camera.mount_angle_rad, LOOKBACK_S)
    records = RecordWriter.open(folder / "records.csv")
    frame_log = CsvStreamWriter.open(folder / "frames.csv", DEMO_FRAME_FIELDS)
    try:
        for k in range(n):
            t0 = time.perf_counter()
            frame: SyntheticFrame = seq.frame(k)
            t1 = time.perf_counter()
            gray = np.asarray(cv2.cvtColor(frame.image, cv2.COLOR_BGR2GRAY), dtype=np.uint8)
            res = odometry.process(gray, frame.timestamp_s, frame.detections.boxes)
            t2 = time.perf_counter()
            render_s += t1 - t0
            odo_s += t2 - t1
            states[res.state.value] = states.get(res.state.value, 0) + 1
            theta_est[k] = gradient.update(frame.timestamp_s, res.R_world_cam)
            frame_log.write_values(
                [
                    [
                        k,
                        frame.timestamp_s,
                        res.state.value,
                        math.degrees(theta_est[k]),
                        math.degrees(theta_true[k]),
                        1e3 * (t2 - t1),
                    ]
                ]
            )
            boxes = frame.detections
            m_idx = np.searchsorted(seq.truth.track_ids, boxes.track_id)
            truth_z = seq.truth.z_m[k, m_idx]
            depth = depth_noise(frame.depth_m, k) if depth_noise is not None else None
            shown: FrameEstimates | None = None
            for p in active:
                if scores[p.name].failed:
                    continue
                R = {"odometry": res.R_world_cam, "imu": R_imu[k], "none": None}[p.rotation]
                t3 = time.perf_counter()
                try:
                    est = streams[p.name].update(
                        k, frame.timestamp_s, R, boxes, frame.image, depth if p.depth else None
                    )
                except SlopedistError as exc:
                    scores[p.name].failed = f"frame {k}: {exc}"
                    continue
                scores[p.name].seconds += time.perf_counter() - t3
                scores[p.name].add(k, boxes.track_id, est, truth_z)
                rows = list(iter_records(boxes, timestamps, est, p.name))
                for row, z in zip(rows, truth_z):
                    row["truth_z_m"] = float(z)
                records.write(rows)
                if p.name == overlay_method:
                    shown = est
            if painter is not None and shown is not None:
                th = theta_est[k]
                head = (
                    f"{scenario.name}  frame {k}  t {frame.timestamp_s:4.1f} s  "
                    f"{overlay_method}: theta {math.degrees(th):+.2f} deg (true "
                    f"{math.degrees(theta_true[k]):+.2f})"
                    if math.isfinite(th)
                    else f"{scenario.name}  frame {k}  no rotation ({res.state.value})"
                )
                painter.write(
                    k, viz.draw_fig3_overlay(frame.image, camera, boxes, shown, None, head)
                )
            if bar is not None:
                bar.update(1)
    finally:
        records.close()
        frame_log.close()
        if painter is not None:
            painter.close()
    files = [str(folder / "records.csv"), str(folder / "frames.csv")]
    if painter is not None:
        files.append(str(painter.target if isinstance(painter, OverlayWriter) else painter.path))
    run = ScenarioRun(
        scenario.name,
        scenario.description.strip(),
        n,
        scores,
        render_s,
        odo_s,
        states,
        theta_est,
        theta_true[:n],
        files,
    )
    if cfg.plots:
        run.files += _plots(run, seq, folder, [p.name for p in active])
    return run, plans


def _plots(run: ScenarioRun, seq: SyntheticSequence, folder: Path, methods: list[str]) -> list[str]:
    """Distance vs truth and θ vs truth plots of one scenario."""
    t = seq.truth.timestamps_s[: run.frames]
    cam = seq.camera
    series = []
    theta_targets = []
    for m, tid in enumerate(seq.truth.track_ids):
        truth = np.where(seq.truth.in_view[: run.frames, m], seq.truth.z_m[: run.frames, m], np.nan)
        est: dict[str, FloatArray] = {}
        below: dict[str, NDArray[np.bool_]] = {}
        for name in methods:
            s = run.scores[name]
            d = np.full(run.frames, np.nan)
            b = np.zeros(run.frames, bool)
            for f, tr, dist, r in zip(s.frame, s.track, s.distance, s.reason):
                if tr == tid:
                    d[f] = dist
                    b[f] = r == MissingReason.BELOW_HORIZON.value
            est[name] = d
            below[name] = b
        series.append(viz.DistanceSeries(int(tid), truth, est, below))
        # θ that would make eq. 1 exact for this target (exact box, true z), and the paper's
        needed = theta_needed_rad(seq.truth.box[: run.frames, m, 3], truth, cam)
        adj = np.full(run.frames, np.nan)
        dy = np.full(run.frames, np.nan)
        if "paper" in run.scores:
            s = run.scores["paper"]
            for f, tr, a, y in zip(s.frame, s.track, s.theta_adj, s.delta_y):
                if tr == tid:
                    adj[f], dy[f] = a, y
        theta_targets.append(viz.TargetTheta(int(tid), needed, adj, dy))
    p1 = folder / "distance.png"
    viz.plot_distance_series(p1, t, series, f"{run.name}: distance vs truth (KITTI z)")
    p2 = folder / "theta.png"
    viz.plot_theta_series(
        p2, t, run.theta_est, run.theta_true, theta_targets, f"{run.name}: ego gradient θ vs truth"
    )
    return [str(p1), str(p2)]


@dataclass
class DemoResult:
    """All scenarios of a demo run."""

    config: DemoConfig
    runs: list[ScenarioRun]
    plans: list[MethodPlan]
    elapsed_s: float

    @property
    def methods(self) -> list[str]:
        return [p.name for p in self.plans if not p.skipped]


def run_demo(cfg: DemoConfig, echo: Callable[[str], None] = print) -> DemoResult:
    """Run the demo and write its outputs (see the module docstring)."""
    start = time.perf_counter()
    cfg.out_dir.mkdir(parents=True, exist_ok=True)
    names = list(cfg.methods) if cfg.methods is not None else available_methods()
    unknown = [m for m in names if m not in available_methods()]
    if unknown:
        raise ConfigurationError(
            f"unknown method(s) {', '.join(unknown)}; choose from {', '.join(available_methods())}"
        )
    scenarios = [load_scenario(s) for s in cfg.scenarios]  # fail early on a bad name or file
    total = sum(
        s.n_frames if cfg.max_frames is None else min(s.n_frames, cfg.max_frames) for s in scenarios
    )
    runs: list[ScenarioRun] = []
    plans: list[MethodPlan] = []
    with tqdm(
        total=total,
        unit="frame",
        disable=not cfg.progress,
        dynamic_ncols=True,
        desc="slopedist demo",
    ) as bar:
        for name, sc in zip(cfg.scenarios, scenarios):
            bar.set_postfix_str(sc.name)
            run, plans = run_scenario(name, cfg, names, bar)
            runs.append(run)
            result = DemoResult(cfg, runs, plans, time.perf_counter() - start)
            _write_results(result)  # after every scenario, so a stopped run keeps its figures
    for p in plans:
        if p.skipped:
            echo(f"skipped method {p.name}: {p.skipped}")
    result = DemoResult(cfg, runs, plans, time.perf_counter() - start)
    _write_results(result)
    return result


# --- tables ---------------------------------------------------------------------------------


def _scored_sets(result: DemoResult) -> dict[str, dict[str, ScoredSet]]:
    """``{scenario: {method: scored set}}`` of the methods that ran."""
    return {r.name: {m: r.scores[m].scored_set() for m in result.methods} for r in result.runs}


def rmse_table(result: DemoResult) -> Table:
    """Table 1: RMSE (m) per scenario × method, and each method pooled over the scenarios."""
    odo = (
        "the built-in visual odometry on the rendered frames"
        if result.config.odometry == "visual"
        else "the TRUE rotations (diagnostic, --odometry truth)"
    )
    title = (
        f"Table 1. RMSE (m) against KITTI z (camera z of the box's bottom centre); rotations "
        f"from {odo}; noisy detector boxes; estimates capped at {CAP_M:g} m, a box at or above "
        f"the vanishing line counts as {CAP_M:g} m"
    )
    scores = pool_methods(_scored_sets(result), result.methods)
    return score_tables.rmse_table(scores, title, row_label="scenario", key="rmse")


def missing_table(result: DemoResult) -> Table:
    """Targets at or above the vanishing line (scored as 80 m) per scenario × method."""
    methods = result.methods
    rows: list[list[Any]] = [
        [r.name, *(r.scores[m].metrics()["below_horizon"] for m in methods)] for r in result.runs
    ]
    title = f"Targets at or above the vanishing line (counted as {CAP_M:g} m)"
    return Table("below_horizon", title, ["scenario", *methods], rows)


def timing_table(result: DemoResult) -> Table:
    """Table 2: milliseconds per frame: odometry and estimation apart."""
    frames = sum(r.frames for r in result.runs)
    odo_ms = 1e3 * sum(r.odometry_s for r in result.runs) / max(frames, 1)
    render_ms = 1e3 * sum(r.render_s for r in result.runs) / max(frames, 1)
    rows: list[list[Any]] = []
    for p in result.plans:
        if p.skipped:
            continue
        est_ms = 1e3 * sum(r.scores[p.name].seconds for r in result.runs) / max(frames, 1)
        odo = odo_ms if p.rotation == "odometry" else 0.0
        src = {
            "odometry": result.config.odometry + " odometry",
            "imu": "IMU (simulated)",
            "none": "-",
        }[p.rotation] + (" + depth map" if p.depth else "")
        rows.append([p.name, src, odo, est_ms, odo + est_ms])
    title = (
        "Table 2. Time per frame (ms; the detector is external and not counted; rendering "
        f"{render_ms:.1f} ms/frame is not counted)"
    )
    headers = ["method", "inputs", "odometry_ms", "estimation_ms", "total_ms"]
    return Table("timing", title, headers, rows)


def odometry_table(result: DemoResult) -> Table:
    """Ego gradient θ from the odometry against θ from the true rotations (degrees)."""
    rows: list[list[Any]] = []
    for r in result.runs:
        err = np.degrees(r.theta_est - r.theta_true)
        ok = np.isfinite(err)
        rows.append(
            [
                r.name,
                int(ok.sum()),
                r.frames,
                float(np.sqrt(np.mean(err[ok] ** 2))) if ok.any() else math.nan,
                float(np.max(np.abs(err[ok]))) if ok.any() else math.nan,
                float(np.max(np.abs(np.degrees(r.theta_true)))),
            ]
        )
    headers = [
        "scenario",
        "frames_ok",
        "frames",
        "theta_rms_err_deg",
        "theta_max_err_deg",
        "theta_true_max_deg",
    ]
    title = "Ego gradient θ (eq. 4) from the odometry vs. from the true rotations (degrees)"
    return Table("odometry", title, headers, rows)


def demo_tables(result: DemoResult) -> list[Table]:
    """Every table of the summary, in order (the first and the third are also CSV files)."""
    return [rmse_table(result), missing_table(result), timing_table(result), odometry_table(result)]


def format_demo_tables(result: DemoResult) -> str:
    """The printed summary."""
    return format_texts(demo_tables(result))


def _results_json(result: DemoResult) -> dict[str, Any]:
    """Every figure behind the tables, and the noise models (``results.json``)."""
    return {
        "config": {
            "scenarios": list(result.config.scenarios),
            "odometry": result.config.odometry,
            "max_frames": result.config.max_frames,
        },
        "protocol": {
            "distance": "KITTI z: camera z of the 3D box's bottom centre",
            "cap_m": CAP_M,
            "matching": "by track id",
            "imu_noise_deg": math.degrees(IMU_PITCH_NOISE_RAD),
            "depth_noise": {
                "frame_log_sigma": DEPTH_SCALE_SIGMA,
                "pixel_log_sigma": DEPTH_PIXEL_SIGMA,
            },
        },
        "methods": {
            p.name: {"rotation": p.rotation, "depth": p.depth, "skipped": p.skipped}
            for p in result.plans
        },
        "scenarios": {
            r.name: {
                "description": r.description,
                "frames": r.frames,
                "render_ms_per_frame": 1e3 * r.render_s / max(r.frames, 1),
                "odometry_ms_per_frame": 1e3 * r.odometry_s / max(r.frames, 1),
                "odometry_states": r.odometry_states,
                "methods": {
                    m: {
                        **s.metrics(),
                        "failed": s.failed,
                        "estimation_ms_per_frame": 1e3 * s.seconds / max(r.frames, 1),
                    }
                    for m, s in r.scores.items()
                    if m in result.methods
                },
                "files": r.files,
            }
            for r in result.runs
        },
        "elapsed_s": result.elapsed_s,
    }


def _write_results(result: DemoResult) -> None:
    out = result.config.out_dir
    tables = demo_tables(result)
    for fname, table in (("rmse.csv", tables[0]), ("timing.csv", tables[2])):
        write_csv(out / fname, table.records(), table.headers)
    (out / "summary.txt").write_text(format_texts(tables) + "\n", encoding="utf-8")
    write_json(out / "results.json", _results_json(result))


def iter_outputs(result: DemoResult) -> Iterator[str]:
    """Paths of everything the run wrote."""
    out = result.config.out_dir
    for name in ("summary.txt", "results.json", "rmse.csv", "timing.csv"):
        yield str(out / name)
    for r in result.runs:
        yield from r.files


def theta_needed_rad(box_bottom_px: FloatArray, z_true_m: FloatArray, camera: Camera) -> FloatArray:
    """θ that makes eq. 1 give exactly ``z_true_m`` for a box bottom row ``u`` (radians):
    eq. 1 solved for the vanishing line, ``v = u − f·h/z``, then eq. 5 for θ."""
    v = box_bottom_px - camera.f * camera.height_m / z_true_m
    return np.asarray(np.arctan((camera.c_y - v) / camera.f))
