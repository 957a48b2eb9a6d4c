"""Refocus fixes (thesis §3.5): focus-fail detection, disparity clusters, averaging, flat scene."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phonestereo.errors import InputError, ShapeError
from phonestereo.fixes.refocus import (
    average_disparities,
    averaging_trials,
    cluster_disparities,
    detect_focus_failures,
    flat_scene_scale,
    sharpness,
)
from phonestereo.fixes.wt_scale import fit_wt_scale


def _board(n: int = 256, sq: int = 16) -> np.ndarray:
    return (np.indices((n, n)).sum(0) // sq % 2 * 200 + 30).astype(np.uint8)


def test_sharpness_ranks_blur_and_flags_the_missed_focus() -> None:
    board = _board()
    scores = [sharpness(cv2.GaussianBlur(board, (0, 0), s)) for s in (0.6, 0.7, 0.65, 3.0, 0.6)]
    # blur σ 3 px (a missed focus) loses > 90 % of the Laplacian variance; σ 0.6–0.7 px differ
    # by < 40 %, far from the 0.5 × median threshold
    verdicts = detect_focus_failures(scores)
    assert [v.failed for v in verdicts] == [False, False, False, True, False]
    assert verdicts[3].relative < 0.1 and "focus missed" in verdicts[3].reason
    assert all(v.reason == "" for i, v in enumerate(verdicts) if i != 3)


def test_sharpness_roi_and_bad_input() -> None:
    img = _board().astype(np.float64)
    img[:, 128:] = cv2.GaussianBlur(img, (0, 0), 4.0)[:, 128:]  # right half out of focus
    assert sharpness(img, (0, 0, 128, 256)) > 10 * sharpness(img, (128, 0, 128, 256))
    with pytest.raises(ShapeError):
        sharpness(np.zeros(10))
    with pytest.raises(InputError, match="roi"):
        sharpness(img, (300, 300, 10, 10))
    with pytest.raises(InputError):
        detect_focus_failures([])
    with pytest.raises(InputError):
        detect_focus_failures([1.0, 2.0], min_relative=1.5)


def test_cluster_disparities_one_label_per_depth() -> None:
    rng = np.random.default_rng(0)
    # charts at 1 m and 2 m (f·B = 18 px·m), 0.05 px matching noise; 3 outliers at 30 px
    d = np.r_[18 + 0.05 * rng.standard_normal(60), 9 + 0.05 * rng.standard_normal(200),
              30 + 0.1 * rng.standard_normal(3), np.nan]
    lab = cluster_disparities(d)
    assert (lab[:60] == 0).all() and (lab[60:260] == 1).all()
    assert (lab[260:] == -1).all()  # 3 members < MIN_POINTS, and the NaN
    assert (cluster_disparities(d, gap_px=50.0)[:263] == 0).all()  # one cluster when gaps tolerated
    assert (cluster_disparities([np.nan, np.nan]) == -1).all()


def test_averaging_shrinks_the_spread_like_sampling_without_replacement() -> None:
    rng = np.random.default_rng(1)
    M, K, sigma = 7, 400, 0.1
    d = 12.0 + sigma * rng.standard_normal((M, K))
    np.testing.assert_allclose(average_disparities(d), d.mean(0), atol=1e-12)
    np.testing.assert_allclose(average_disparities(d, [0, 2]), d[[0, 2]].mean(0), atol=1e-12)
    stds = {
        n: float(np.sqrt(np.mean(np.var(averaging_trials(d, n, 300, seed=2), axis=0))))
        for n in (1, 3, 5, 7)
    }
    for n in (1, 3, 5):
        # mean of n of the M attempts drawn without replacement: E[var] = σ²·(M − n) / (n·M);
        # 300 draws × 400 corners estimate its square root to a few per cent
        expect = sigma * np.sqrt((M - n) / (n * M))
        assert stds[n] == pytest.approx(expect, rel=0.06)
    assert stds[7] < 1e-12  # all 7 attempts: every draw is the same mean
    with pytest.raises(InputError):
        averaging_trials(d, 8)
    with pytest.raises(ShapeError):
        average_disparities(np.zeros(3))


def test_flat_scene_scale_removes_the_residual_distortion_bias() -> None:
    g = np.stack(np.meshgrid(np.linspace(20, 480, 21), np.linspace(20, 620, 25)), -1).reshape(-1, 2)
    c = np.array([244.0, 341.0])
    s_true = 1 - 8e-4  # tele scale of a refocus (tele → wide W-T scale is 1/s_true)
    u = (g - [12.0, 0.0]) - c
    rho2 = np.sum(u**2, 1, keepdims=True) / 400.0**2
    rng = np.random.default_rng(3)
    qt = c + s_true * u * (1 + 1e-3 * rho2) + 0.005 * rng.standard_normal(g.shape)
    plain = fit_wt_scale(g, qt, c)
    flat = flat_scene_scale(g, qt, c)
    # the e-only fit absorbs part of a 1e-3 radial term (0.3 px at the corners) as scale; the
    # flat-scene method does not: < 5e-6 (0.005 px noise over ±300 px: σ_s ≈ 1e-6; found 4e-7)
    assert abs(flat.wt.scale - 1 / s_true) < 5e-6
    assert abs(plain.scale - 1 / s_true) > 5e-5
    assert flat.ok and flat.inliers == len(g)
    assert flat.rms_residual_px < 0.5 * flat.rms_h_px
    np.testing.assert_allclose(
        flat.undistort_tele(qt[:3]), c + s_true * u[:3], atol=0.05
    )  # 0.05 px: noise + the small s·ρ² cross term
    assert flat.to_dict()["wt"]["ok"]
    few = flat_scene_scale(g[:4], qt[:4], c)
    assert not few.ok and "needs" in few.reason
