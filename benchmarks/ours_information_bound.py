"""What the inputs can tell: an information bound for ``ours``.

Is there information in what ``ours`` is given — the boxes, their class, the calibration, the
camera rotations and metric ORB-SLAM3 poses, the tracks over time — that ``ours`` does not use,
enough to reach the targets set for it (pooled RMSE ≤ 2.6 m ground-truth boxes, ≤ 1.7 m
PointRCNN ≥ 2, ≤ 2.1 m RRC ≥ 0.5)? A learned correction answers it from above: a gradient-boosting
regressor (scikit-learn's ``HistGradientBoostingRegressor``, the ``learned`` extra) trained
**leave one sequence out** on ``log truth − log ours`` from features ``ours`` could compute
itself. If it stays above a figure, these inputs (as far as a flexible learner on 12 drives can
read them) do not hold what the figure needs; if it gets there, the features that carry it say
where a geometric change should look.

Same protocol as ``slopedist eval kitti-tracking`` (the scenes and runs of
``ours_detector_boxes.py``: Car/Van labels, truncated 0, occluded ≤ 1, 0 < z ≤ 80 m; detector
boxes matched by IoU ≥ 0.5; estimates capped at 80 m; ORB-SLAM3 rotations; shipped defaults).
Prints

1. Pooled RMSE (m) per box source: ``ours``, and ``ours`` corrected by the model trained on the
   other twelve sequences with (a) the row's own record columns and box geometry, (b) plus the
   causal track, frame and ego features (everything known at the row's frame), (c) plus whole-
   track features (an offline bound: the track's future too).
2. Per sequence, ``ours`` against the causal and offline corrections.
3. Which features matter: permutation importance (increase of the fold's pooled RMSE, m, when a
   feature group's columns are shuffled together; then the single features) on the two largest
   folds, causal model.
4. An oracle (cheating, labelled as such): per sequence the best of ``gradient_sigma_rad`` ∈
   {0.35°, 0.5°, 0.7°, 1°, 1.4°} × ``size_learning`` on/off — the best any setting of the
   existing model can do per drive; with the best single setting and the setting chosen leave
   one sequence out for comparison.

``ours``' runs are cached per sequence in ``/tmp/stack_cache`` (``--cache``; clear it after
changing ``ours``: the key is the box source, the options and the sequence, not the code).

Usage::

    python benchmarks/ours_information_bound.py [--data ../shared/data/kitti_tracking]
                                                [--sources gt,pointrcnn,rrc] [--skip 4]
"""

from __future__ import annotations

import argparse
import hashlib
import math
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from ours_detector_boxes import (
    CUE_COLUMNS,
    DEFAULT_DATA,
    ROTATION,
    Scene,
    Scored,
    rmse,
    run_ours_boxes,
    scenes,
)

from slopedist.evaluation.learned_peer import regressor_class
from slopedist.evaluation.table import format_table
from slopedist.io.kitti.tracking import BoxSource
from slopedist.odometry.base import LOOKBACK_S
from slopedist.streaming.step import ego_gradients

CAP_M = 80.0
FIGURES_M = {BoxSource.GT: 2.6, BoxSource.POINTRCNN: 1.7, BoxSource.RRC: 2.1}
"""The causal targets set for ``ours`` per box source (pooled RMSE, m)."""

RECORD_COLUMNS = (
    *CUE_COLUMNS,
    "sigma_m",
    "cue_gap_sigma",
    "odd_size_prob",
    "yaw_rad",
    "track_uid",
)

