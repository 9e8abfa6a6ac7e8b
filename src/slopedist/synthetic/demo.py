"""The built-in demo (``slopedist demo``): the synthetic-hill suite from rendered pixels.

For every scenario of the suite (:data:`~slopedist.synthetic.scenarios.SUITE`), frame
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
  degrees, odometry time in ms; :data:`~slopedist.synthetic.demo_scenario.DEMO_FRAME_FIELDS`),
  ``<name>/distance.png``, ``<name>/theta.png`` and ``<name>/overlay.mp4`` (the paper's Fig. 3
  style; an animated GIF when OpenCV cannot write MP4).

Convention: radians inside, degrees in files and tables; distances in metres; times in seconds
(milliseconds in the tables).
"""

from __future__ import annotations

import math
import multiprocessing
import re
import time
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.core.geometry import GradientAdjustment
from slopedist.estimators import EstimatorConfig, causal_methods
from slopedist.evaluation import accuracy_tables as score_tables
from slopedist.evaluation.metrics import AT_CAP_REASONS, PooledScores, pool_methods
from slopedist.evaluation.plots import (
    DistanceSeries,
    TargetTheta,
    plot_distance_series,
    plot_theta_series,
)
from slopedist.evaluation.table import Table, format_texts
from slopedist.io.formatting import write_csv, write_json
from slopedist.io.overlay import video_codec, video_fallback_note
from slopedist.io.prefetch import usable_cores
from slopedist.synthetic.demo_scenario import (
    CAP_M,
    DEFAULT_OUT,
    DemoConfig,
    MethodPlan,
    ScenarioLoop,
    ScenarioRun,
    plan_methods,
)
from slopedist.synthetic.scenarios import load_scenario
from slopedist.synthetic.sensors import (
    DEPTH_PIXEL_SIGMA,
    DEPTH_SCALE_SIGMA,
    IMU_PITCH_NOISE_RAD,
)
from slopedist.synthetic.sequence import SyntheticSequence

FloatArray = NDArray[np.float64]

SYNTHETIC_TRUTH_POINT = "vehicle centre"
"""The point of a vehicle the synthetic truth refers to, in words."""
SYNTHETIC_TRUTH_SHORT = f"the synthetic truth ({SYNTHETIC_TRUTH_POINT})"
SYNTHETIC_TRUTH = (
    f"{SYNTHETIC_TRUTH_SHORT}: camera z of the 3D box's bottom centre, KITTI's convention"
)
"""What the demo scores against, for its tables and ``results.json``."""

__all__ = [
    "DEFAULT_OUT",
    "DemoConfig",
    "DemoResult",
    "demo_jobs",
    "format_demo_tables",
    "iter_outputs",
    "plan_methods",
    "run_demo",
    "run_scenario",
    "scenario_folder",
    "theta_needed_rad",
]


def run_scenario(
    name: str,
    cfg: DemoConfig,
    method_names: list[str],
    bar: tqdm | None = None,
    plot: bool = True,
) -> tuple[ScenarioRun, list[MethodPlan], ScenarioPlots | None]:
    """Run every method on one scenario (see the module docstring). With ``cfg.plots``, the
    plots' inputs are returned, and the plots written here too when ``plot`` (False: the caller
    writes them with :func:`write_plots`, in another process if it likes)."""
    scenario = load_scenario(name)
    folder = scenario_folder(cfg.out_dir, scenario.name, name)
    folder.mkdir(parents=True, exist_ok=True)
    plans = plan_methods(method_names, scenario.camera.camera(), cfg.estimator)
    loop = ScenarioLoop(scenario, cfg, plans, folder)
    files = loop.run(bar)
    run = ScenarioRun(
        scenario.name,
        scenario.description.strip(),
        loop.n,
        loop.scores,
        loop.render_s,
        loop.odometry_s,
        loop.states,
        loop.theta_est,
        loop.theta_true[: loop.n],
        files,
    )
    methods = [p.name for p in loop.active]
    plots = plot_inputs(run, loop.seq, folder, methods, cfg.estimator) if cfg.plots else None
    if plots is not None and plot:
        run.files += write_plots(plots)
    return run, plans, plots


SAFE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]{0,99}")
"""A scenario name usable as a folder name: letters, digits, ``_``, ``-`` and ``.``, not
starting with ``.`` or ``-`` (so never ``.``, ``..`` or a hidden folder), at most 100 long."""


