"""``ours`` with a generic class: vans and trucks that a class-blind detector calls ``Car``."""

from __future__ import annotations

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.estimators import make_estimator
from slopedist.estimators.base import FrameInput
from slopedist.estimators.ours.class_table import ClassTable
from slopedist.estimators.ours.priors import CLASS_PRIORS, VEHICLE_TYPE_MIXTURE, yaw_grid
from slopedist.estimators.ours.vehicle_types import (
    NOT_THIS_TYPE_LOG_WEIGHT,
    type_log_var,
    type_moments,
    type_rows,
)
from slopedist.odometry.base import RotationTrack
from slopedist.streaming.step import estimate_sequence
from slopedist.synthetic.traffic import SimulatedTraffic, simulate_traffic

CAM = Camera(721.5, 609.6, 172.9, 1.65, 0.0)
ODD_TRAFFIC = {"Car": 0.6, "Van": 0.25, "Truck": 0.15}


def _estimates(sim: SimulatedTraffic, **options: object) -> tuple[np.ndarray, np.ndarray]:
    """``ours``' distance and ``sigma_m`` of every box, m (NaN where withheld)."""
    est = make_estimator("ours", CAM, **options)
    out, sigma = np.full(len(sim.boxes), np.nan), np.full(len(sim.boxes), np.nan)
    for k, t in enumerate(sim.timestamps_s):
        rows = np.flatnonzero(sim.boxes.frame == k)
        if rows.size:
            frame = FrameInput(k, float(t), 0.0, sim.boxes.select(rows), R_world_cam=np.eye(3))
            result = est.estimate(frame)
            out[rows], sigma[rows] = result.distance_m, result.extra["sigma_m"]
    assert np.isfinite(out).mean() > 0.97  # the rest withheld as too_uncertain
    return out, sigma


def _squared_errors(sim: SimulatedTraffic, **options: object) -> np.ndarray:
    return (_estimates(sim, **options)[0] - sim.z_m) ** 2


def test_a_generic_class_is_read_as_a_mixture_of_types() -> None:
    rows, log_w = type_rows(CLASS_PRIORS["Car"], VEHICLE_TYPE_MIXTURE, generic=True)
    assert [r[0] for r in rows] == [p.height_m for _, p, _ in VEHICLE_TYPE_MIXTURE]
    assert np.exp(log_w).sum() == pytest.approx(1.0) and log_w.argmax() == 0
    own, own_w = type_rows(CLASS_PRIORS["Van"], VEHICLE_TYPE_MIXTURE, generic=False)
    assert all(r == own[0] for r in own) and own[0][0] == CLASS_PRIORS["Van"].height_m
    assert own_w.tolist() == [0.0] + [NOT_THIS_TYPE_LOG_WEIGHT] * 3
    table = ClassTable(None, yaw_grid(), ("Car",))
    k = yaw_grid().size
    specific = table.gather(np.array(["Van", "Van"], dtype=object))
    assert specific.type_log_weight is None and specific.hypotheses.height_m.shape == (2, k)
    mixed = table.gather(np.array(["Car", "Van"], dtype=object))
    assert mixed.generic.tolist() == [True, False]
    assert mixed.hypotheses.height_m.shape == (2, 4 * k)
    assert mixed.hypotheses.height_m[0, ::k].tolist() == [r[0] for r in rows]
    assert (mixed.hypotheses.height_m[1] == CLASS_PRIORS["Van"].height_m).all()


def test_vans_and_trucks_called_car_are_far_less_wrong_read_as_a_generic_class() -> None:
    """Flat road, 0.5 px box noise, 12 vehicles (60 % cars, 25 % vans, 15 % trucks) over four
    seeds: read as a mixture of types, ``ours`` errs far less than taking ``Car`` at its word
    (no odd-object mode), and less than with the odd-object mode alone (which already helps:
    a near van far from a car's size is an odd object). The goal (within 10 % of the
    run with the true classes) is NOT met: a van at 40 m and a car at 28 m differ in their
    ground contact by less than a 1° road-gradient prior explains, so only near vehicles are
    told apart."""
    true_cls, strict, blind, generic = [], [], [], []
    for seed in range(4):
        kw = {"seed": seed, "box_noise_px": 0.5, "vehicle_types": ODD_TRAFFIC}
        labelled = simulate_traffic(CAM, 12, 150, label_types=True, **kw)
        called_car = simulate_traffic(CAM, 12, 150, **kw)
        assert np.array_equal(labelled.boxes.boxes, called_car.boxes.boxes)
        assert set(called_car.boxes.cls) == {"Car"} and len(set(labelled.boxes.cls)) >= 2
        true_cls.append(_squared_errors(labelled))
        strict.append(_squared_errors(called_car, odd_object_weight=0.0))
        blind.append(_squared_errors(called_car))
        generic.append(_squared_errors(called_car, generic_classes=("Car",)))
    runs = {"true": true_cls, "strict": strict, "blind": blind, "generic": generic}
    scored = np.all([np.isfinite(np.concatenate(v)) for v in runs.values()], axis=0)
    rmse = {k: float(np.sqrt(np.mean(np.concatenate(v)[scored]))) for k, v in runs.items()}
    assert rmse["generic"] < 0.8 * rmse["strict"]
    assert rmse["generic"] < rmse["blind"] < 0.95 * rmse["strict"]
    assert rmse["true"] < rmse["generic"]


