"""The per-view weights' χ² gate (calibration/view_weights.py)."""

from __future__ import annotations

import numpy as np

from phonestereo.calibration.bundle import Observations
from phonestereo.calibration.view_weights import view_weights


def _obs(sigmas: list[float], n: int, rng: np.random.Generator) -> tuple[np.ndarray, Observations]:
    """Residuals of len(sigmas) views of n corners each, view k with per-coordinate σ_k."""
    view = np.repeat(np.arange(len(sigmas)), n)
    res = rng.normal(size=(view.size, 2)) * np.asarray(sigmas)[view, None]
    z = np.zeros(view.size)
    obs = Observations(z.astype(int), view, np.zeros((view.size, 3)), res, z.astype(int))
    return res, obs


def test_views_alike_but_for_chance_keep_the_pooled_sigma() -> None:
    # 40 views of 54 corners with one σ: each view's own σ estimate errs by ~7 % (ν = 102),
    # which weights of their own would pass to the covariance. The gate at 99.7 % leaves
    # ~0.3 % of views reweighted by chance: over 40 views × 10 draws, ≤ 5 of 400 (expected 1.2,
    # measured 1).
    rng = np.random.default_rng(7)
    reweighted = 0
    for _ in range(10):
        res, obs = _obs([0.05] * 40, 54, rng)
        w = view_weights(res, np.ones(res.shape[0], bool), obs)
        reweighted += int(np.sum(np.abs(w[::54] - 1.0) > 1e-12))
    assert reweighted <= 5


def test_a_view_noisier_beyond_chance_gets_its_own_sigma() -> None:
    # the presets' ISP: far views err ~3× the near ones; 1.5× is already far beyond chance
    # at 54 corners (the χ² interval is ≈ 0.66-1.46 in σ² at ν = 102)
    rng = np.random.default_rng(8)
    sig = [0.015] * 9 + [0.045, 0.0225]
    res, obs = _obs(sig, 54, rng)
    w = view_weights(res, np.ones(res.shape[0], bool), obs)[::54]
    np.testing.assert_allclose(w[:9], 1.0)
    # the weight is σ_ref / σ_view from the view's own residuals: within ~3 × 7 % of the truth
    np.testing.assert_allclose(w[9:], [1 / 3, 1 / 1.5], rtol=0.2)
