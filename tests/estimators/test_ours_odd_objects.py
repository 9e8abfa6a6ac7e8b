"""``ours``'s odd-object mode and its per-track check: an object whose size is not its class's
(a low concrete block called ``Car``) on a flat road follows the ground contact."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.estimators.base import FrameEstimates, FrameInput
from slopedist.estimators.ours import OursEstimator
from slopedist.estimators.ours.cues import project_box
from slopedist.estimators.ours.fusion import ModeSpreads, SizeMode
from slopedist.estimators.ours.odd_objects import (
    MAX_EVIDENCE,
    MAX_LOG_ODDS,
    MAX_SHARE,
    MEMORY_S,
    PRIOR_COUNT,
    OddShare,
    frame_log_ratio,
    updated_evidence,
    with_evidence,
)
from slopedist.io.detections.boxes import BoxTable

CAM = Camera(721.5, 609.6, 172.9, 1.65, 0.0)
CAR = np.array([1.53, 1.63, 3.88])
BLOCK = np.array([0.8, 1.2, 2.0])
"""A low concrete block (height, width, length, m): about half a car's height."""


def _drive(est: OursEstimator, dims: np.ndarray, z_m: float, n: int) -> list[FrameEstimates]:
    """``n`` frames (10 Hz, flat road, camera at rest) of one object labelled ``Car`` whose
    centre stays ``z_m`` ahead, 0.5 m right of the camera."""
    box = project_box(CAM.f, CAM.c_x, CAM.c_y, CAM.height_m, 0.5, z_m, 0.0, dims)
    table = BoxTable.build(np.zeros(1), box[None], [4], classes=np.array(["Car"], dtype=object))
    outs = []
    for k in range(n):
        frame = FrameInput(k, 0.1 * k, 0.0, table.select(np.array([0])), R_world_cam=np.eye(3))
        frame.boxes.frame[:] = k
        outs.append(est.estimate(frame))
    return outs


def _face_error(out: FrameEstimates, dims: np.ndarray, z_m: float) -> float:
    """Relative error of the nearest-face distance (truth: the centre minus half the length)."""
    face = z_m - dims[2] / 2
    return float(out.extra["distance_nearest_face_m"][0] / face - 1.0)


def test_a_low_block_called_car_follows_the_ground_contact() -> None:
    """Taken at its class's size, a 0.8 m block reads 40 % too far (old behaviour: no odd-object
    mode); with the mode its size cue gives way and, as the track's evidence builds up, the
    distance is the ground contact's."""
    z = 10.0
    outs = _drive(OursEstimator(CAM), BLOCK, z, 30)
    strict = _drive(OursEstimator(CAM, odd_object_weight=0.0), BLOCK, z, 30)
    assert _face_error(strict[-1], BLOCK, z) > 0.3
    assert abs(_face_error(outs[-1], BLOCK, z)) < 0.06
    odd = [o.extra["odd_size_prob"][0] for o in outs]
    assert odd[0] > 0.5 and odd[-1] > 0.95 and odd[-1] > odd[0]  # the track's evidence adds up
    contact_face = outs[-1].extra["distance_ground_contact_m"][0] - CAR[2] / 2
    face = outs[-1].extra["distance_nearest_face_m"][0]
    assert face == pytest.approx(contact_face, rel=0.05)
    assert strict[-1].extra["odd_size_prob"][0] == 0.0


def test_a_car_stays_a_car() -> None:
    """A car of its class's size: the odd-object mode keeps a negligible weight and changes
    nothing."""
    outs = _drive(OursEstimator(CAM), CAR, 18.0, 30)
    strict = _drive(OursEstimator(CAM, odd_object_weight=0.0), CAR, 18.0, 30)
    assert max(o.extra["odd_size_prob"][0] for o in outs) < 0.01
    assert abs(_face_error(outs[-1], CAR, 18.0)) < 0.01
    assert outs[-1].distance_m[0] == pytest.approx(strict[-1].distance_m[0], rel=2e-3)


def test_without_tracks_each_frame_stands_alone() -> None:
    """With nothing carried over frames (no motion model), the odd-object weight is the
    frame's own: the same in every frame of a still scene."""
    est = OursEstimator(CAM, motion_model=False)
    odd = [o.extra["odd_size_prob"][0] for o in _drive(est, BLOCK, 10.0, 10)]
    assert odd[0] > 0.5 and np.allclose(odd, odd[0])


def test_mode_spreads() -> None:
    """Per mode: the class's spreads, the height's times the atypical factor, both at least
    the odd object's floor (the class's spreads come repeated over the modes, mode-major)."""
    sh, sw = np.array([[0.08, 0.2]]), np.array([[0.06, 0.7]])
    modes = [SizeMode(), SizeMode(height_factor=3.0), SizeMode(log_sigma_floor=0.5)]
    h, w = ModeSpreads(modes, 2).spreads(np.tile(sh, 3), np.tile(sw, 3))
    assert h.shape == w.shape == (1, 6)
    assert np.allclose(h[0], [0.08, 0.2, 0.24, 0.6, 0.5, 0.5])
    assert np.allclose(w[0], [0.06, 0.7, 0.06, 0.7, 0.5, 0.7])
    one_h, one_w = ModeSpreads(modes[2:], 2).spreads(sh, sw)
    assert np.allclose(one_h, [[0.5, 0.5]]) and np.allclose(one_w, [[0.5, 0.7]])
    typical_h, typical_w = ModeSpreads(modes[:1], 2).spreads(sh, sw)
    assert np.array_equal(typical_h, sh) and np.array_equal(typical_w, sw)
    assert modes[2].odd and not modes[1].odd
    assert ModeSpreads(modes, 2).odd == 2 and ModeSpreads(modes[:2], 2).odd is None


