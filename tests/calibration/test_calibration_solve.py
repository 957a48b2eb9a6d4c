"""Calibration bundle: analytic Jacobian, recovery of known truth, OpenCV on the same corners."""

from __future__ import annotations

import glob
from pathlib import Path

import cv2
import numpy as np
import pytest

from phonestereo.calibration.bundle import Layout, residuals_and_jacobian
from phonestereo.calibration.solve import (
    CHI2_2DOF_997,
    CalibrationOptions,
    _observations,
    calibrate_camera,
    calibrate_stereo,
    trimmed_noise_variance,
)
from phonestereo.calibration.views import BoardView, chessboard_object_points
from phonestereo.errors import InputError
from phonestereo.geometry import Camera, Transform, make_lens

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "opencv_stereo"


def _true_rig(model: str = "opencv5") -> tuple[Camera, Camera, Transform]:
    coeffs = {
        "opencv5": (-0.12, 0.05, 4e-4, -3e-4, -0.01),
        "radial-odd": (0.003, -0.1, 0.02, 0.03, 0.0, 0.0, 4e-4, -3e-4),
    }[model]
    wide = Camera((1000, 750), 800.0, 801.0, 505.0, 371.0, make_lens(model, coeffs))
    tele = Camera((1000, 750), 1600.0, 1602.0, 497.0, 380.0, make_lens(model, coeffs))
    rel = Transform.from_rotvec([0.002, -0.004, 0.003], [0.0005, -0.012, 0.0015])
    return wide, tele, rel


def _views(
    cam: Camera, poses: list[Transform], obj: np.ndarray, rng: np.random.Generator, sigma: float
) -> list[BoardView | None]:
    out: list[BoardView | None] = []
    for i, T in enumerate(poses):
        q = cam.project(T.apply(obj))
        ok = cam.contains(q, margin=2)
        if ok.sum() < 12:
            out.append(None)
            continue
        q = q + rng.normal(0, sigma, q.shape)
        out.append(BoardView(obj[ok], q[ok], np.flatnonzero(ok), f"v{i}"))
    return out


def _board_poses(rng: np.random.Generator, n: int, dist: float) -> list[Transform]:
    poses = []
    for _ in range(n):
        rv = rng.normal(0, 0.35, 3) * [1, 1, 0.3]
        t = np.array(
            [rng.uniform(-0.12, 0.02), rng.uniform(-0.1, 0.0), dist * rng.uniform(0.8, 1.3)]
        )
        poses.append(Transform.from_rotvec(rv, t))
    return poses


def test_analytic_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(3)
    wide, tele, rel = _true_rig("radial-odd")
    obj = chessboard_object_points((8, 6), 0.02)
    poses = _board_poses(rng, 3, 0.5)
    obs = _observations([_views(wide, poses, obj, rng, 0.0), _views(tele, poses, obj, rng, 0.0)])
    layout = Layout((wide.lens, tele.lens), (wide.size, tele.size), 3, stereo=True)
    x = layout.pack((wide, tele), rel, tuple(poses))
    _, jac = residuals_and_jacobian(x, layout, obs)
    assert jac is not None
    num = np.empty((jac.shape[0], x.size))
    for k in range(x.size):
        h = 1e-6 * max(1.0, abs(x[k]))
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        rp = residuals_and_jacobian(xp, layout, obs, with_jacobian=False)[0]
        rm = residuals_and_jacobian(xm, layout, obs, with_jacobian=False)[0]
        num[:, k] = (rp - rm) / (2 * h)
    # central differences are good to ~1e-6 relative here; the analytic one must agree.
    scale = np.abs(num).max(axis=0) + 1e-9
    assert np.max(np.abs(jac.toarray() - num) / scale) < 1e-5