FEATURE_GROUPS: dict[str, tuple[str, ...]] = {
    "cues": (
        "log_ours",
        "log_size",
        "log_gc",
        "log_width",
        "log_sigma_rel",
        "gc_over_size",
        "cue_gap_sigma",
        "odd_size_prob",
        "abs_yaw",
        "is_van",
    ),
    "box": ("box_w", "box_h", "aspect", "bottom_below_horizon", "top_above_horizon", "centre_x"),
    "track": (
        "track_age_s",
        "track_count",
        "track_gc_mean",
        "track_gc_wmean",
        "track_gc_weight",
        "lateral_rate",
        "height_rate",
    ),
    "frame": ("frame_gc_median", "frame_count"),
    "ego": ("ego_speed_mps", "ego_yaw_rate", "ego_gradient"),
    "offline": ("whole_gc_mean", "whole_gc_wmean", "whole_gc_weight", "whole_count", "near_gc"),
}
CAUSAL = ("cues", "box", "track", "frame", "ego")
MODELS: dict[str, tuple[tuple[str, ...], bool]] = {
    "row": (("cues", "box"), False),
    "causal": (CAUSAL, False),
    "offline": ((*CAUSAL, "offline"), False),
    "causal strong-reg": (CAUSAL, True),
    "offline strong-reg": ((*CAUSAL, "offline"), True),
}
"""The corrections of section 1: the feature groups each model sees, and whether it is the
strongly regularised regressor (few leaves, many rows per leaf: less able to memorise a track
by its constant features)."""

GRID_DEG = (0.35, 0.5, 0.7, 1.0, 1.4)
"""Section 4's target-gradient spreads (degrees); the shipped default is 1°."""


def cached_run(scene: Scene, source: BoxSource, options: dict[str, Any], cache: Path) -> Scored:
    """:func:`run_ours_boxes` with the record columns, cached per (source, options, sequence)."""
    key = hashlib.sha1(repr(sorted(options.items())).encode()).hexdigest()[:10]
    path = cache / f"{source.value}_{scene.seq.name}_{key}.npz"
    if path.exists():
        z = np.load(path)
        extra = {k: z[k] for k in RECORD_COLUMNS}
        return Scored(z["distance_m"], z["ok"], extra)
    r = run_ours_boxes(scene, options, columns=RECORD_COLUMNS)
    cache.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, Any] = {"distance_m": r.distance_m, "ok": r.ok, **r.extra}
    np.savez(path, **arrays)
    return r


def ego_motion(scene: Scene) -> tuple[NDArray[np.float64], ...]:
    """Per frame: the ego's metric speed (m/s) and yaw rate (rad/s) from the ORB-SLAM3 poses
    (camera-to-world ``[R | t]``, backward differences: causal), and its gradient θ (rad)."""
    seq = scene.seq
    poses = np.loadtxt(seq.rotation_path(ROTATION)).reshape(-1, 3, 4)[: seq.n_frames]
    t = seq.timestamps_s[: len(poses)]
    dt = np.maximum(np.diff(t, prepend=t[0] - 0.1), 1e-3)
    step = np.diff(poses[:, :, 3], axis=0, prepend=poses[:1, :, 3])
    rel = np.einsum("nji,njk->nik", np.roll(poses[:, :, :3], 1, axis=0), poses[:, :, :3])
    rel[0] = np.eye(3)
    yaw = np.arctan2(rel[:, 0, 2], rel[:, 2, 2])  # rotation about the camera's y axis
    theta = ego_gradients(seq.rotations(ROTATION), seq.camera.mount_angle_rad, LOOKBACK_S)
    return np.linalg.norm(step, axis=1) / dt, yaw / dt, theta[: len(poses)]


