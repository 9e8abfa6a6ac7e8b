"""Does following ``slopedist calibrate``'s mount advice ever make the evaluation worse?

On every shared KITTI tracking sequence (no images there: ORB-SLAM3 rotations stand in for the
built-in odometry) and for two box sources (the ground-truth label file as a user would pass it,
and PointRCNN detections with score ≥ 2), this script:

1. self-calibrates the mount with :func:`slopedist.mount_calibration.advise_mount`, starting from
   a configured mount (the *prior*);
2. replaces the model floor by a **leave-one-sequence-out** floor: the error against the known
   KITTI mount (h = 1.65 m, θ0 = 0°, the protocol's) that the fit and segment spread do not
   explain, i.e. the F with ``mean(e² / (max(fit, spread)² + F²)) = 1``
   (:func:`~slopedist.mount_calibration.calibrated_floor`), over the *other* sequences (both box
   sources, prior = the known mount), so no sequence's own truth decides its advice;
3. evaluates ``paper`` and ``ours`` (the KITTI protocol, the same box source) with the prior and
   with the advised mount, and checks that no sequence's RMSE worsens by more than 2 %.

Scenarios (priors): the known KITTI mount (1.65 m, 0°: any advice can only hurt, so the tool must
decline or stay harmless) and two wrong mounts (1.45 m, +1°; 1.85 m, −1°: advice should help).
The floor printed as "all sequences" is :data:`slopedist.mount_calibration.MODEL_FLOOR`'s source.

Usage::

    PYTHONPATH=src python benchmarks/calibrate_advice.py [--data ../shared/data/kitti_tracking]
        [--scenario known|all] [--json OUT]

Exit status 1 when, in the ``known`` scenario (the shared sequences as configured: issue 12's
check), a sequence's ``paper`` or ``ours`` worsens by more than 2 %. The wrong-mount scenarios are
reported, not checked: there the advice lowers ``paper``'s RMSE on most runs, but ``ours``, which
hardly depends on the mount, moves by a few per cent either way. Takes about 7 minutes (2 cores;
``--scenario known``: 2).
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from slopedist.camera import KITTI_CAMERA_HEIGHT_M
from slopedist.datasets.kitti_tracking import BoxSource, list_sequences
from slopedist.datasets.sequence_files import SequenceFiles, read_sequence_files
from slopedist.io.tables import write_json
from slopedist.kitti_eval import KittiEvalConfig, run_kitti_tracking
from slopedist.mount_calibration import (
    MountAdvice,
    MountSigma,
    advise_mount,
    calibrated_floor,
    judge_mount,
)

DEFAULT_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "kitti_tracking"
METHODS = ("paper", "ours")
TOLERANCE = 1.02
PRCNN_SCORE = 2.0
KNOWN = (KITTI_CAMERA_HEIGHT_M, 0.0)
SCENARIOS = {"known": KNOWN, "low": (1.45, 1.0), "high": (1.85, -1.0)}
"""Name → configured (prior) mount: height in metres, θ0 in degrees."""
SOURCES = {BoxSource.GT: ("label_02", None), BoxSource.POINTRCNN: ("pointrcnn_car", PRCNN_SCORE)}


@dataclass
class Case:
    """One sequence, box source and prior: the advice with no floor (decided again later)."""

    sequence: str
    source: BoxSource
    prior: tuple[float, float]
    raw: MountAdvice


def run_advice(root: Path, name: str, source: BoxSource, prior: tuple[float, float]) -> Case:
    folder, score = SOURCES[source]
    files = SequenceFiles(
        root / "calib" / f"{name}.txt",
        root / "orbslam3_poses" / f"{name}.txt",
        root / folder / f"{name}.txt",
        min_score=score,
        height_m=prior[0],
        mount_angle_rad=math.radians(prior[1]),
    )
    seq = read_sequence_files(files)
    raw = advise_mount(seq.camera, seq.track, seq.boxes, floor=MountSigma(0.0, 0.0))
    return Case(name, source, prior, raw)


def floor_from(cases: list[Case]) -> MountSigma:
    """The model floor of cases run with the known mount as prior (see the docstring)."""
    sig = [c.raw.fit.larger(c.raw.spread) for c in cases]
    mount = calibrated_floor(
        [c.raw.estimate.mount_angle_rad - math.radians(KNOWN[1]) for c in cases],
        [s.mount_angle_rad for s in sig],
    )
    height = calibrated_floor(
        [c.raw.estimate.height_m - KNOWN[0] for c in cases], [s.height_m for s in sig]
    )
    return MountSigma(mount, height)


def rmse(
    root: Path, name: str, source: BoxSource, height_m: float, mount_deg: float
) -> dict[str, float]:
    cfg = KittiEvalConfig(
        sequences=[name],
        methods=METHODS,
        boxes=source,
        min_score=SOURCES[source][1],
        height_m=height_m,
        mount_angle_rad=math.radians(mount_deg),
    )
    report = run_kitti_tracking(root, cfg).report()["methods"]
    return {m: float(report[m]["sequences"][name]["rmse"]) for m in METHODS}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--scenario", choices=("known", "all"), default="all")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    root: Path = args.data
    if not root.is_dir():
        print(f"no KITTI tracking data at {root}; nothing to check", file=sys.stderr)
        return 0
    names = list_sequences(root)
    scenarios = ["known"] if args.scenario == "known" else list(SCENARIOS)
    known_cases = [run_advice(root, n, s, KNOWN) for n in names for s in SOURCES]
    print(f"model floor over all sequences: {describe(floor_from(known_cases))}")
    failures: dict[str, int] = {}
    out: dict[str, Any] = {"floor_all": floor_from(known_cases).__dict__, "scenarios": {}}
    for scenario in scenarios:
        prior = SCENARIOS[scenario]
        cases = (
            known_cases
            if prior == KNOWN
            else [run_advice(root, n, s, prior) for n in names for s in SOURCES]
        )
        print(f"\nscenario {scenario}: configured h = {prior[0]} m, θ0 = {prior[1]:+g}°")
        print(
            f"{'seq':5} {'boxes':9} {'θ0 est':>14} {'h est':>15} {'advice':>16} "
            + " ".join(f"{m + ' before→after':>22}" for m in METHODS)
        )
        rows, failures[scenario] = [], 0
        for case in cases:
            others = [c for c in known_cases if c.sequence != case.sequence]
            advice = judge_mount(
                case.raw.estimate, case.raw.segments, case.raw.prior, floor_from(others)
            )
            row, bad = evaluate(root, case, advice)
            failures[scenario] += bad
            rows.append(row)
        out["scenarios"][scenario] = rows
        print(summary(rows))
    if args.json is not None:
        write_json(args.json, out)
    print(
        "\nsequence/method pairs worse by more than "
        f"{100 * (TOLERANCE - 1):.0f} %: {failures} (the check: scenario known)"
    )
    return 1 if failures["known"] else 0


def summary(rows: list[dict[str, Any]]) -> str:
    """Advised runs, runs better/worse by more than the tolerance and the mean RMSE per method."""
    advised = sum(
        1 for r in rows if r["advice"]["advise"]["mount_angle"] or r["advice"]["advise"]["height"]
    )
    parts = [f"advised {advised} of {len(rows)}"]
    for m in METHODS:
        before = [r["rmse_before"][m] for r in rows]
        after = [r["rmse_after"][m] for r in rows]
        better = sum(1 for b, a in zip(before, after) if a < b / TOLERANCE)
        worse = sum(1 for b, a in zip(before, after) if a > b * TOLERANCE)
        parts.append(
            f"{m}: {better} better, {worse} worse, mean RMSE "
            f"{sum(before) / len(before):.2f} → {sum(after) / len(after):.2f} m"
        )
    return "; ".join(parts)


def describe(s: MountSigma) -> str:
    return f"θ0 {math.degrees(s.mount_angle_rad):.2f}°, h {s.height_m:.3f} m"


def evaluate(root: Path, case: Case, advice: MountAdvice) -> tuple[dict[str, Any], int]:
    """Print and return one row: the advice and paper/ours before and after following it."""
    prior_h, prior_deg = case.prior
    before = rmse(root, case.sequence, case.source, prior_h, prior_deg)
    after = (
        before
        if advice.declined
        else rmse(
            root, case.sequence, case.source, advice.height_m, math.degrees(advice.mount_angle_rad)
        )
    )
    e, s = advice.estimate, advice.sigma
    use = (
        "declined"
        if advice.declined
        else (f"{math.degrees(advice.mount_angle_rad):+.2f}° {advice.height_m:.3f}m")
    )
    worse = [m for m in METHODS if after[m] > TOLERANCE * before[m]]
    print(
        f"{case.sequence:5} {case.source.value:9} "
        f"{math.degrees(e.mount_angle_rad):+6.2f}±{math.degrees(s.mount_angle_rad):.2f}° "
        f"{e.height_m:6.3f}±{s.height_m:.3f}m {use:>16} "
        + " ".join(
            f"{before[m]:9.2f}→{after[m]:6.2f}{' WORSE' if m in worse else '      '}"
            for m in METHODS
        )
    )
    row = {
        "sequence": case.sequence,
        "boxes": case.source.value,
        "advice": advice.as_dict(),
        "rmse_before": before,
        "rmse_after": after,
        "worse": worse,
    }
    return row, len(worse)


if __name__ == "__main__":
    sys.exit(main())