@pytest.mark.parametrize("seed", [0, 1])
def test_stereo_recovers_truth_within_its_covariance(seed: int) -> None:
    rng = np.random.default_rng(seed)
    wide, tele, rel = _true_rig()
    obj = chessboard_object_points((12, 9), 0.015)
    poses = _board_poses(rng, 12, 0.45)
    sigma = 0.1
    wv = _views(wide, poses, obj, rng, sigma)
    tv = _views(tele, [rel @ T for T in poses], obj, rng, sigma)
    res = calibrate_stereo(
        wv, tv, (wide.size, tele.size), CalibrationOptions(reject_outliers=False)
    )
    truth = Layout((wide.lens, tele.lens), (wide.size, tele.size), len(poses), True).pack(
        (wide, tele), rel, tuple(poses)
    )
    z = (res.parameters - truth) / np.sqrt(np.diag(res.covariance))
    # Normal errors: with ~100 parameters, |z| > 4.5 has probability < 1e-3 overall.
    assert np.max(np.abs(z[: res.parameters.size])) < 4.5, np.max(np.abs(z))
    # The fitted noise equals the injected one (per coordinate), within 5 %.
    assert res.rms_px_per_coordinate == pytest.approx(sigma, rel=0.05)
    assert np.linalg.norm(res.T_tele_wide.t - rel.t) < 2e-4  # metres, i.e. 0.2 mm of 12 mm
    # The baseline's σ: first-order propagation equals the spread of |t| over draws from the
    # covariance (σ_t / |t| ~ 1e-3, so the norm is linear to ~1e-6); 20 000 draws → ±1 %.
    norm, sd = res.baseline()
    idx = [res.parameter_names.index(f"T_tele_wide.t{a}") for a in "xyz"]
    draws = rng.multivariate_normal(res.T_tele_wide.t, res.covariance[np.ix_(idx, idx)], 20_000)
    assert norm == pytest.approx(np.linalg.norm(res.T_tele_wide.t))
    assert sd == pytest.approx(np.std(np.linalg.norm(draws, axis=1)), rel=0.03)
    assert abs(norm - np.linalg.norm(rel.t)) < 4.5 * sd


def test_trimmed_noise_variance_is_unbiased_for_gaussian_residuals() -> None:
    # A Gaussian trimmed at the rejection threshold keeps 98.2 % of its variance; the
    # correction gives it back (MC standard error of the ratio ≈ 0.1 %).
    r = np.random.default_rng(0).normal(0.0, 0.3, (400_000, 2))
    kept = r[np.sum(r**2, axis=1) <= CHI2_2DOF_997 * 0.09]
    assert trimmed_noise_variance(kept, 0, trimmed=False) / 0.09 == pytest.approx(0.982, abs=0.003)
    assert trimmed_noise_variance(kept, 0, trimmed=True) / 0.09 == pytest.approx(1.0, abs=0.003)


def test_outlier_rejection_keeps_the_covariance_of_clean_data() -> None:
    # Gaussian corners without outliers: the rejection still drops ~0.3 % of them (the tail),
    # and the covariance must not shrink for it. Measured mean variance ratio (rejection on /
    # off) over these 4 seeds: 1.005 (0.986 before the σ was corrected for the trimming).
    ratios = []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        wide, tele, rel = _true_rig()
        obj = chessboard_object_points((12, 9), 0.015)
        poses = _board_poses(rng, 12, 0.45)
        wv = _views(wide, poses, obj, rng, 0.1)
        tv = _views(tele, [rel @ T for T in poses], obj, rng, 0.1)
        sizes = (wide.size, tele.size)
        off = calibrate_stereo(wv, tv, sizes, CalibrationOptions(reject_outliers=False))
        on = calibrate_stereo(wv, tv, sizes, CalibrationOptions())
        assert 0 < on.n_outliers < 0.01 * on.inliers.size
        ratios.append(np.mean(np.diag(on.covariance) / np.diag(off.covariance)))
    assert abs(np.mean(ratios) - 1.0) < 0.01, ratios


def _opencv_corners() -> tuple[list[np.ndarray], list[np.ndarray]]:
    left, right = [], []
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)
    for f in sorted(glob.glob(str(DATA / "left*.jpg"))):
        pair = []
        for path in (f, f.replace("left", "right")):
            img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
            ok, c = cv2.findChessboardCorners(img, (9, 6))
            assert ok, path
            pair.append(cv2.cornerSubPix(img, c, (11, 11), (-1, -1), crit).reshape(-1, 2))
        left.append(pair[0])
        right.append(pair[1])
    return left, right


