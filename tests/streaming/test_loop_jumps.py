"""An odometry jump in ``slopedist run``: the per-frame log, the run summary and the overlay
say so, not that the odometry was ``ok``."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from slopedist.estimators import make_estimator
from slopedist.io.frames import open_frames
from slopedist.odometry.base import OdometryResult
from slopedist.streaming import loop as runner
from slopedist.streaming.config import RunConfig
from slopedist.streaming.loop import run_frames
from tests.streaming.test_loop import (
    CAM,
    ScriptedOdometry,
    boxes_every_frame,
    make_frames,
    read_csv,
    rot_x,
)

GLITCH_S = 0.8
"""The time of the frame whose rotation pitches 5° away and back (a one-frame glitch)."""


class GlitchingOdometry(ScriptedOdometry):
    """:class:`ScriptedOdometry` with a 5° pitch glitch at :data:`GLITCH_S`."""

    def process(
        self, image_gray: np.ndarray, timestamp_s: float, mask_boxes: np.ndarray | None = None
    ) -> OdometryResult:
        res = super().process(image_gray, timestamp_s, mask_boxes)
        if abs(timestamp_s - GLITCH_S) > 1e-9 or res.R_world_cam is None:
            return res
        glitch = rot_x(math.radians(5.0)) @ res.R_world_cam
        return OdometryResult(glitch, res.state, res.inliers, res.segment)


def test_a_jump_frame_is_odometry_jump_in_frames_csv_run_json_and_the_overlay(
    tmp_path: Path, monkeypatch
) -> None:
    heads: list[str] = []
    drawn = runner.draw_fig3_overlay

    def spy(*args, **kwargs):  # type: ignore[no-untyped-def]
        heads.append(args[5])
        return drawn(*args, **kwargs)

    monkeypatch.setattr(runner, "draw_fig3_overlay", spy)
    n = 12
    result = run_frames(
        open_frames(make_frames(tmp_path / "f", n)),
        boxes_every_frame(n),
        GlitchingOdometry(),
        make_estimator("paper", CAM),
        RunConfig(tmp_path / "out", overlay=tmp_path / "out" / "overlay", progress=False),
    )
    k = round(GLITCH_S / 0.1)
    frames = read_csv(tmp_path / "out" / "frames.csv")
    assert frames[k]["odometry_state"] == "odometry_jump" and frames[k]["theta_deg"] == ""
    assert {r["odometry_state"] for r in frames[1:] if r is not frames[k]} == {"ok"}
    records = [r for r in read_csv(tmp_path / "out" / "records.csv") if r["frame"] == str(k)]
    assert {r["reason"] for r in records} == {"odometry_jump"}
    expected = {"not_initialised": 1, "ok": n - 2, "odometry_jump": 1}
    assert result.odometry_states == expected
    summary = json.loads((tmp_path / "out" / "run.json").read_text())
    assert summary["odometry_states"] == expected
    assert "no rotation (odometry_jump)" in heads[k]