def test_the_type_mixture_adds_the_published_vans_and_trucks_to_a_cars_size_spread() -> None:
    car = CLASS_PRIORS["Car"]
    moments = type_moments(car, VEHICLE_TYPE_MIXTURE)
    assert moments[0].tolist() == [0.0, 0.0, pytest.approx(np.log(28742 / 32836))]
    assert np.exp(moments[1:3, 0]) == pytest.approx([1.29, 1.80], abs=0.01)  # vans, trucks
    assert type_log_var(moments) == pytest.approx(0.0189, abs=5e-4)  # prior weights
    told_a_car = np.array([0.0, -50.0, -50.0, -50.0])  # the cues say: a car
    assert type_log_var(moments, told_a_car) == pytest.approx(0.0, abs=1e-12)
    assert type_log_var(moments, np.array([-50.0, 0.0, -50.0, -50.0])) > 0.25**2  # a van


def test_sigma_covers_vans_and_trucks_called_car_when_read_generic_for_sigma_only() -> None:
    """Class-blind traffic (60 % cars, 25 % vans, 15 % trucks, all called ``Car``; flat road,
    0.5 px box noise, two seeds): taking ``Car`` at its word, σ is the car's size spread and
    only about half the errors fall within 1σ (a Gaussian: 68 %). With ``generic_sigma_only``
    the published vehicle-type mix widens σ (not the distance, which stays identical): the
    1σ coverage is within 0.55–0.80 and more errors are within 2σ (0.80 against 0.76)."""
    blind_err, blind_sigma, wide_sigma = [], [], []
    for seed in range(2):
        kw = {"seed": seed, "box_noise_px": 0.5, "vehicle_types": ODD_TRAFFIC}
        sim = simulate_traffic(CAM, 12, 150, **kw)
        d, sigma = _estimates(sim)
        d_wide, sigma_wide = _estimates(sim, generic_classes=("Car",), generic_sigma_only=True)
        np.testing.assert_array_equal(d_wide, d)
        blind_err.append(np.abs(d - sim.z_m))
        blind_sigma.append(sigma)
        wide_sigma.append(sigma_wide)
    err, old, new = (np.concatenate(v) for v in (blind_err, blind_sigma, wide_sigma))
    ok = np.isfinite(err)
    assert np.all(new[ok] >= old[ok])
    assert np.mean(err[ok] <= old[ok]) < 0.55  # the old σ: too narrow
    assert 0.55 <= np.mean(err[ok] <= new[ok]) <= 0.80
    assert np.mean(err[ok] <= 2 * new[ok]) > np.mean(err[ok] <= 2 * old[ok]) + 0.025


def test_ours_offline_widens_only_its_sigma_for_a_generic_class_read_for_sigma_only() -> None:
    sim = simulate_traffic(CAM, 6, 60, seed=1, box_noise_px=0.5, vehicle_types=ODD_TRAFFIC)
    n = len(sim.timestamps_s)
    track = RotationTrack(sim.timestamps_s, np.repeat(np.eye(3)[None], n, 0), np.ones(n, bool))
    runs = [
        estimate_sequence(
            make_estimator("ours-offline", CAM, **opts), sim.boxes, sim.timestamps_s, track
        )
        for opts in ({}, {"generic_classes": ("Car",), "generic_sigma_only": True})
    ]
    plain, wide = (r.estimates for r in runs)
    np.testing.assert_array_equal(wide.distance_m, plain.distance_m)
    ok = np.isfinite(plain.distance_m)
    assert np.all(wide.extra["sigma_m"][ok] >= plain.extra["sigma_m"][ok])
    assert np.mean(wide.extra["sigma_m"][ok] > 1.05 * plain.extra["sigma_m"][ok]) > 0.3
