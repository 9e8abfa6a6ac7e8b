"""The learned peer: box features, leave-one-sequence-out fitting, determinism, the extra."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError, OptionalDependencyError
from slopedist.evaluation.learned_peer import (
    FEATURE_NAMES,
    PEER_METHOD,
    LeaveOneSequenceOut,
    PeerSamples,
    box_features,
    fit_peer,
)
from slopedist.io.detections.boxes import BoxTable

CAMERA = Camera(f=700.0, c_x=600.0, c_y=180.0)


def test_box_features_are_intrinsics_normalised_by_hand() -> None:
    boxes = BoxTable.build(
        [0, 0], [[530.0, 180.0, 670.0, 250.0], [600.0, 110.0, 635.0, 180.0]], classes=["Van", "Bus"]
    )
    x = box_features(boxes, CAMERA)
    assert x.shape == (2, len(FEATURE_NAMES))
    np.testing.assert_allclose(x[0], [-0.1, 0.0, 0.1, 0.1, 0.2, 0.1, 2.0, 1.0])
    np.testing.assert_allclose(x[1], [0.0, -0.1, 0.05, 0.0, 0.05, 0.1, 0.5, 2.0])
    twice_f = Camera(f=1400.0, c_x=600.0, c_y=180.0)
    scaled = BoxTable.build([0], [[460.0, 180.0, 740.0, 320.0]], classes=["car"])
    np.testing.assert_allclose(box_features(scaled, twice_f)[0, :7], x[0, :7])
    assert box_features(scaled, twice_f)[0, 7] == 0.0


def _car_samples(rng: np.random.Generator, n: int, scale: float = 1.0) -> PeerSamples:
    """Cars behind one another on a flat road seen by :data:`CAMERA`: box height f·1.5/z,
    bottom row c_y + f·1.65/z; ``scale`` multiplies the truth (a sequence that disagrees)."""
    z = rng.uniform(5.0, 60.0, n)
    x = rng.uniform(-4.0, 4.0, n)
    h, w = CAMERA.f * 1.5 / z, CAMERA.f * 1.6 / z
    bottom = CAMERA.c_y + CAMERA.f * 1.65 / z
    left = CAMERA.c_x + CAMERA.f * x / z - w / 2
    boxes = BoxTable.build(np.zeros(n), np.column_stack([left, bottom - h, left + w, bottom]))
    return PeerSamples(box_features(boxes, CAMERA), scale * z)


def test_each_sequence_is_predicted_by_a_model_that_never_saw_it() -> None:
    rng = np.random.default_rng(3)
    samples = {s: _car_samples(rng, 400) for s in ("a", "b")}
    samples["odd"] = _car_samples(rng, 400, scale=2.0)  # its truth is twice the geometry's
    peer = LeaveOneSequenceOut(samples)
    assert peer.training_sequences("odd") == ["a", "b"]
    err_a = peer.predict("a", samples["a"].features) - samples["a"].distance_m
    err_odd = peer.predict("odd", samples["odd"].features) - samples["odd"].distance_m
    # "a" is learned from "b" (same geometry) and "odd" (twice it): it lands between them
    assert np.sqrt(np.mean(err_odd**2)) > 15.0  # "odd"'s own truth was never seen
    assert np.mean(err_odd) < -15.0
    # learned from a and b only, odd is predicted at its geometric distance
    np.testing.assert_allclose(
        peer.predict("odd", samples["odd"].features),
        samples["odd"].distance_m / 2.0,
        rtol=0.15,
        atol=1.0,
    )
    assert np.mean(err_a) > 3.0


def test_the_peer_is_deterministic() -> None:
    rng = np.random.default_rng(5)
    samples = {s: _car_samples(rng, 300) for s in ("a", "b", "c")}
    first = LeaveOneSequenceOut(samples).predict("c", samples["c"].features)
    second = LeaveOneSequenceOut(samples).predict("c", samples["c"].features)
    np.testing.assert_array_equal(first, second)


def test_unusable_rows_are_left_out_and_non_finite_features_give_nan() -> None:
    rng = np.random.default_rng(7)
    s = _car_samples(rng, 200)
    x = s.features.copy()
    x[0, 6] = np.nan
    y = s.distance_m.copy()
    y[1] = -1.0
    model = fit_peer(x, y)
    assert np.isfinite(model.predict(x[2:3])).all()
    peer = LeaveOneSequenceOut({"a": PeerSamples(x, y), "b": s})
    out = peer.predict("b", x[:3])
    assert np.isnan(out[0]) and np.isfinite(out[1:]).all()


def test_no_training_pair_is_a_configuration_error() -> None:
    with pytest.raises(ConfigurationError, match="no usable training pair"):
        fit_peer(np.full((3, len(FEATURE_NAMES)), np.nan), np.ones(3))
    rng = np.random.default_rng(1)
    only = LeaveOneSequenceOut({"a": _car_samples(rng, 50)})
    with pytest.raises(ConfigurationError, match="no other sequence"):
        only.model("a")


def test_a_sequence_without_a_usable_pair_is_not_a_training_sequence() -> None:
    """A drive whose matched boxes all lack a usable truth (no labelled vehicle in range) does
    not count: the other drive then has nothing to train on and its peer row is missing,
    instead of a fit on zero rows stopping the whole evaluation."""
    rng = np.random.default_rng(4)
    good = _car_samples(rng, 60)
    unusable = PeerSamples(good.features[:5], np.full(5, np.nan))
    peer = LeaveOneSequenceOut(
        {
            "empty": unusable,
            "none": PeerSamples(good.features[:0], good.distance_m[:0]),
            "b": good,
        }
    )
    assert unusable.usable == 0 and good.usable == 60
    assert peer.training_sequences("b") == []
    assert peer.training_sequences("empty") == ["b"]
    with pytest.raises(ConfigurationError, match="no other sequence"):
        peer.model("b")


def test_without_scikit_learn_the_error_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "sklearn.ensemble", None)
    rng = np.random.default_rng(2)
    s = _car_samples(rng, 50)
    with pytest.raises(OptionalDependencyError, match=r"slopedist\[learned\]"):
        fit_peer(s.features, s.distance_m)


@pytest.mark.kitti
def test_the_peer_row_on_kitti_tracking_is_trained_leave_one_sequence_out(
    kitti_tracking_dir: Path,
) -> None:
    from slopedist.evaluation.kitti import KittiEvalConfig, learned_peer, run_kitti_tracking

    cfg = KittiEvalConfig(sequences=["0003"], methods=("flat", PEER_METHOD))
    evaluation = run_kitti_tracking(kitti_tracking_dir, cfg)
    report = evaluation.report()
    peer_row = report["methods"][PEER_METHOD]["overall"]
    assert peer_row["n"] == report["methods"]["flat"]["overall"]["n"] > 0
    assert peer_row["rmse"] < report["methods"]["flat"]["overall"]["rmse"]
    assert "leave-one-sequence-out" in report["protocol"]["learned_peer"]
    assert report["protocol"]["rotation_per_method"][PEER_METHOD] is None
    peer = learned_peer(kitti_tracking_dir, cfg)
    assert "0003" not in peer.training_sequences("0003")
    assert len(peer.training_sequences("0003")) == len(peer.samples) - 1 >= 12