def scenario_folder(out_dir: Path, name: str, source: str | Path = "") -> Path:
    """The output folder of scenario ``name`` under ``out_dir``.

    Raises:
        ConfigurationError: a name that is not a plain folder name (``..``, ``/abs``, ``a/b``,
            a leading dot or dash, other characters): it would write outside ``out_dir``.
    """
    if not SAFE_NAME.fullmatch(name):
        where = f" (from {source})" if source and str(source) != name else ""
        raise ConfigurationError(
            f"scenario name {name!r}{where} cannot name an output folder: use letters, digits, "
            "'_', '-' and '.', not starting with '.' or '-', at most 100 characters"
        )
    return out_dir / name


@dataclass
class ScenarioPlots:
    """What the two plots of one scenario show (small arrays: cheap to send to a worker).

    Attributes:
        distance_path, theta_path: the PNG files.
        t_s: frame times, seconds; series: per target, distances vs truth (metres).
        theta_est, theta_true: θ of eq. 4 per frame, radians; targets: per target θ terms.
        adjustment: the paper's eq. 7 steps the methods ran with (its thresholds are drawn).
    """

    name: str
    distance_path: Path
    theta_path: Path
    t_s: FloatArray
    series: list[DistanceSeries]
    theta_est: FloatArray
    theta_true: FloatArray
    targets: list[TargetTheta]
    adjustment: GradientAdjustment


def plot_inputs(
    run: ScenarioRun,
    seq: SyntheticSequence,
    folder: Path,
    methods: list[str],
    estimator: EstimatorConfig,
) -> ScenarioPlots:
    """The distance vs truth and θ vs truth plots' data of one scenario (``estimator``: the
    methods' options, whose eq. 7 steps the θ plot draws)."""
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
                    b[f] = r in AT_CAP_REASONS
            est[name] = d
            below[name] = b
        series.append(DistanceSeries(int(tid), truth, est, below))
        # θ that would make eq. 1 exact for this target (exact box, true z), and the paper's
        needed = theta_needed_rad(seq.truth.box[: run.frames, m, 3], truth, cam)
        adj = np.full(run.frames, np.nan)
        dy = np.full(run.frames, np.nan)
        if "paper" in run.scores:
            s = run.scores["paper"]
            for f, tr, a, y in zip(s.frame, s.track, s.theta_adj, s.delta_y):
                if tr == tid:
                    adj[f], dy[f] = a, y
        theta_targets.append(TargetTheta(int(tid), needed, adj, dy))
    return ScenarioPlots(
        run.name,
        folder / "distance.png",
        folder / "theta.png",
        t,
        series,
        run.theta_est,
        run.theta_true,
        theta_targets,
        GradientAdjustment.from_degrees(estimator.alphas_deg, estimator.thresholds_px),
    )


def write_plots(plots: ScenarioPlots) -> list[str]:
    """Write the two plots of one scenario; returns their paths."""
    plot_distance_series(
        plots.distance_path,
        plots.t_s,
        plots.series,
        f"{plots.name}: distance against the synthetic truth ({SYNTHETIC_TRUTH_POINT})",
    )
    plot_theta_series(
        plots.theta_path,
        plots.t_s,
        plots.theta_est,
        plots.theta_true,
        plots.targets,
        f"{plots.name}: ego gradient θ against the true rotations; Δy and the eq. 7 steps",
        plots.adjustment,
    )
    return [str(plots.distance_path), str(plots.theta_path)]


def demo_jobs(cfg: DemoConfig) -> int:
    """Scenarios run at once (:attr:`DemoConfig.jobs`; None: usable cores, ≤ scenarios)."""
    if cfg.jobs is not None:
        return min(cfg.jobs, len(cfg.scenarios))
    return max(1, min(usable_cores(), len(cfg.scenarios)))