def test_frame_log_ratio_by_hand() -> None:
    """Two headings (prior 0.7, 0.3), three modes (typical 0.9, atypical 0.07, odd 0.03) and
    a track evidence of 1.5 nats: the frame's ratio read back from the odd mode's posterior is
    its likelihood over the others', each a prior-weighted mean over the headings."""
    pi_h = np.array([0.7, 0.3])
    pi_m = np.array([0.9, 0.07, 0.03])
    lik = np.array([[0.2, 0.1], [0.5, 0.05], [0.4, 0.3]])  # (modes, headings)
    per_mode = lik @ pi_h
    others = (pi_m[0] * per_mode[0] + pi_m[1] * per_mode[1]) / (pi_m[0] + pi_m[1])
    prior_odds = pi_m[2] / (1 - pi_m[2]) * math.exp(1.5)
    posterior_odds = prior_odds * per_mode[2] / others
    p = posterior_odds / (1 + posterior_odds)
    ratio = frame_log_ratio(np.array([p]), np.array([math.log(prior_odds)]))
    assert ratio[0] == pytest.approx(math.log(per_mode[2] / others))
    sure = frame_log_ratio(np.array([1.0, 0.0]), np.zeros(2))  # saturated: bounded
    assert sure.tolist() == [MAX_LOG_ODDS, -MAX_LOG_ODDS]


def test_evidence_update_and_prior() -> None:
    ev = updated_evidence(
        np.array([1.0, 2.0, 3.0]),
        np.array([4.0, np.nan, 4.0]),
        np.array([0.25, 1.0, 1.0]),
        np.array([False, False, True]),
    )
    assert ev.tolist() == [2.0, 2.0, 0.0]  # a NaN ratio adds nothing; a restart forgets
    capped = updated_evidence(np.array([19.0]), np.array([30.0]), np.ones(1), np.zeros(1, bool))
    assert capped.tolist() == [MAX_EVIDENCE]
    args = (np.array([1.0, 2.0]), np.array([4.0, np.nan]), np.array([0.25, 1.0]))
    no_restart = updated_evidence(*args, None)  # no track restarted: as all False
    assert no_restart.tolist() == updated_evidence(*args, np.zeros(2, bool)).tolist() == [2.0, 2.0]
    prior = np.zeros((2, 6))
    out = with_evidence(prior, np.array([1.0, -2.0]), 1, 3)
    assert out[:, :3].tolist() == [[0.0] * 3] * 2  # the typical mode's columns
    assert out[:, 3:].tolist() == [[1.0] * 3, [-2.0] * 3]  # the odd mode's
    assert prior.sum() == 0.0  # not changed in place


@pytest.mark.parametrize(
    "options",
    [{"odd_object_weight": 1.0}, {"odd_object_weight": -0.1}, {"odd_object_log_sigma": 0.0}],
)
def test_bad_odd_object_options_fail_clearly(options: dict) -> None:
    with pytest.raises(ConfigurationError, match="odd_object"):
        OursEstimator(CAM, **options)
    with pytest.raises(ConfigurationError, match="sum below 1"):
        OursEstimator(CAM, atypical_height_weight=0.5, odd_object_weight=0.5)


def test_the_odd_share_by_hand() -> None:
    """The drive's odd share: the configured weight before any target; then
    ``(n₀·w₀ + Σ c·p)/(n₀ + Σ c)`` with each target counting ``min(1, dt/τ)`` and the sums
    fading over the memory; NaN posteriors (no size cue) count nothing; bounded above."""
    w0 = 0.028
    share = OddShare(math.log(w0) - math.log1p(-w0))
    assert share.share == pytest.approx(w0) and share.log_odds_offset == pytest.approx(0.0)
    share.update(np.array([1.0, 1.0, np.nan]), 0.0)  # the first frame counts each target once
    n0 = PRIOR_COUNT
    assert share.share == pytest.approx((n0 * w0 + 2.0) / (n0 + 2.0))
    share.update(np.array([0.5]), 0.25)  # half a correlation time later: half a target each
    fade = math.exp(-0.25 / MEMORY_S)
    expected = (n0 * w0 + 2.0 * fade + 0.5 * 0.5) / (n0 + 2.0 * fade + 0.5)
    assert share.share == pytest.approx(expected)
    s = share.share
    assert share.log_odds_offset == pytest.approx(math.log(s / (1 - s)) - math.log(w0 / (1 - w0)))
    for k in range(1, 400):  # a drive of nothing but odd objects
        share.update(np.ones(4), 0.25 + 0.1 * k)
    assert share.share == MAX_SHARE
    share.reset()
    assert share.share == pytest.approx(w0)


