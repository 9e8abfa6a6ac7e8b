"""Box-noise model: jitter and scale statistics, misses, visibility, truncation, seeding."""

from __future__ import annotations

import numpy as np
import pytest

from slopedist.core.errors import ConfigurationError
from slopedist.synthetic.noise import BoxNoiseSpec, noisy_boxes

SIZE = (1242, 375)
BOX = np.array([[600.0, 150.0, 680.0, 210.0]])


def _draws(spec: BoxNoiseSpec, n: int = 4000, box: np.ndarray = BOX) -> np.ndarray:
    out = [noisy_boxes(box, [1.0], spec, SIZE, seed=3, frame=k)[0][0] for k in range(n)]
    return np.asarray(out)


def test_exact_spec_returns_the_boxes() -> None:
    out, found = noisy_boxes(BOX, [1.0], BoxNoiseSpec.exact(), SIZE, 1, 0)
    assert found.all()
    np.testing.assert_array_equal(out, BOX)


def test_jitter_and_scale_statistics() -> None:
    spec = BoxNoiseSpec(jitter_px=1.5, scale_sigma=0.0, miss_rate=0.0)
    d = _draws(spec) - BOX
    np.testing.assert_allclose(d.std(axis=0), 1.5, rtol=0.08)
    np.testing.assert_allclose(d.mean(axis=0), 0.0, atol=0.1)
    spec = BoxNoiseSpec(jitter_px=0.0, scale_sigma=0.05, miss_rate=0.0)
    d = _draws(spec)
    width = d[:, 2] - d[:, 0]
    height = d[:, 3] - d[:, 1]
    assert np.std(width / 80.0) == pytest.approx(0.05, rel=0.08)
    np.testing.assert_allclose(width / 80.0, height / 60.0, rtol=1e-9)  # one factor for both
    np.testing.assert_allclose(0.5 * (d[:, 0] + d[:, 2]), 640.0, atol=1e-9)  # about the centre


def test_miss_rate() -> None:
    spec = BoxNoiseSpec(miss_rate=0.2)
    found = [noisy_boxes(BOX, [1.0], spec, SIZE, 5, k)[1][0] for k in range(3000)]
    assert np.mean(found) == pytest.approx(0.8, abs=0.025)


def test_hidden_small_and_absent_targets_are_not_detected() -> None:
    boxes = np.array([BOX[0], BOX[0], [600.0, 150.0, 610.0, 155.0], [np.nan] * 4])
    out, found = noisy_boxes(boxes, [1.0, 0.1, 1.0, 0.0], BoxNoiseSpec.exact(), SIZE, 1, 0)
    assert found.tolist() == [True, False, False, False]
    assert np.isnan(out[1:]).all()


def test_truncation_clips_to_the_image() -> None:
    box = np.array([[1200.0, 300.0, 1241.0, 374.0]])
    spec = BoxNoiseSpec(jitter_px=5.0, truncate=True, miss_rate=0.0)
    d = _draws(spec, 300, box)
    assert d[:, 2].max() <= 1241.0 and d[:, 3].max() <= 374.0
    d = _draws(BoxNoiseSpec(jitter_px=5.0, truncate=False, miss_rate=0.0), 300, box)
    assert d[:, 2].max() > 1241.0


def test_noise_depends_only_on_seed_and_frame() -> None:
    spec = BoxNoiseSpec(jitter_px=2.0)
    a = noisy_boxes(BOX, [1.0], spec, SIZE, 9, 17)[0]
    b = noisy_boxes(BOX, [1.0], spec, SIZE, 9, 17)[0]
    c = noisy_boxes(BOX, [1.0], spec, SIZE, 9, 18)[0]
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    # a second target in view does not change the noise of the first
    two = noisy_boxes(np.vstack([BOX, BOX + 100]), [1.0, 1.0], spec, SIZE, 9, 17)[0]
    np.testing.assert_array_equal(two[0], a[0])


@pytest.mark.parametrize(
    "kwargs",
    [{"jitter_px": -1.0}, {"miss_rate": 1.5}, {"scale_sigma": float("nan")}, {"min_visible": 2.0}],
)
def test_invalid_noise_parameters(kwargs: dict) -> None:
    with pytest.raises(ConfigurationError):
        BoxNoiseSpec(**kwargs)