def running_mean(
    values: NDArray[np.float64], weights: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The weighted mean of ``values`` over the rows so far (NaN values skipped) and the
    weight so far."""
    w = np.where(np.isfinite(values), weights, 0.0)
    cw = np.cumsum(w)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.cumsum(np.nan_to_num(values) * w) / cw, cw


def track_features(
    f: dict[str, NDArray[np.float64]], uid: NDArray[np.float64], frame: NDArray[np.intp]
) -> None:
    """The causal per-track columns and the whole-track (offline) ones, in place. The
    ground-contact-minus-size log ratio is weighted by (10 m / size distance)⁴, the inverse
    of the ground contact's variance, which grows as d²."""
    g = f["gc_over_size"]
    near_w = np.nan_to_num((10.0 / np.exp(f["log_size"])) ** 4)
    cx, h = f["centre_x"], f["box_h"]
    for key in (*FEATURE_GROUPS["track"], *FEATURE_GROUPS["offline"]):
        f[key] = np.full(len(g), np.nan)
    for u in np.unique(uid[np.isfinite(uid)]):
        rows = np.flatnonzero(uid == u)
        rows = rows[np.argsort(frame[rows], kind="stable")]
        fr = frame[rows].astype(float)
        f["track_age_s"][rows] = 0.1 * (fr - fr[0])
        f["track_count"][rows] = np.arange(1, rows.size + 1)
        f["track_gc_mean"][rows], _ = running_mean(g[rows], np.ones(rows.size))
        f["track_gc_wmean"][rows], f["track_gc_weight"][rows] = running_mean(g[rows], near_w[rows])
        gap = np.maximum(np.diff(fr, prepend=np.nan), 1.0) * 0.1
        f["lateral_rate"][rows] = np.diff(cx[rows], prepend=np.nan) / gap
        f["height_rate"][rows] = np.diff(np.log(h[rows]), prepend=np.nan) / gap
        last = rows.size - 1
        f["whole_gc_mean"][rows] = f["track_gc_mean"][rows][last]
        f["whole_gc_wmean"][rows] = f["track_gc_wmean"][rows][last]
        f["whole_gc_weight"][rows] = f["track_gc_weight"][rows][last]
        f["whole_count"][rows] = rows.size
        f["near_gc"][rows] = g[rows][int(np.nanargmin(f["log_size"][rows]))]


def frame_features(f: dict[str, NDArray[np.float64]], frame: NDArray[np.intp]) -> None:
    """Per row: the median ground-contact-minus-size log ratio of the *other* vehicles of its
    frame, and how many boxes the frame has, in place."""
    g = f["gc_over_size"]
    f["frame_gc_median"] = np.full(len(g), np.nan)
    f["frame_count"] = np.zeros(len(g))
    for fr in np.unique(frame):
        rows = np.flatnonzero(frame == fr)
        f["frame_count"][rows] = rows.size
        for i in rows:
            others = g[rows[rows != i]]
            others = others[np.isfinite(others)]
            if others.size:
                f["frame_gc_median"][i] = np.median(others)


def features(scene: Scene, r: Scored) -> dict[str, NDArray[np.float64]]:
    """Every feature of every fed box of a scene (NaN where a box has no value), from ``ours``'
    record columns, the box, its track (``ours``' own ``track_uid``), its frame and the ego."""
    cam, b = scene.seq.camera, scene.boxes
    frame = b.frame.astype(np.intp)
    speed, yaw_rate, theta = ego_motion(scene)
    th = theta[frame]
    horizon = cam.c_y - cam.f * np.tan(th)  # the vanishing line of the ego's road plane
    with np.errstate(invalid="ignore", divide="ignore"):
        log = {k: np.log(np.where(r.extra[k] > 0, r.extra[k], np.nan)) for k in CUE_COLUMNS}
        f = {
            "log_ours": np.log(r.distance_m),
            "log_size": log["distance_size_m"],
            "log_gc": log["distance_ground_contact_m"],
            "log_width": log["distance_width_m"],
            "log_sigma_rel": np.log(r.extra["sigma_m"] / r.distance_m),
            "gc_over_size": log["distance_ground_contact_m"] - log["distance_size_m"],
            "cue_gap_sigma": r.extra["cue_gap_sigma"],
            "odd_size_prob": r.extra["odd_size_prob"],
            "abs_yaw": np.abs(r.extra["yaw_rad"]),
            "is_van": (np.asarray(b.cls) == "Van").astype(float),
            "box_w": (b.boxes[:, 2] - b.boxes[:, 0]) / cam.f,
            "box_h": (b.boxes[:, 3] - b.boxes[:, 1]) / cam.f,
            "aspect": (b.boxes[:, 2] - b.boxes[:, 0]) / (b.boxes[:, 3] - b.boxes[:, 1]),
            "bottom_below_horizon": (b.boxes[:, 3] - horizon) / cam.f,
            "top_above_horizon": (horizon - b.boxes[:, 1]) / cam.f,
            "centre_x": ((b.boxes[:, 0] + b.boxes[:, 2]) / 2 - cam.c_x) / cam.f,
            "ego_speed_mps": speed[frame],
            "ego_yaw_rate": yaw_rate[frame],
            "ego_gradient": th,
        }
    track_features(f, r.extra["track_uid"], frame)
    frame_features(f, frame)
    return f


def collect(sc: dict[str, Scene], source: BoxSource, cache: Path) -> dict[str, NDArray[Any]]:
    """Every scored row of a source: ``seq``, ``truth`` (label z, m), ``ours`` (capped, m) and
    every feature."""
    parts = []
    for name, scene in sc.items():
        r = cached_run(scene, source, {}, cache)
        f = features(scene, r)
        det = scene.det_rows
        ok = r.ok[det]
        rows = det[ok]
        part = {k: v[rows] for k, v in f.items()}
        part["seq"] = np.full(rows.size, name)
        part["truth"] = scene.truth_m[ok]
        part["ours"] = r.distance_m[rows]
        parts.append(part)
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def feature_names(model: str) -> list[str]:
    return [c for g in MODELS[model][0] for c in FEATURE_GROUPS[g]]


def regressor(strong: bool = False) -> Any:
    """The correction model: fixed settings, lightly or (``strong``) strongly regularised; both
    set before looking at any result, none tuned on these data."""
    return regressor_class()(
        max_iter=100 if strong else 200,
        learning_rate=0.05 if strong else 0.08,
        max_leaf_nodes=7 if strong else 15,
        min_samples_leaf=400 if strong else 50,
        l2_regularization=1.0,
        early_stopping=False,
        random_state=0,
    )


def corrected(ours: NDArray[np.float64], log_correction: NDArray[np.float64]) -> Any:
    return np.minimum(ours * np.exp(log_correction), CAP_M)


def fit_fold(
    table: dict[str, NDArray[Any]], names: list[str], held: str | None, strong: bool = False
) -> Any:
    """The model trained on every sequence but ``held`` (all of them with None: in-sample), on
    ``log truth − log ours`` weighted by ours² (so that the log loss weighs rows as their
    metric error does)."""
    train = table["seq"] != held
    X = np.stack([table[c] for c in names], axis=1)
    y = np.log(table["truth"] / table["ours"])
    model = regressor(strong)
    model.fit(X[train], y[train], sample_weight=table["ours"][train] ** 2)
    return model


def loso(table: dict[str, NDArray[Any]], model: str) -> NDArray[np.float64]:
    """The corrected distance of every row, each sequence by the model that never saw it."""
    names = feature_names(model)
    X = np.stack([table[c] for c in names], axis=1)
    out = np.empty(len(X))
    for held in np.unique(table["seq"]):
        m = table["seq"] == held
        fitted = fit_fold(table, names, held, MODELS[model][1])
        out[m] = corrected(table["ours"][m], fitted.predict(X[m]))
    return out


def in_sample(table: dict[str, NDArray[Any]]) -> NDArray[np.float64]:
    """CHEATING: the causal model trained on every row, the scored ones included — how much
    of the error the features can describe at all, were their relation the same on every
    drive."""
    names = feature_names("causal")
    X = np.stack([table[c] for c in names], axis=1)
    return corrected(table["ours"], fit_fold(table, names, None).predict(X))


def section_bound(
    tables: dict[BoxSource, dict[str, NDArray[Any]]],
) -> dict[BoxSource, dict[str, NDArray[np.float64]]]:
    """Sections 1 and 2; returns the corrected distances per source and model."""
    print(
        "1. Pooled RMSE (m): ours and ours corrected by a model trained leave one sequence "
        "out on log truth - log ours (features: row = the row's record columns and box; "
        "causal = + its track so far, its frame, the ego; offline = + whole-track features)"
    )
    out: dict[BoxSource, dict[str, NDArray[np.float64]]] = {}
    rows = []
    for source, t in tables.items():
        out[source] = {m: loso(t, m) for m in MODELS}
        rows.append(
            [
                source.value,
                t["truth"].size,
                f"{rmse(t['ours'] - t['truth']):.3f}",
                *(f"{rmse(out[source][m] - t['truth']):.3f}" for m in MODELS),
                f"{rmse(in_sample(t) - t['truth']):.3f}",
                f"<= {FIGURES_M[source]}",
            ]
        )
    header = ["boxes", "n", "ours", *MODELS, "causal IN-SAMPLE (cheat)", "figure"]
    print(format_table(header, rows))
    print("   (every model column leave one sequence out)\n")
    print("2. Per sequence RMSE (m): ours / causal correction / offline correction")
    for source, t in tables.items():
        cells = []
        for s in np.unique(t["seq"]):
            m = t["seq"] == s
            e = [
                rmse(x - t["truth"][m])
                for x in (t["ours"][m], *(out[source][k][m] for k in MODELS))
            ]
            cells.append(f"{s} {e[0]:.2f}/{e[2]:.2f}/{e[3]:.2f}")
        print(f"   {source.value}: " + "  ".join(cells))
    print()
    return out


def fold_rmse(model: Any, X: NDArray[np.float64], t: dict[str, NDArray[Any]], m: Any) -> float:
    return rmse(corrected(t["ours"][m], model.predict(X)) - t["truth"][m])


def permuted_increase(
    model: Any,
    X: NDArray[np.float64],
    t: dict[str, NDArray[Any]],
    m: NDArray[np.bool_],
    columns: list[int],
    rng: np.random.Generator,
) -> float:
    """Mean increase of the held-out fold's RMSE (m) over 3 shuffles of ``columns`` together."""
    base = fold_rmse(model, X, t, m)
    rises = []
    for _ in range(3):
        Xp = X.copy()
        Xp[:, columns] = X[rng.permutation(len(X))][:, columns]
        rises.append(fold_rmse(model, Xp, t, m) - base)
    return float(np.mean(rises))


def section_importance(tables: dict[BoxSource, dict[str, NDArray[Any]]]) -> None:
    """Section 3: permutation importance of the causal model on the two largest folds."""
    names = feature_names("causal")
    groups = list(CAUSAL)
    print(
        "3. Permutation importance, causal model, two largest folds: RMSE increase (m) "
        "when a group's / a feature's columns are shuffled"
    )
    for source, t in tables.items():
        seqs, counts = np.unique(t["seq"], return_counts=True)
        X_all = np.stack([t[c] for c in names], axis=1)
        for held in seqs[np.argsort(-counts)[:2]]:
            m = t["seq"] == held
            model = fit_fold(t, names, held)
            X = X_all[m]
            rng = np.random.default_rng(0)
            by_group = {
                g: permuted_increase(
                    model, X, t, m, [names.index(c) for c in FEATURE_GROUPS[g]], rng
                )
                for g in groups
            }
            single = {c: permuted_increase(model, X, t, m, [i], rng) for i, c in enumerate(names)}
            top = sorted(single, key=lambda c: -single[c])[:6]
            base = fold_rmse(model, X, t, m)
            ours = rmse(t["ours"][m] - t["truth"][m])
            print(
                f"   {source.value} {held} (ours {ours:.2f}, corrected {base:.2f}): groups "
                + ", ".join(f"{g} {v:+.2f}" for g, v in by_group.items())
                + "; top features "
                + ", ".join(f"{c} {single[c]:+.2f}" for c in top)
            )
    print()


def grid() -> dict[str, dict[str, Any]]:
    """Section 4's settings: label -> ``ours`` options (as ``--ours-option KEY=VALUE``)."""
    return {
        f"{deg:g} deg{' +size' if learn else ''}": {
            "gradient_sigma_rad": math.radians(deg),
            "size_learning": learn,
        }
        for deg in GRID_DEG
        for learn in (False, True)
    }


SquaredErrors = dict[str, dict[str, tuple[float, int]]]
"""Per setting, per sequence: the sum of squared errors (m²) and the count."""


def pooled_choice(se: SquaredErrors, choice: dict[str, str]) -> float:
    """Pooled RMSE (m) with each sequence scored under the setting ``choice`` names."""
    sq = sum(se[c][s][0] for s, c in choice.items())
    return math.sqrt(sq / sum(se[c][s][1] for s, c in choice.items()))


def best_setting(se: SquaredErrors, seqs: Sequence[str]) -> str:
    """The setting with the lowest pooled RMSE over ``seqs``."""
    return min(se, key=lambda c: pooled_choice(se, same_setting(seqs, c)))


def same_setting(seqs: Sequence[str], setting: str) -> dict[str, str]:
    return dict.fromkeys(seqs, setting)


def best_on(se: SquaredErrors, seq: str) -> str:
    """The setting with the lowest error on ``seq`` itself (the oracle's choice)."""
    return min(se, key=lambda c: se[c][seq][0])


def sweep(sc: dict[str, Scene], source: BoxSource, cache: Path) -> SquaredErrors:
    """Every setting of :func:`grid` on every sequence of a source."""
    se: SquaredErrors = {}
    for label, options in grid().items():
        se[label] = {}
        for name, scene in sc.items():
            r = cached_run(scene, source, options, cache)
            ok = r.ok[scene.det_rows]
            e = r.distance_m[scene.det_rows][ok] - scene.truth_m[ok]
            se[label][name] = (float(np.sum(e * e)), int(e.size))
    return se


def section_oracle(by_source: dict[BoxSource, dict[str, Scene]], cache: Path) -> None:
    """Section 4: the oracle per-sequence setting, the best single setting, the LOSO choice."""
    print(
        "4. ORACLE (cheating: chosen on each sequence's own truth) per-sequence setting of "
        "gradient_sigma_rad x size_learning; pooled RMSE (m)"
    )
    rows = []
    for source, sc in by_source.items():
        se = sweep(sc, source, cache)
        names = list(sc)
        oracle = {s: best_on(se, s) for s in names}
        chosen = {s: best_setting(se, [o for o in names if o != s]) for s in names}
        single = best_setting(se, names)
        rows.append(
            [
                source.value,
                f"{pooled_choice(se, same_setting(names, '1 deg')):.3f}",
                f"{pooled_choice(se, same_setting(names, single)):.3f} ({single})",
                f"{pooled_choice(se, chosen):.3f}",
                f"{pooled_choice(se, oracle):.3f}",
                " ".join(f"{s}:{c}" for s, c in oracle.items()),
            ]
        )
    header = ["boxes", "default", "best single", "LOSO choice", "ORACLE", "oracle's choice"]
    print(format_table(header, rows) + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--sources", default="gt,pointrcnn,rrc")
    ap.add_argument("--skip", default="", help="comma-separated section numbers to skip")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/stack_cache"))
    args = ap.parse_args(argv)
    if not (args.data / "label_02").is_dir():
        print(f"KITTI tracking data not found at {args.data}; pass --data", file=sys.stderr)
        return 2
    # one OpenMP thread per fit: on a shared machine spinning threads cost far more than they give
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    regressor_class()  # scikit-learn, the learned extra, or one clear error
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    sources = [BoxSource(s.strip()) for s in args.sources.split(",") if s.strip()]
    t0 = time.perf_counter()
    by_source = {s: scenes(args.data, s) for s in sources}
    tables = {s: collect(by_source[s], s, args.cache) for s in sources}
    if not {"1", "2"} <= skip:
        section_bound(tables)
    if "3" not in skip:
        section_importance(tables)
    if "4" not in skip:
        section_oracle(by_source, args.cache)
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
