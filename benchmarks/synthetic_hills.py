"""Synthetic hills: renderer speed, and where each method's error comes from.

Renders every scenario of the suite once (``SyntheticSequence.frame``: image, true depth, noisy
detector boxes) and prints:

1. Renderer speed: milliseconds per 1242×375 frame (image + true depth map + visibility of the
   targets), wall clock and process CPU time, best of ``--repeats`` passes over
   ``--speed-frames`` frames of each scenario (OpenCV limited to one thread); and the CPU time
   without the depth map (made only when asked for: ``Rendered.depth_m``).
2. RMSE (m, the demo's protocol: KITTI z, 80 m cap, a box at or above the vanishing line counts
   as 80 m) of ``flat``, ``ego`` and ``paper`` on the same noisy boxes with three rotation
   sources: the built-in visual odometry on the rendered frames (``vo``), the true rotations
   (``true``), and the true rotations inverted (``inv``: ``R_world_camᵀ``, i.e. world-to-camera
   matrices fed where the pipeline expects camera-to-world; for a pitch-only motion this flips
   the sign of θ in eq. 4). ``oracle`` is eq. 1 with, per target, the θ that makes it exact for
   the target's exact box (the best any choice of vanishing line can do with those boxes'
   noise).
3. Ego gradient θ (eq. 4) from the visual odometry against θ from the true rotations: RMS and
   largest error (degrees) and the frames where the odometry gave no rotation (the demo's
   odometry table).
4. Phases of ``target_steep_uphill`` (true rotations): RMSE per method when both vehicles are on
   the flat, when the target climbs while the ego is on the flat, while the ego goes through the
   sag, and when both are on the slope.

Usage::

    python benchmarks/synthetic_hills.py [--repeats 2] [--speed-frames 30]
"""

from __future__ import annotations

import argparse
import math
import time

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core import geometry as geo
from slopedist.estimators import make_estimator
from slopedist.estimators.base import FrameInput
from slopedist.evaluation.metrics import cap_estimates
from slopedist.odometry.base import RotationTrack, lookback_indices
from slopedist.odometry.visual import BuiltinVisualOdometry
from slopedist.streaming.step import ego_gradients
from slopedist.synthetic.demo import theta_needed_rad
from slopedist.synthetic.scenarios import SUITE, load_scenario
from slopedist.synthetic.sequence import SyntheticSequence

METHODS = ("flat", "ego", "paper")
SOURCES = ("vo", "true", "inv")


def render_speed(repeats: int, frames: int) -> None:
    print(
        "1. Renderer speed (image + true depth + visibility of the targets), ms per frame:"
        " wall clock and process CPU time (≈ wall time on an idle core), best of the passes;"
        " no_depth: CPU time when the depth map is not asked for"
    )
    print(f"{'scenario':>22s} {'wall':>7s} {'cpu':>7s} {'no_depth':>8s}")
    rows = []
    for name in SUITE:
        seq = SyntheticSequence(load_scenario(name))
        seq.render(0)
        best = [math.inf, math.inf, math.inf]
        for _ in range(repeats):
            for with_depth in (True, False):
                t0, c0 = time.perf_counter(), time.process_time()
                for k in range(frames):
                    r = seq.render(k)
                    seq.visible_share(k, r)
                    if with_depth:
                        _ = r.depth_m  # made on first access
                wall = (time.perf_counter() - t0) / frames
                cpu = (time.process_time() - c0) / frames
                if with_depth:
                    best[0], best[1] = min(best[0], wall), min(best[1], cpu)
                else:
                    best[2] = min(best[2], cpu)
        rows.append(best)
        print(f"{name:>22s} {1e3 * best[0]:7.1f} {1e3 * best[1]:7.1f} {1e3 * best[2]:8.1f}")
    m = 1e3 * np.mean(rows, axis=0)
    print(f"{'mean':>22s} {m[0]:7.1f} {m[1]:7.1f} {m[2]:8.1f}\n")


def _rmse(d: NDArray[np.float64], reason: NDArray[np.object_], z: NDArray[np.float64]) -> float:
    capped, ok = cap_estimates(d, reason, 80.0)
    return float(np.sqrt(np.mean((capped[ok] - z[ok]) ** 2))) if ok.any() else math.nan