def _blocks_then_one_more(
    est: OursEstimator, n_frames: int, sized_first: bool = False, sized_last: bool = False
) -> FrameEstimates:
    """Three low blocks called ``Car`` (10, 14 and 18 m ahead) for ``n_frames`` frames at
    10 Hz on a flat road, then a fourth (12 m) joins them: that frame's estimates.
    ``sized_first`` / ``sized_last``: the detector gives the first three's / the fourth's
    size (the block's, σ 10 %)."""
    z_m = [10.0, 14.0, 18.0, 12.0]
    x_m = [0.5, -3.0, 3.5, 4.0]
    boxes = np.array(
        [
            project_box(CAM.f, CAM.c_x, CAM.c_y, CAM.height_m, x, z, 0.0, BLOCK)
            for x, z in zip(x_m, z_m)
        ]
    )
    told = np.array([sized_first] * 3 + [sized_last])
    sizes = {
        name: np.where(told, BLOCK[k], np.nan)
        for k, name in enumerate(("height_m", "width_m", "length_m"))
    }
    out = None
    for k in range(n_frames + 1):
        n = 3 if k < n_frames else 4
        table = BoxTable.build(
            np.full(n, k),
            boxes[:n],
            np.arange(n),
            classes=np.array(["Car"] * n, dtype=object),
            **{name: v[:n] for name, v in sizes.items()},
        )
        out = est.estimate(FrameInput(k, 0.1 * k, 0.0, table, R_world_cam=np.eye(3)))
    assert out is not None
    return out


def test_a_drive_of_odd_boxes_raises_the_odd_share_for_its_next_target() -> None:
    """After 10 s of low blocks called ``Car`` the drive's learned odd share is far above the
    configured 2.8 %: a fourth block is read as odd from its first frame, and its distance is
    nearer its ground contact's than with the fixed weight (which takes its size at the class's
    word until its own track's evidence builds up)."""
    fixed = _blocks_then_one_more(OursEstimator(CAM, learn_odd_share=False), 100)
    learned = _blocks_then_one_more(OursEstimator(CAM), 100)
    assert learned.extra["odd_size_prob"][3] > fixed.extra["odd_size_prob"][3] + 0.1
    face = 12.0 - BLOCK[2] / 2
    err_fixed = abs(fixed.extra["distance_nearest_face_m"][3] / face - 1)
    err_learned = abs(learned.extra["distance_nearest_face_m"][3] / face - 1)
    assert err_learned < 0.7 * err_fixed


def test_a_drive_of_cars_keeps_the_odd_share_low() -> None:
    """Cars of their class's size: the learned share falls below the configured weight (a
    block joining after 10 s is read as odd a little less readily than with the fixed weight)
    and the cars' distances are the fixed weight's."""
    learned = OursEstimator(CAM)
    fixed = OursEstimator(CAM, learn_odd_share=False)
    outs, strict = _drive(learned, CAR, 18.0, 100), _drive(fixed, CAR, 18.0, 100)
    assert outs[-1].distance_m[0] == pytest.approx(strict[-1].distance_m[0], rel=1e-3)
    box = project_box(CAM.f, CAM.c_x, CAM.c_y, CAM.height_m, -3.0, 12.0, 0.0, BLOCK)
    table = BoxTable.build(np.full(1, 100), box[None], [9], classes=np.array(["Car"], dtype=object))
    joined = [
        est.estimate(FrameInput(100, 10.0, 0.0, table, R_world_cam=np.eye(3))).extra[
            "odd_size_prob"
        ][0]
        for est in (learned, fixed)
    ]
    assert joined[0] < joined[1]


def test_a_box_whose_detector_gives_its_size_has_no_odd_mode() -> None:
    """A size the detector measured is that vehicle's: its box is never read as an odd object
    (whatever the odd-object weight or the drive's share), and it neither takes the drive's
    share nor adds to it: 10 s of sized blocks leave the share at the configured weight for
    the next block, which 10 s of unsized blocks raise."""
    for sized_first, sized_last in ((False, True), (True, True)):
        learned = _blocks_then_one_more(OursEstimator(CAM), 100, sized_first, sized_last)
        without = _blocks_then_one_more(
            OursEstimator(CAM, odd_object_weight=0.0), 100, sized_first, sized_last
        )
        assert learned.extra["odd_size_prob"][3] < 1e-9
        assert learned.distance_m[3] == pytest.approx(without.distance_m[3], rel=1e-9)
    after_sized = _blocks_then_one_more(OursEstimator(CAM), 100, True, False)
    fixed = _blocks_then_one_more(OursEstimator(CAM, learn_odd_share=False), 100, True, False)
    assert after_sized.extra["odd_size_prob"][3] == pytest.approx(fixed.extra["odd_size_prob"][3])
    after_unsized = _blocks_then_one_more(OursEstimator(CAM), 100)
    assert after_unsized.extra["odd_size_prob"][3] > fixed.extra["odd_size_prob"][3] + 0.1
