"""``ok`` is a promise: a distance whose own 1σ is a large share of it is withheld.

Camera f = 720 px, c_y = 180 px, h = 1.65 m, image 1240 × 375 (as test_ours_border.py).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.estimators import make_estimator
from slopedist.estimators.base import FrameEstimates
from slopedist.io.detections.boxes import BoxTable
from slopedist.streaming.step import FrameStep

CAMERA = Camera(720.0, 620.0, 180.0, height_m=1.65).with_image_size(1240, 375)


def estimates(distance_m: list[float], sigma_m: list[float], status: list[str]) -> FrameEstimates:
    n = len(distance_m)
    return FrameEstimates(
        theta_rad=np.zeros(n),
        theta_adj_rad=np.zeros(n),
        delta_y_px=np.zeros(n),
        v_px=np.zeros(n),
        distance_m=np.array(distance_m, dtype=float),
        reason=np.array([""] * n, dtype=object),
        reference=np.array(["centre"] * n, dtype=object),
        status=np.array(status, dtype=object),
        extra={"sigma_m": np.array(sigma_m, dtype=float)},
    )


def test_ok_rows_with_a_sigma_over_the_share_become_missing() -> None:
    est = estimates(
        [20.0, 20.0, 20.0, 20.0, 30.0],
        [10.0, 10.5, np.nan, 50.0, 40.0],
        ["ok", "ok", "ok", "upper_bound", "ok"],
    )
    est.withhold_uncertain(0.5)
    assert est.status.tolist() == ["ok", "missing", "ok", "upper_bound", "missing"]
    assert est.reason.tolist() == ["", "too_uncertain", "", "", "too_uncertain"]
    np.testing.assert_array_equal(est.distance_m, [20.0, np.nan, 20.0, 20.0, np.nan])
    assert est.extra["sigma_m"][1] == 10.5  # the σ that says why stays


@given(
    st.lists(st.floats(0.1, 1e4), min_size=1, max_size=6),
    st.lists(st.floats(0.0, 1e5), min_size=6, max_size=6),
    st.floats(0.01, 10.0),
)
def test_what_stays_ok_keeps_within_the_share(
    distance: list[float], sigma: list[float], share: float
) -> None:
    est = estimates(distance, sigma[: len(distance)], ["ok"] * len(distance))
    est.withhold_uncertain(share)
    ok = est.status == "ok"
    assert np.all(est.extra["sigma_m"][ok] <= share * est.distance_m[ok])
    assert np.all(np.isnan(est.distance_m[~ok]))


def settled(boxes: list[list[float]], **options: object) -> FrameEstimates:
    step = FrameStep(make_estimator("ours", CAMERA, **options))
    return step.estimate(0, 0.0, 0.0, np.eye(3), BoxTable.build(np.zeros(len(boxes)), boxes))


def test_ours_withholds_a_box_of_a_few_pixels_whose_cues_contradict() -> None:
    """A 1.5 px box 120 rows below the horizon: its size says ~700 m, its ground contact ~10 m;
    ``ours`` has no confident number for it, while a car 20 m ahead stays ``ok``."""
    car_20m = [560.0, 180 + 720 * 1.65 / 20 - 720 * 1.53 / 20, 560 + 720 * 1.63 / 20]
    car_20m.append(180 + 720 * 1.65 / 20)
    est = settled([[600.0, 298.5, 601.5, 300.0], car_20m])
    assert est.status.tolist() == ["missing", "ok"]
    assert est.reason[0] == "too_uncertain" and np.isnan(est.distance_m[0])
    assert est.extra["sigma_m"][0] > 0.5 * est.extra["distance_size_m"][0]
    assert est.distance_m[1] == pytest.approx(20.0 + 3.88 / 2, rel=0.1)
    # without the share, a 2.5 px box whose cues contradict as much is ok; the 1.5 px box is
    # still withheld, by the resolution rule (under 2 px tall)
    loose = settled(
        [[600.0, 297.5, 602.5, 300.0], [600.0, 298.5, 601.5, 300.0]], max_relative_sigma=100.0
    )
    assert loose.status.tolist() == ["ok", "missing"]
    assert loose.reason[1] == "beyond_resolution"


def test_the_share_is_checked() -> None:
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ConfigurationError, match="max_relative_sigma"):
            make_estimator("ours", CAMERA, max_relative_sigma=bad)
