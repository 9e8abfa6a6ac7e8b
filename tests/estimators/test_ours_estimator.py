"""``ours`` as a whole: defaults, records, tracking, streaming == batch, no leaks, real data."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.estimators import ReferencePoint, available_methods, make_estimator
from slopedist.estimators.base import FrameInput, largest_implied_image
from slopedist.estimators.ours import EXTRA_COLUMNS, OursEstimator
from slopedist.estimators.ours.cues import project_box
from slopedist.estimators.ours.priors import YAW_GRID_DEG
from slopedist.io.detections.boxes import BoxTable, box_problems
from slopedist.odometry.base import RotationTrack
from slopedist.streaming.step import ego_gradients, estimate_sequence
from slopedist.synthetic.traffic import simulate_traffic

CAM = Camera(721.5, 609.6, 172.9, 1.65, 0.0)
CAR = np.array([1.53, 1.63, 3.88])


def _at_rest(n: int, period: float = 0.1) -> RotationTrack:
    t = np.arange(n) * period
    return RotationTrack.from_arrays(t, np.broadcast_to(np.eye(3), (n, 3, 3)))


def _frame(
    k: int, boxes: np.ndarray, ids: list[int] | None = None, theta: float = 0.0, cls: str = "Car"
) -> FrameInput:
    table = BoxTable.build(
        np.full(len(boxes), k), boxes, ids, classes=np.full(len(boxes), cls, dtype=object)
    )
    return FrameInput(k, 0.1 * k, theta, table, R_world_cam=np.eye(3))


def test_registered_and_built_with_defaults_only() -> None:
    assert "ours" in available_methods() and "ours-selfcal" in available_methods()
    est = make_estimator("ours", CAM)
    assert isinstance(est, OursEstimator) and est.name == "ours"
    assert not est.ablation.self_calibrate
    assert make_estimator("ours-selfcal", CAM).ablation.self_calibrate  # type: ignore[attr-defined]


def test_unknown_or_bad_options_fail_clearly() -> None:
    with pytest.raises(ConfigurationError, match="unknown option"):
        make_estimator("ours", CAM, speed_of_light=1.0)
    with pytest.raises(ConfigurationError, match="box_sigma_px"):
        make_estimator("ours", CAM, box_sigma_px=-1.0)


def test_single_box_record_is_complete_and_refers_to_the_centre() -> None:
    b = project_box(CAM.f, CAM.c_x, CAM.c_y, 1.65, 1.0, 25.0, 0.0, CAR)
    est = make_estimator("ours", CAM)
    out = est.estimate(_frame(0, b[None]))
    assert out.distance_m[0] == pytest.approx(25.0, rel=0.03)
    assert out.reference[0] == ReferencePoint.CENTRE.value
    assert out.reason[0] == ""
    assert set(EXTRA_COLUMNS) <= set(out.extra)
    face = out.extra["distance_nearest_face_m"][0]
    assert face == pytest.approx(25.0 - CAR[2] / 2, rel=0.03)
    assert 0 < out.extra["sigma_m"][0] < 5.0
    assert np.isnan(out.extra["speed_mps"][0])  # one frame: no speed yet
    assert out.theta_adj_rad[0] == pytest.approx(0.0, abs=math.radians(1.0))


def test_bad_boxes_are_missing_with_reasons_and_no_rotation_still_estimates() -> None:
    good = project_box(CAM.f, CAM.c_x, CAM.c_y, 1.65, 0.0, 20.0, 0.0, CAR)
    boxes = np.stack([good, [10, 10, 5, 20], [np.nan, 1, 2, 3]])
    out = make_estimator("ours", CAM).estimate(_frame(0, boxes, theta=math.nan))
    assert list(out.reason) == ["", "inverted_box", "non_finite_box"]
    assert out.distance_m[0] == pytest.approx(20.0, rel=0.05)
    assert np.isnan(out.distance_m[1:]).all()
    assert all(np.isnan(v[1:]).all() for v in out.extra.values())


def test_empty_frame_keeps_all_columns() -> None:
    out = make_estimator("ours", CAM).estimate(_frame(0, np.zeros((0, 4))))
    assert len(out) == 0 and set(EXTRA_COLUMNS) <= set(out.extra)


@pytest.mark.parametrize("with_ids", [True, False])
def test_tracking_gives_speed_and_ttc_of_simulated_traffic(with_ids: bool) -> None:
    sim = simulate_traffic(CAM, 6, 80, seed=1, box_noise_px=0.5, with_ids=with_ids)
    res = estimate_sequence(
        make_estimator("ours", CAM), sim.boxes, sim.timestamps_s, _at_rest(len(sim.timestamps_s))
    )
    e = res.estimates
    late = sim.boxes.frame >= 30
    speed_err = e.extra["speed_mps"][late] - sim.speed_mps[late]
    ok = np.isfinite(speed_err)
    assert ok.mean() > 0.9
    assert np.median(np.abs(speed_err[ok])) < 1.5
    z_err = np.abs(e.distance_m / sim.z_m - 1)
    assert np.median(z_err) < 0.08
    appr = late & (sim.speed_mps < -3) & np.isfinite(e.extra["ttc_s"])
    true_ttc = -sim.z_m[appr] / sim.speed_mps[appr]
    assert np.median(np.abs(e.extra["ttc_s"][appr] / true_ttc - 1)) < 0.25
    # one track per vehicle (id-less boxes are associated by IoU)
    uid = e.extra["track_uid"]
    n_tracks = sum(len(np.unique(uid[sim.vehicle == v])) for v in np.unique(sim.vehicle))
    assert n_tracks <= len(np.unique(sim.vehicle)) + 2


def test_streaming_equals_batch_with_empty_frames_and_gaps() -> None:
    sim = simulate_traffic(CAM, 5, 60, seed=2, box_noise_px=1.0, with_ids=False)
    # boxes in the image (a car beside the ego lies wholly left of any image the camera fits:
    # the estimator gives it a distance, the settled records outside_image)
    seen = box_problems(sim.boxes.boxes, largest_implied_image(CAM)) != "outside_image"
    boxes = sim.boxes.select(
        seen & ~np.isin(sim.boxes.frame, [10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 40])
    )
    n = len(sim.timestamps_s)
    track = _at_rest(n)
    for opts in (
        {},
        {
            "self_calibrate": True,
            "yaw_memory": True,
            "gradient_feedback": True,
            "adapt_box_noise": True,
            "adapt_contact_trust": True,
            "learn_contact_angle": True,
            "learn_horizon_jitter": True,
            "learn_contact_spread": True,
        },
    ):
        batch = estimate_sequence(OursEstimator(CAM, **opts), boxes, sim.timestamps_s, track)
        # the estimator itself, fed every frame (also those without boxes, which FrameStep
        # skips): tracks age by time, not by calls
        stream = OursEstimator(CAM, **opts)
        theta = ego_gradients(track)
        by_frame = boxes.frame_index()
        empty = boxes.select(np.zeros(len(boxes), dtype=bool))
        parts = []
        for k in range(n):
            t = float(track.timestamps_s[k])
            fb = by_frame.get(k, empty)
            out = stream.estimate(
                FrameInput(k, t, float(theta[k]), fb, R_world_cam=track.R_world_cam[k])
            )
            parts.append(out.distance_m)
            if k in by_frame:
                assert set(out.extra) == set(batch.estimates.extra)
        np.testing.assert_array_equal(np.concatenate(parts), batch.estimates.distance_m)
        # reset: the same sequence again gives the same numbers
        again = estimate_sequence(
            batch_est := OursEstimator(CAM, **opts), boxes, sim.timestamps_s, track
        )
        again2 = estimate_sequence(batch_est, boxes, sim.timestamps_s, track)
        np.testing.assert_array_equal(again.estimates.distance_m, again2.estimates.distance_m)


ABLATION_LIKE = [
    {
        "use_width": False,
        "yaw_hypotheses": False,
        "use_ground_contact": False,
        "motion_model": False,
    },
    {"use_ground_contact": False},
    {"motion_model": False, "occlusion_aware": False},
    {"gradient_feedback": True, "yaw_memory": True},
    {"atypical_height_weight": 0.1},
    {"adapt_box_noise": True, "censor_border_cuts": False},
    {"adapt_contact_trust": True},
    {"learn_contact_angle": True, "learn_horizon_jitter": True},
    {"learn_contact_spread": True},
]


@pytest.mark.parametrize("opts", ABLATION_LIKE)
@pytest.mark.parametrize("with_ids", [True, False])
def test_every_option_set_estimates_simulated_traffic(opts: dict, with_ids: bool) -> None:
    sim = simulate_traffic(CAM, 8, 40, seed=5, box_noise_px=0.3, with_ids=with_ids)
    res = estimate_sequence(
        OursEstimator(CAM, **opts), sim.boxes, sim.timestamps_s, _at_rest(len(sim.timestamps_s))
    )
    e = res.estimates
    assert np.all(np.isfinite(e.distance_m)) and np.all(np.isfinite(e.extra["sigma_m"]))
    assert np.median(np.abs(e.distance_m / sim.z_m - 1)) < 0.1
    assert np.all(e.extra["distance_nearest_face_m"] < e.distance_m)


def test_tracks_keep_their_state_by_name() -> None:
    est = OursEstimator(CAM)
    outs = _approach(est, 0, 5, 40.0, -5.0, 7, CAR)
    tr = est.tracks
    assert len(tr) == 1 and tr.box_track_id.tolist() == [7]
    assert tr.filter_rows.shape == (5, 1) and tr.last_box_px.shape == (4, 1)
    assert math.exp(tr.filter_rows[0, 0]) == pytest.approx(outs[-1].distance_m[0], rel=0.01)
    assert tr.n_updates[0] == 5 and tr.last_time_s[0] == pytest.approx(0.4)
    assert np.allclose(tr.R_world_cam[:, :, 0], np.eye(3))
    assert tr.log_heading_belief.shape == (len(YAW_GRID_DEG), 1)
    p00, p01, p11 = tr.filter_rows[2:, 0]
    assert np.all(np.linalg.eigvalsh([[p00, p01], [p01, p11]]) > 0)


def _approach(
    est: OursEstimator, k0: int, n: int, z0: float, speed: float, tid: int, dims: np.ndarray
) -> list:
    outs = []
    for k in range(k0, k0 + n):
        z = z0 + speed * 0.1 * (k - k0)
        b = project_box(CAM.f, CAM.c_x, CAM.c_y, 1.65, 0.5, z, 0.0, dims)
        outs.append(est.estimate(_frame(k, b[None], [tid])))
    return outs


@pytest.mark.parametrize("with_id", [True, False])
def test_a_lost_and_found_id_does_not_leak_state_between_vehicles(with_id: bool) -> None:
    """Vehicle A approaches fast, is lost for 2 s; vehicle B, with A's id (or in A's place),
    recedes slowly. B must start from the prior: no speed in its first frame, its own speed
    afterwards, a new track uid."""
    tid = 7 if with_id else -1
    est = OursEstimator(CAM)
    a = _approach(est, 0, 20, 40.0, -15.0, tid, CAR)
    b = _approach(est, 40, 20, 12.0, 2.0, tid, np.array([1.8, 1.9, 4.8]))
    assert a[-1].extra["speed_mps"][0] == pytest.approx(-15.0, abs=2.0)
    assert np.isnan(b[0].extra["speed_mps"][0])
    assert b[-1].extra["speed_mps"][0] == pytest.approx(2.0, abs=1.5)
    assert b[0].extra["track_uid"][0] != a[-1].extra["track_uid"][0]


def test_an_id_switch_within_the_track_age_is_caught_by_the_gate() -> None:
    est = OursEstimator(CAM)
    a = _approach(est, 0, 10, 15.0, 0.0, 3, CAR)
    b = _approach(est, 10, 5, 60.0, 0.0, 3, CAR)  # same id next frame, 45 m further
    assert b[0].extra["track_uid"][0] != a[-1].extra["track_uid"][0]
    assert b[0].distance_m[0] == pytest.approx(60.0, rel=0.1)
    assert np.isnan(b[0].extra["speed_mps"][0])


def test_box_touching_the_image_border_relies_on_the_other_cues() -> None:
    cam = Camera(721.5, 609.6, 172.9, 1.65, 0.0, image_width=1242, image_height=375)
    b = project_box(cam.f, cam.c_x, cam.c_y, 1.65, -1.0, 6.0, 0.0, CAR)
    cut = b.copy()
    cut[3] = 374.0  # bottom cut by the image border: the box height is wrong, the width not
    out = make_estimator("ours", cam).estimate(_frame(0, cut[None]))
    assert out.status[0] == "ok" and 0 < b[0] < b[2] < 1241
    naive = make_estimator("ours", cam, truncation_factor=1.0).estimate(_frame(0, cut[None]))
    assert abs(out.distance_m[0] - 6.0) < 0.5 * abs(naive.distance_m[0] - 6.0)
    # without the image size, the largest bottom edge seen beyond 2·c_y stands for the border
    guessed = make_estimator("ours", CAM).estimate(_frame(0, cut[None]))
    assert guessed.distance_m[0] == pytest.approx(out.distance_m[0])


@pytest.mark.parametrize(
    "x_m,z_m,side",
    [
        (10.5, 14.0, True),
        (-9.0, 12.0, True),
        (18.0, 22.0, True),
        (1.0, 5.0, False),
        (2.0, 7.0, False),
        (-3.0, 6.0, False),
    ],
)
def test_a_box_cut_by_the_border_bounds_the_distance(x_m: float, z_m: float, side: bool) -> None:
    # a car at the side of the image (its box cut by the left or right border) or right in
    # front (bottom cut): the cut size cue, and a cut bottom's ground contact, say "at least
    # this far", so the vehicle is at most that far; as bounds they must not pull it away
    cam = Camera(721.5, 609.6, 172.9, 1.65, 0.0, image_width=1242, image_height=375)
    b = project_box(cam.f, cam.c_x, cam.c_y, 1.65, x_m, z_m, 0.0, CAR)
    cut = b.copy()
    if side:
        cut[[0, 2]] = np.clip(cut[[0, 2]], 0.0, 1241.0)
    else:
        cut[3] = min(cut[3], 374.0)
    assert not np.allclose(cut, b), "the scene must cut the box"
    frame = _frame(0, cut[None])
    # with the image size, a box whose every cue is cut is an upper bound (at least the truth)
    stated = make_estimator("ours", cam).estimate(frame)
    # without it, the border the boxes reveal censors the same cues and the fused distance stays
    cam = CAM
    bounded = make_estimator("ours", cam).estimate(frame).distance_m[0]
    if stated.status[0] == "upper_bound":
        assert not side and cut[0] <= 1.0 and stated.distance_m[0] >= z_m
    else:
        assert stated.distance_m[0] == pytest.approx(bounded)
    soft = make_estimator("ours", cam, censor_border_cuts=False).estimate(frame).distance_m[0]
    naive = (
        make_estimator("ours", cam, censor_border_cuts=False, truncation_factor=1.0)
        .estimate(frame)
        .distance_m[0]
    )
    assert naive > 1.02 * z_m  # the cut cues taken at face value say too far
    assert abs(bounded - z_m) <= abs(soft - z_m) + 1e-9
    if side:  # the height cue is whole
        assert abs(bounded - z_m) < 0.05 * z_m
    else:  # only the width is whole (the heading is then loosely known); the ground
        # contact's bound is what helps
        assert abs(bounded - z_m) < 0.2 * z_m
        assert abs(bounded - z_m) < 0.7 * abs(soft - z_m)


def test_kitti_sequence_beats_paper(kitti_tracking_dir: Path) -> None:
    from slopedist.io.kitti.tracking import RotationSource, load_sequence, protocol_mask

    seq = load_sequence(kitti_tracking_dir, "0018")
    gt = seq.labels.select(protocol_mask(seq.labels))
    track = seq.rotations(RotationSource.ORBSLAM3)
    rmse = {}
    for m in ("paper", "ours"):
        r = estimate_sequence(make_estimator(m, seq.camera), gt, seq.timestamps_s, track)
        d = np.minimum(
            np.where(np.isfinite(r.estimates.distance_m), r.estimates.distance_m, 80.0), 80.0
        )
        rmse[m] = float(np.sqrt(np.mean((d - r.boxes.extra["z"]) ** 2)))
    assert rmse["ours"] < 0.5 * rmse["paper"]
    assert rmse["ours"] < 2.0