@pytest.mark.skipif(not DATA.exists(), reason="shared/data not beside the clone")
def test_opencv_stereo_sample_against_opencv() -> None:
    left, right = _opencv_corners()
    obj = chessboard_object_points((9, 6), 1.0)
    objs = [obj.astype(np.float32)] * len(left)
    size = (640, 480)
    _, K1, D1, _, _ = cv2.calibrateCamera(
        objs, [c.astype(np.float32) for c in left], size, None, None
    )
    _, K2, D2, _, _ = cv2.calibrateCamera(
        objs, [c.astype(np.float32) for c in right], size, None, None
    )
    rms_cv, *_ = cv2.stereoCalibrate(
        objs,
        [c.astype(np.float32) for c in left],
        [c.astype(np.float32) for c in right],
        K1,
        D1,
        K2,
        D2,
        size,
        flags=cv2.CALIB_USE_INTRINSIC_GUESS,
    )
    wv = [BoardView(obj, c, np.arange(54), "L") for c in left]
    tv = [BoardView(obj, c, np.arange(54), "R") for c in right]
    plain = calibrate_stereo(
        wv, tv, (size, size), CalibrationOptions(reject_outliers=False, view_weights=False)
    )
    # Same model, same corners, no rejection, every corner alike (OpenCV's criterion): at least
    # as good as OpenCV's joint solve (0.446).
    assert plain.rms_px_per_point <= rms_cv + 1e-6
    robust = calibrate_stereo(wv, tv, (size, size))
    # Issue #3: with rejection ≤ 0.14 px per coordinate (mrcal: 0.129 px, 2.4 % rejected).
    assert robust.rms_px_per_coordinate <= 0.14
    assert robust.n_outliers / robust.inliers.size < 0.05
    assert np.linalg.norm(robust.T_tele_wide.t) == pytest.approx(3.33, abs=0.05)  # squares


def test_too_few_views_is_a_clear_error() -> None:
    rng = np.random.default_rng(0)
    wide, _, _ = _true_rig()
    obj = chessboard_object_points((8, 6), 0.02)
    views = [v for v in _views(wide, _board_poses(rng, 1, 0.5), obj, rng, 0.1) if v is not None]
    with pytest.raises(InputError, match="views"):
        calibrate_camera(views, wide.size)
    with pytest.raises(InputError, match="no board views"):
        calibrate_camera([], wide.size)


def test_mono_result_has_no_baseline() -> None:
    rng = np.random.default_rng(1)
    wide, _, _ = _true_rig()
    obj = chessboard_object_points((8, 6), 0.02)
    views = [v for v in _views(wide, _board_poses(rng, 6, 0.5), obj, rng, 0.1) if v is not None]
    res = calibrate_camera(views, wide.size)
    with pytest.raises(InputError, match="--tele"):
        res.baseline()


def test_views_weighted_by_their_own_residuals_keep_noisy_views_and_honest_covariance() -> None:
    # A phone's far boards are noisier (on the presets' ISP the wide's views of the tele poses
    # err 0.04-0.055 px against 0.012-0.017 px; calibration/view_weights.py). Here every third
    # view has 4x the noise. With one pooled σ the solve takes those views' corners for outliers
    # and its covariance is off; a view whose residual σ differs beyond chance weighted by its
    # own keeps them, d²/P ≈ 1.
    wide, tele, rel = _true_rig()
    obj = chessboard_object_points((12, 9), 0.015)
    d2: dict[str, list[float]] = {"pooled": [], "per view": []}
    rejected = {"pooled": 0, "per view": 0}
    for seed in range(4):
        rng = np.random.default_rng(40 + seed)
        poses = _board_poses(rng, 12, 0.45)
        sig = [0.2 if i % 3 == 0 else 0.05 for i in range(len(poses))]
        wv = [_views(wide, [T], obj, rng, sig[i])[0] for i, T in enumerate(poses)]
        tv = [_views(tele, [rel @ T], obj, rng, sig[i])[0] for i, T in enumerate(poses)]
        truth = Layout((wide.lens, tele.lens), (wide.size, tele.size), len(poses), True).pack(
            (wide, tele), rel, tuple(poses)
        )
        for key in d2:
            opts = CalibrationOptions(view_weights=key == "per view")
            res = calibrate_stereo(wv, tv, (wide.size, tele.size), opts)
            err = res.parameters - truth
            d2[key].append(float(err @ np.linalg.solve(res.covariance, err)) / err.size)
            rejected[key] += res.n_outliers
            own = res.view_sigma_ratios()
            if key == "pooled":
                assert own == {}
            else:  # exactly the noisy views, both cameras, at ~4× the pooled σ
                assert {v for _, v in own} == {i for i in range(len(poses)) if i % 3 == 0}
                assert all(3.0 < r < 5.0 for r in own.values()), own
    # measured: pooled d²/P 4.5-5.9 with 1594 corners rejected (whole noisy views); per view
    # 0.85-1.08 (mean 1.00) with 31 rejected (χ² at 99.7 %: ~0.3 % of ~10000 corners); 4 seeds
    # × ~130 parameters give the mean d²/P to ±0.06
    assert 0.85 < np.mean(d2["per view"]) < 1.15, d2
    assert rejected["per view"] < 60 and rejected["pooled"] > 10 * rejected["per view"], rejected