def evaluate(name: str) -> dict[str, object]:
    seq = SyntheticSequence(load_scenario(name))
    cam = seq.camera
    n = len(seq)
    vo = BuiltinVisualOdometry(cam)
    R_vo = np.zeros((n, 3, 3))
    frames = []
    for k in range(n):
        f = seq.frame(k)
        res = vo.process(
            cv2.cvtColor(f.image, cv2.COLOR_BGR2GRAY), f.timestamp_s, f.detections.boxes
        )
        R_vo[k] = res.R_world_cam if res.R_world_cam is not None else np.nan
        frames.append(f.detections)
    t = seq.truth.timestamps_s
    R_true = seq.truth.poses_cam0()[:, :, :3]
    tracks = {"vo": R_vo, "true": R_true, "inv": np.swapaxes(R_true, 1, 2)}
    thetas = {
        s: ego_gradients(RotationTrack.from_arrays(t, R), cam.mount_angle_rad)
        for s, R in tracks.items()
    }
    out: dict[str, object] = {"theta": thetas}
    rows: dict[str, list] = {}
    for src in SOURCES:
        for m in METHODS:
            est = make_estimator(m, cam)
            d, reason, z, frame = [], [], [], []
            for k, boxes in enumerate(frames):
                e = est.estimate(FrameInput(k, float(t[k]), float(thetas[src][k]), boxes))
                idx = np.searchsorted(seq.truth.track_ids, boxes.track_id)
                d += e.distance_m.tolist()
                reason += list(e.reason)
                z += seq.truth.z_m[k, idx].tolist()
                frame += [k] * len(boxes)
            rows[f"{m}/{src}"] = [
                np.asarray(d),
                np.asarray(reason, dtype=object),
                np.asarray(z),
                np.asarray(frame),
            ]
    # oracle: per target the θ that makes eq. 1 exact for the exact box, applied to the noisy box
    d, reason, z, frame = [], [], [], []
    for k, boxes in enumerate(frames):
        idx = np.searchsorted(seq.truth.track_ids, boxes.track_id)
        need = theta_needed_rad(seq.truth.box[k, idx, 3], seq.truth.z_m[k, idx], cam)
        v = geo.vanishing_line_row(need, cam.f, cam.c_y)
        dd = geo.ground_contact_distance(cam.f, cam.height_m, boxes.boxes[:, 3], v)
        d += dd.tolist()
        reason += ["" if np.isfinite(x) else "below_horizon" for x in dd]
        z += seq.truth.z_m[k, idx].tolist()
        frame += [k] * len(boxes)
    rows["oracle"] = [
        np.asarray(d),
        np.asarray(reason, dtype=object),
        np.asarray(z),
        np.asarray(frame),
    ]
    out["rows"] = rows
    out["seq"] = seq
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--speed-frames", type=int, default=30)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    render_speed(args.repeats, args.speed_frames)

    print(
        "2. RMSE (m) by rotation source: vo = built-in visual odometry on the rendered frames,"
        " true = true rotations, inv = true rotations inverted (θ sign flipped)"
    )
    cols = [f"{m}/{s}" for s in SOURCES for m in METHODS] + ["oracle"]
    print(f"{'scenario':>20s} " + " ".join(f"{c:>10s}" for c in cols))
    results = {}
    for name in SUITE:
        res = evaluate(name)
        results[name] = res
        rows = res["rows"]
        assert isinstance(rows, dict)
        print(f"{name:>20s} " + " ".join(f"{_rmse(*rows[c][:3]):10.2f}" for c in cols))

    print("\n3. θ from the visual odometry against θ from the true rotations (degrees)")
    print(f"{'scenario':>20s} {'rms_err':>8s} {'max_err':>8s} {'lost':>5s} {'true_max':>8s}")
    for name, res in results.items():
        th = res["theta"]
        assert isinstance(th, dict)
        err = np.degrees(th["vo"] - th["true"])
        ok = np.isfinite(err)
        rms = float(np.sqrt(np.mean(err[ok] ** 2))) if ok.any() else math.nan
        mx = float(np.max(np.abs(err[ok]))) if ok.any() else math.nan
        print(
            f"{name:>20s} {rms:8.4f} {mx:8.4f} {int((~ok).sum()):5d} "
            f"{float(np.max(np.abs(np.degrees(th['true'])))):8.2f}"
        )

    print("\n4. target_steep_uphill by phase (true rotations), RMSE (m) and targets")
    res = results["target_steep_uphill"]
    seq = res["seq"]
    assert isinstance(seq, SyntheticSequence)
    rows = res["rows"]
    assert isinstance(rows, dict)
    tr = seq.truth
    ego_g = 100 * tr.ego_grade
    tgt_g = 100 * tr.target_grade[:, 0]
    lb = lookback_indices(tr.timestamps_s)
    ego_changing = np.abs(ego_g - ego_g[lb]) > 1.0
    phases = {
        "both on the flat": (ego_g < 1) & (tgt_g < 1),
        "target climbs, ego on the flat": (ego_g < 1) & (tgt_g >= 1) & ~ego_changing,
        "ego in the sag (pitching up)": ego_changing,
        "both on the slope": (ego_g >= 11) & ~ego_changing,
    }
    cols = [f"{m}/true" for m in METHODS] + ["oracle"]
    print(f"{'phase':>32s} {'frames':>6s} " + " ".join(f"{c:>10s}" for c in cols))
    for label, mask in phases.items():
        fr = rows[cols[0]][3]
        sel = mask[fr]
        vals = [_rmse(rows[c][0][sel], rows[c][1][sel], rows[c][2][sel]) for c in cols]
        print(f"{label:>32s} {int(mask.sum()):6d} " + " ".join(f"{v:10.2f}" for v in vals))


if __name__ == "__main__":
    main()
