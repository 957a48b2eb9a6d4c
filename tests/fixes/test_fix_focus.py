"""Focus fixes (§3.5): scale/offset fits, median normalisation, W-T scale from e."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from phonestereo.fixes.focus import (
    ScaleOffset,
    fit_scale_offset,
    normalise_to_median,
)
from phonestereo.fixes.wt_scale import fit_wt_scale_per_cluster

C = np.array([1003.2, 748.9])


@settings(max_examples=40, deadline=None)
@given(
    s=st.floats(0.98, 1.02),
    ox=st.floats(-3, 3),
    oy=st.floats(-3, 3),
    seed=st.integers(0, 1000),
)
def test_scale_offset_recovered_exactly(s: float, ox: float, oy: float, seed: int) -> None:
    q = np.random.default_rng(seed).uniform(0, 2000, (50, 2))
    fit = fit_scale_offset(q, s * (q - C) + C + [ox, oy], C)
    # Noise-free linear data: the solve is exact to rounding (1e-9 relative).
    assert abs(fit.scale - s) < 1e-9
    assert np.allclose(fit.offset_px, [ox, oy], atol=1e-7)
    back = fit.inverse().apply(fit.apply(q))
    assert np.abs(back - q).max() < 1e-9


def test_scale_offset_robust_to_outliers_and_sigma_honest() -> None:
    rng = np.random.default_rng(3)
    q = rng.uniform(200, 1800, (400, 2))
    q_to = 1.0008 * (q - C) + C + [0.2, -0.1] + rng.normal(0, 0.05, q.shape)
    q_to[:20] += rng.uniform(5, 30, (20, 2))  # 5 % gross mismatches
    fit = fit_scale_offset(q, q_to, C)
    # 0.05 px noise over ±800 px: σ_s ≈ 0.05 / (460 · √800) ≈ 4e-6; allow 4σ plus robust loss.
    assert abs(fit.scale - 1.0008) < 4 * fit.sigma_scale + 2e-6
    assert 1e-6 < fit.sigma_scale < 2e-5


def test_too_few_points_is_a_result_not_an_error() -> None:
    fit = fit_scale_offset(np.zeros((3, 2)), np.zeros((3, 2)), C)
    assert not fit.ok and ">= 6" in fit.reason


def test_normalise_to_median_maps_every_attempt_to_the_median() -> None:
    q0 = np.random.default_rng(0).uniform(0, 2000, (30, 2))
    truths = [
        ScaleOffset(s, np.array(o), C)
        for s, o in [
            (1.0, [0, 0]),
            (1.0011, [0.3, 0.1]),
            (0.9994, [-0.2, 0.4]),
            (1.0003, [0.1, -0.1]),
        ]
    ]
    fits = [fit_scale_offset(q0, t.apply(q0), C) for t in truths]
    corr = normalise_to_median(fits)
    s_m = np.median([t.scale for t in truths])
    o_m = np.median([t.offset_px for t in truths], axis=0)
    target = s_m * (q0 - C) + C + o_m
    for t, k in zip(truths, corr, strict=True):
        assert np.abs(k.apply(t.apply(q0)) - target).max() < 1e-8


def test_wt_scale_per_cluster() -> None:
    rng = np.random.default_rng(5)
    c = np.array([480.0, 520.0])
    qw = rng.uniform([250, 250], [750, 750], (400, 2))
    lab = (qw[:, 0] > 500).astype(int)
    d = np.where(lab == 1, 6.0, 15.0)
    scales = {0: 1.0005, 1: 1.0023}
    qt = qw - np.column_stack([d, np.zeros(400)])
    for k, s in scales.items():
        m = lab == k
        qt[m] = (qt[m] - c) / s + c  # tele shrunk by 1/s: the fix scales by s
    qt[:, 1] += rng.normal(0, 0.02, 400)
    fits = fit_wt_scale_per_cluster(qw, qt, c, lab)
    for k, s in scales.items():
        # 0.02 px e noise over a ±125 px spread, 200 points: σ_s ≈ 1e-5.
        assert abs(fits[k].scale - s) < 5e-5, (k, fits[k])
        assert fits[k].rms_e_px < 0.03
