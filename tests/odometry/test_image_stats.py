"""Image statistics of the visual odometry: the sharpness measure computed as OpenCV does."""

from __future__ import annotations

import cv2
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from slopedist.odometry import image_stats


@settings(max_examples=60, deadline=None)
@given(
    arrays(
        np.int16,
        st.tuples(st.integers(1, 40), st.integers(1, 40)),
        elements=st.integers(-1020, 1020),
    )
)
def test_mean_std_is_opencvs_to_the_last_bit(values: np.ndarray) -> None:
    mean, std = cv2.meanStdDev(values)
    assert image_stats.mean_std(values) == (float(mean[0, 0]), float(std[0, 0]))


def test_gradient_energy_is_the_mean_squared_sobel_gradient_over_the_variance() -> None:
    rng = np.random.default_rng(3)
    image = cv2.GaussianBlur(rng.integers(0, 256, (120, 160), dtype=np.uint8), (0, 0), 1.5)
    small = image_stats.half_size(image)
    square_sum = 0.0
    for dx, dy in ((1, 0), (0, 1)):  # OpenCV's int16 Sobel and meanStdDev, as defined
        mean, std = cv2.meanStdDev(cv2.Sobel(small, cv2.CV_16S, dx, dy, ksize=3))
        square_sum += float(std[0, 0]) ** 2 + float(mean[0, 0]) ** 2
    expected = square_sum / max(float(cv2.meanStdDev(small)[1][0, 0]) ** 2, 1.0)
    assert image_stats.gradient_energy(image) == expected
    assert image_stats.gradient_energy(image, small=small) == expected
    flat = np.full((20, 20), 7, np.uint8)  # no gradient, no spread
    assert image_stats.gradient_energy(flat) == 0.0
