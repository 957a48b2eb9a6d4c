"""Signal-dependent noise level of a chessboard image (features.noise_level)."""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.features._image import noise_sigma
from phonestereo.features.noise_level import NoiseLevel, estimate_noise_level


def _board(square: int = 16, size: int = 256) -> np.ndarray:
    """A chessboard filling the image, 30 / 220 intensity, edges blurred over ~1 px."""
    import cv2

    y, x = np.mgrid[0:size, 0:size]
    img = np.where(((x // square) + (y // square)) % 2 == 0, 30.0, 220.0).astype(np.float32)
    return cv2.GaussianBlur(img, (0, 0), 0.8)


def test_shot_plus_read_noise_is_recovered() -> None:
    """σ² = 1 + 0.05·I (read + shot): black squares σ 1.6, white 3.5 DN. Both ends within
    10 % in σ (the fit sees two clusters of flat pixels, ~10 000 differences each)."""
    rng = np.random.default_rng(0)
    clean = _board()
    truth = NoiseLevel(1.0, 0.05)
    noisy = clean + rng.standard_normal(clean.shape) * np.sqrt(truth.variance(clean))
    est = estimate_noise_level(noisy.astype(np.float32))
    for level in (30.0, 220.0):
        assert np.sqrt(est.variance(level)) == pytest.approx(
            np.sqrt(truth.variance(level)), rel=0.1
        ), est


def test_constant_noise_on_an_edge_dense_board() -> None:
    """σ = 2 everywhere: the flat-area estimate is within 5 %, while the plain MAD of all
    differences (features._image.noise_sigma) is biased by the board's edges."""
    rng = np.random.default_rng(1)
    noisy = (_board() + rng.normal(0, 2.0, (256, 256))).astype(np.float32)
    est = estimate_noise_level(noisy)
    assert np.sqrt(est.variance(125.0)) == pytest.approx(2.0, rel=0.05)
    assert noise_sigma(noisy) > 1.1 * 2.0


def test_quantised_low_noise_is_not_zero() -> None:
    """σ = 0.6 DN rounded to integers: the median |difference| is 0 there, the estimate is
    not (quantisation adds 1/12 DN² → σ ≈ 0.66)."""
    rng = np.random.default_rng(2)
    noisy = np.rint(_board() + rng.normal(0, 0.6, (256, 256))).astype(np.float32)
    sigma = np.sqrt(estimate_noise_level(noisy).variance(125.0))
    assert 0.5 < sigma < 0.85


def test_pure_noise_without_a_board() -> None:
    rng = np.random.default_rng(3)
    est = estimate_noise_level(rng.normal(100, 3.0, (64, 64)).astype(np.float32))
    assert np.sqrt(est.variance(100.0)) == pytest.approx(3.0, rel=0.1)