def _scenario_runs(
    cfg: DemoConfig, method_names: list[str], bar: tqdm, titles: list[str]
) -> Iterator[tuple[ScenarioRun, list[MethodPlan]]]:
    """Every scenario's run, in the order of ``cfg.scenarios`` (``titles``: their names for the
    progress bar); with more than one job, the scenarios run in worker processes (the bar then
    moves by whole scenarios), and each scenario's plots are written by a task of their own,
    queued when the scenario ends, so the workers stay busy while the last scenarios run. The
    runs' plot files are listed once every plot is written (after the last run is yielded)."""
    jobs = demo_jobs(cfg)
    if jobs == 1:
        for name, title in zip(cfg.scenarios, titles):
            bar.set_postfix_str(title)
            run, plans, _ = run_scenario(name, cfg, method_names, bar)
            yield run, plans
        return
    context = multiprocessing.get_context("spawn")  # no fork of a process with threads
    with ProcessPoolExecutor(jobs, mp_context=context) as pool:
        pending = {
            pool.submit(run_scenario, name, cfg, method_names, None, False): i
            for i, name in enumerate(cfg.scenarios)
        }
        finished: dict[int, tuple[ScenarioRun, list[MethodPlan]]] = {}
        plot_jobs: list[tuple[ScenarioRun, Future[list[str]]]] = []
        following = 0  # the next scenario to yield
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                run, plans, plots = future.result()
                finished[pending.pop(future)] = run, plans
                if plots is not None:
                    plot_jobs.append((run, pool.submit(write_plots, plots)))
            while following in finished:
                run, plans = finished.pop(following)
                following += 1
                bar.set_postfix_str(run.name)
                bar.update(run.frames)
                yield run, plans
        for run, job in plot_jobs:
            run.files += job.result()


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
    names = list(cfg.methods) if cfg.methods is not None else causal_methods()
    unknown = [m for m in names if m not in causal_methods()]
    if unknown:
        raise ConfigurationError(
            f"unknown or offline method(s) {', '.join(unknown)}; the demo runs causally, "
            f"choose from {', '.join(causal_methods())}"
        )
    scenarios = [load_scenario(s) for s in cfg.scenarios]  # fail early on a bad name or file
    folders = [scenario_folder(cfg.out_dir, sc.name, s) for s, sc in zip(cfg.scenarios, scenarios)]
    if len(set(folders)) < len(folders):
        raise ConfigurationError(
            "two scenarios share a name, so one would overwrite the other's outputs: "
            + ", ".join(sc.name for sc in scenarios)
        )
    cfg.out_dir.mkdir(parents=True, exist_ok=True)
    note = video_fallback_note() if cfg.video else None
    if note:
        echo(f"warning: {note}")
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
        for run, plans in _scenario_runs(cfg, names, bar, [sc.name for sc in scenarios]):
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


def pooled_scores(result: DemoResult) -> PooledScores:
    """Every method's scores per scenario and pooled over the scenarios (the methods that
    ran), behind Table 1 and the uncertainty table."""
    sets = {r.name: {m: r.scores[m].scored_set() for m in result.methods} for r in result.runs}
    return pool_methods(sets, result.methods)


def rmse_table(result: DemoResult, scores: PooledScores) -> Table:
    """Table 1: RMSE (m) per scenario × method, and each method pooled over the scenarios
    (``scores``: :func:`pooled_scores`)."""
    odo = (
        "the built-in visual odometry on the rendered frames"
        if result.config.odometry == "visual"
        else "the TRUE rotations (diagnostic, --odometry truth)"
    )
    title = (
        f"Table 1. RMSE (m) against {SYNTHETIC_TRUTH}; rotations from {odo}; noisy detector "
        f"boxes; estimates capped at {CAP_M:g} m, a box at or above the vanishing line counts "
        f"as {CAP_M:g} m"
    )
    table = score_tables.rmse_table(scores, title, row_label="scenario", key="rmse")
    empty = [r.name for r in result.runs if not any(len(s.truth) for s in r.scores.values())]
    if empty:  # a road without traffic, or targets never in view
        table.note += ("\n" if table.note else "") + (
            f"{', '.join(empty)}: no box in any frame (no target in the scenario or none in "
            "view): nothing to score, records.csv has no rows."
        )
    return table


def missing_table(result: DemoResult) -> Table:
    """Targets counted at the cap (at or near the vanishing line, or beyond what the image
    resolves: scored as 80 m) per scenario × method."""
    methods = result.methods
    rows: list[list[Any]] = [
        [r.name, *(r.scores[m].metrics()["below_horizon"] for m in methods)] for r in result.runs
    ]
    title = (
        f"Targets at or near the vanishing line (counted as {CAP_M:g} m against the synthetic "
        "truth)"
    )
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
    """Every table of the summary, in order (the first and the third are also CSV files; the
    last, how well the methods' own σ describes their errors, when a method reports one)."""
    scores = pooled_scores(result)
    tables = [rmse_table(result, scores), missing_table(result), timing_table(result)]
    sigma = score_tables.uncertainty_table(scores, truth=SYNTHETIC_TRUTH_SHORT)
    return [*tables, odometry_table(result), *([sigma] if sigma is not None else [])]


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
            "overlay_codec": video_codec() if result.config.video else None,
            "overlay_warning": video_fallback_note() if result.config.video else None,
        },
        "protocol": {
            "distance": SYNTHETIC_TRUTH,
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
