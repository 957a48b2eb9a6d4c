"""Intrinsic and stereo calibration by nonlinear least squares (thesis §1.3.2).

Initial values come from OpenCV (``initCameraMatrix2D`` and ``solvePnP`` per view); the joint
refinement is SciPy's ``least_squares`` (trust-region reflective) on the analytic sparse
Jacobian of :mod:`phonestereo.calibration.bundle`, with mrcal-style iterative outlier rejection:
after each solve, points whose residual norm exceeds the 99.7 % χ²₂ quantile of the fitted
per-coordinate noise σ are dropped and the problem is solved again, until none is dropped.
The σ of a set trimmed that way is corrected for the trimming (:func:`trimmed_noise_variance`),
in the threshold of the next round and in the reported covariance.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

from phonestereo.calibration.bundle import Layout, Observations, residuals_and_jacobian
from phonestereo.calibration.result import CalibrationResult
from phonestereo.calibration.view_weights import view_weights, weighted_rows
from phonestereo.calibration.views import BoardView
from phonestereo.errors import ConvergenceError, InputError
from phonestereo.geometry import Camera, Transform, make_lens

CHI2_2DOF_997 = 11.618  # 99.7 % quantile of χ² with 2 degrees of freedom
# E[χ²₂ | χ²₂ ≤ t] / 2 at t = CHI2_2DOF_997: the variance a Gaussian keeps when the points
# beyond the rejection threshold are dropped (χ²₂ is exponential with mean 2).
TRIMMED_VARIANCE_FRACTION = 1.0 - (CHI2_2DOF_997 / 2) * np.exp(-CHI2_2DOF_997 / 2) / (
    1.0 - np.exp(-CHI2_2DOF_997 / 2)
)
DENSE_LIMIT = 40_000_000  # Jacobian entries below which the dense solver is used


@dataclass(frozen=True)
class CalibrationOptions:
    """How to calibrate."""

    #: Lens model name (``opencv5``, ``opencv8``, ``radial-odd``).
    model: str = "opencv5"
    #: Radial terms of ``radial-odd``.
    n_radial: int = 6
    #: Iterative outlier rejection (on by default, like mrcal).
    reject_outliers: bool = True
    #: Cap on rejection rounds.
    max_rounds: int = 10
    #: Give a view its own residual σ where it differs from the pooled one beyond chance
    #: (variance components, :mod:`~phonestereo.calibration.view_weights`). On the presets'
    #: phone-ISP renders the wide's far boards err 3× more than its near ones; the pooled solve
    #: rejected their corners as outliers (28–73 a seed) and read d²/P 1.31 over six seeds, with
    #: the test 1.00. On linear renders, where views differ little, the 20-seed covariance test
    #: reads d²/P 1.086, RMS z 1.063 (pooled 1.091 / 1.040). On by default because real
    #: calibrations are phone JPEGs; off: every corner alike (OpenCV's and mrcal's criterion).
    view_weights: bool = True


def _initial_camera(
    views: Sequence[BoardView], size: tuple[int, int], lens_name: str, n_radial: int
) -> tuple[Camera, list[Transform]]:
    obj = [v.object_points.astype(np.float32) for v in views]
    img = [v.image_points.astype(np.float32) for v in views]
    if all(np.ptp(v.object_points[:, 2]) < 1e-12 for v in views):
        K = cv2.initCameraMatrix2D(obj, img, size, 1.0)
    else:  # non-planar chart: start from a 60° field of view at the image centre
        f = 0.5 * size[0] / np.tan(np.radians(30))
        K = np.array([[f, 0, (size[0] - 1) / 2], [0, f, (size[1] - 1) / 2], [0, 0, 1.0]])
    cam = Camera(size, K[0, 0], K[1, 1], K[0, 2], K[1, 2], make_lens(lens_name, n_radial=n_radial))
    poses = []
    for v in views:
        ok, rvec, tvec = cv2.solvePnP(
            v.object_points, v.image_points, K, None, flags=cv2.SOLVEPNP_ITERATIVE
        )
        if not ok:
            raise ConvergenceError(
                f"solvePnP failed on view '{v.name}'; is the board labelled right?"
            )
        poses.append(Transform.from_rotvec(rvec.ravel(), tvec.ravel()))
    return cam, poses


def _observations(per_camera: Sequence[Sequence[BoardView | None]]) -> Observations:
    cams, views, objs, imgs, ids = [], [], [], [], []
    for c, seq in enumerate(per_camera):
        for v, bv in enumerate(seq):
            if bv is None:
                continue
            n = bv.n_points
            cams.append(np.full(n, c))
            views.append(np.full(n, v))
            objs.append(bv.object_points)
            imgs.append(bv.image_points)
            ids.append(bv.ids)
    return Observations(
        np.concatenate(cams),
        np.concatenate(views),
        np.concatenate(objs),
        np.concatenate(imgs),
        np.concatenate(ids),
    )


def _subset(obs: Observations, keep: np.ndarray) -> Observations:
    return Observations(
        obs.camera[keep],
        obs.view[keep],
        obs.object_points[keep],
        obs.image_points[keep],
        obs.ids[keep],
    )


def _solve(
    layout: Layout, obs: Observations, x0: np.ndarray, options: CalibrationOptions
) -> tuple[np.ndarray, np.ndarray, int, np.ndarray | None]:
    inliers = np.ones(obs.camera.shape[0], dtype=bool)
    w = np.ones(obs.camera.shape[0])
    x = x0
    rounds = 0
    n_params = layout.n_params
    while True:
        sub = _subset(obs, inliers)
        wr = np.repeat(w[inliers], 2)  # one weight per residual (x, y of each corner)

        def fun(p: np.ndarray, sub: Observations = sub, wr: np.ndarray = wr) -> np.ndarray:
            return residuals_and_jacobian(p, layout, sub, with_jacobian=False)[0] * wr

        # The Jacobian is built sparse; small problems (every phone calibration so far) solve
        # faster and more exactly with the dense trust-region step than with LSMR.
        dense = 2 * sub.camera.shape[0] * n_params <= DENSE_LIMIT

        def jac(  # type: ignore[no-untyped-def]
            p: np.ndarray, sub: Observations = sub, dense: bool = dense, wr: np.ndarray = wr
        ):
            j = weighted_rows(residuals_and_jacobian(p, layout, sub)[1], wr)
            return j.toarray() if dense and j is not None else j

        sol = least_squares(
            fun,
            x,
            jac=jac,
            method="trf",
            x_scale="jac",
            tr_solver="exact" if dense else "lsmr",
            ftol=1e-10,
            xtol=1e-10,
            gtol=1e-10,
            max_nfev=100,
        )
        x = sol.x
        rounds += 1
        if not (options.reject_outliers or options.view_weights) or rounds > options.max_rounds:
            break
        r = residuals_and_jacobian(x, layout, obs, with_jacobian=False)[0].reshape(-1, 2)
        new_w = view_weights(r, inliers, obs) if options.view_weights else w
        new_inliers = inliers
        if options.reject_outliers:  # the test in units of each view's own σ
            rw = r * new_w[:, None]
            sigma2 = trimmed_noise_variance(rw[inliers], n_params, trimmed=not inliers.all())
            new_inliers = np.sum(rw**2, axis=1) <= CHI2_2DOF_997 * sigma2
            if new_inliers.sum() < n_params:
                break
        if np.array_equal(new_inliers, inliers) and np.allclose(new_w, w, rtol=0.02):
            break
        inliers, w = new_inliers, new_w
    return x, inliers, rounds, (w if options.view_weights else None)


def trimmed_noise_variance(residuals: np.ndarray, n_params: int, *, trimmed: bool) -> float:
    """Per-coordinate noise variance σ² from the residuals of the kept points, px².

    σ² = Σ r² / (2M − P) (degrees of freedom of the fit), divided by
    :data:`TRIMMED_VARIANCE_FRACTION` (0.982) when the points were kept by the χ²₂ test at
    :data:`CHI2_2DOF_997`: trimming the tails of a Gaussian lowers its sample variance, and
    without the correction each rejection round tightens the next one's threshold and the
    covariance comes out optimistic. Measured over 20 rendered seeds (no true outliers):
    rejected points 9.3 → 8.3 per solve, mean squared Mahalanobis distance per parameter
    1.164 → 1.136. Where the dropped points are real outliers, σ comes out 0.9 % high.

    Parameters
    ----------
    residuals : ndarray, shape (M, 2)
        Residuals of the kept points, px.
    n_params : int
        Parameters of the fit.
    trimmed : bool
        Whether any point was dropped by the test.
    """
    r = np.asarray(residuals, dtype=np.float64)
    dof = max(r.size - n_params, 1)
    sigma2 = float(np.sum(r**2) / dof)
    return sigma2 / TRIMMED_VARIANCE_FRACTION if trimmed else sigma2


def _finish(
    layout: Layout,
    obs: Observations,
    x: np.ndarray,
    inliers: np.ndarray,
    rounds: int,
    t0: float,
    weights: np.ndarray | None = None,
) -> CalibrationResult:
    r, jac = residuals_and_jacobian(x, layout, _subset(obs, inliers))
    assert jac is not None
    if weights is not None:  # σ² is then that of a view of σ_ref; J weighted alike
        wr = np.repeat(np.asarray(weights, np.float64)[inliers], 2)
        r, jac = r * wr, weighted_rows(jac, wr)
    sigma2 = trimmed_noise_variance(r.reshape(-1, 2), layout.n_params, trimmed=not inliers.all())
    jtj = (jac.T @ jac).toarray()
    try:
        cov = np.linalg.inv(jtj) * sigma2
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(jtj) * sigma2
    res_all = residuals_and_jacobian(x, layout, obs, with_jacobian=False)[0].reshape(-1, 2)
    ri = res_all[inliers]
    cams = tuple(layout.camera(x, c) for c in range(len(layout.lenses)))
    return CalibrationResult(
        cameras=cams,
        T_tele_wide=layout.rel(x),
        board_poses=layout.poses(x),
        parameter_names=layout.parameter_names(),
        parameters=x,
        covariance=cov,
        residuals=res_all,
        image_points=obs.image_points,
        camera_index=obs.camera,
        view_index=obs.view,
        ids=obs.ids,
        inliers=inliers,
        rms_px_per_point=float(np.sqrt(np.mean(np.sum(ri**2, axis=1)))),
        rms_px_per_coordinate=float(np.sqrt(np.mean(ri**2))),
        rounds=rounds,
        seconds=time.perf_counter() - t0,
        weights=None if weights is None else np.asarray(weights, np.float64),
    )


def _n_intrinsics(options: CalibrationOptions) -> int:
    return 4 + make_lens(options.model, n_radial=options.n_radial).n_coefficients


def _check_views(views: Sequence[BoardView], size: tuple[int, int], n_intr: int, who: str) -> None:
    if len(views) == 0:
        raise InputError(f"{who}: no board views; check the image glob and the board size")
    need = max(3, int(np.ceil((n_intr + 6 * len(views)) / 2 / 4)))
    planar = all(np.ptp(v.object_points[:, 2]) < 1e-12 for v in views)
    if len(views) < 2 and n_intr > 4 and planar:
        raise InputError(
            f"{who}: {len(views)} view(s) cannot constrain {n_intr} intrinsics; "
            "take at least 3 views of the board at different tilts (or use the three-plane chart)"
        )
    total = sum(v.n_points for v in views)
    if 2 * total < n_intr + 6 * len(views) + need:
        raise InputError(
            f"{who}: only {total} corners for {n_intr + 6 * len(views)} unknowns; "
            "add views or use a model with fewer coefficients"
        )
    w, h = size
    for v in views:
        q = v.image_points
        if (
            (q[:, 0] < -0.5).any()
            or (q[:, 1] < -0.5).any()
            or (q[:, 0] > w - 0.5).any()
            or (q[:, 1] > h - 0.5).any()
        ):
            raise InputError(
                f"{who}: view '{v.name}' has corners outside the {w}x{h} image; "
                "are the images of one size?"
            )


def calibrate_camera(
    views: Sequence[BoardView], size: tuple[int, int], options: CalibrationOptions | None = None
) -> CalibrationResult:
    """Calibrate one camera's intrinsics from board views (§1.3.2).

    Parameters
    ----------
    views : sequence of BoardView
        At least 3 views at different tilts (a flat board), or one three-plane view.
    size : (int, int)
        Image (width, height) in pixels.
    options : CalibrationOptions, optional

    Returns
    -------
    CalibrationResult
    """
    options = options or CalibrationOptions()
    t0 = time.perf_counter()
    _check_views(views, size, _n_intrinsics(options), "calibration")
    cam0, poses = _initial_camera(views, size, options.model, options.n_radial)
    layout = Layout((cam0.lens,), (size,), len(views), stereo=False)
    obs = _observations([views])
    x, inliers, rounds, w = _solve(layout, obs, layout.pack((cam0,), None, tuple(poses)), options)
    return _finish(layout, obs, x, inliers, rounds, t0, w)


def calibrate_stereo(
    wide_views: Sequence[BoardView | None],
    tele_views: Sequence[BoardView | None],
    sizes: tuple[tuple[int, int], tuple[int, int]],
    options: CalibrationOptions | None = None,
) -> CalibrationResult:
    """Calibrate both cameras and ``T_tele_wide`` jointly from synchronous board views.

    ``wide_views[i]`` and ``tele_views[i]`` see the same board pose; either may be None (the
    board not found in that camera). The tele may see only part of the board: corners are tied
    through the board frame, not matched by position.
    """
    options = options or CalibrationOptions()
    if len(wide_views) != len(tele_views):
        raise InputError(
            f"stereo calibration needs pairs: {len(wide_views)} wide vs "
            f"{len(tele_views)} tele views"
        )
    t0 = time.perf_counter()
    both = [
        i
        for i, (a, b) in enumerate(zip(wide_views, tele_views, strict=True))
        if a is not None and b is not None
    ]
    if len(both) < 1:
        raise InputError(
            "stereo calibration needs at least one pair where both cameras see the board"
        )
    wv = [v for v in wide_views if v is not None]
    tv = [v for v in tele_views if v is not None]
    _check_views(wv, sizes[0], _n_intrinsics(options), "wide calibration")
    _check_views(tv, sizes[1], _n_intrinsics(options), "tele calibration")
    cam_w, poses_w = _initial_camera(wv, sizes[0], options.model, options.n_radial)
    cam_t, poses_t = _initial_camera(tv, sizes[1], options.model, options.n_radial)
    layout = Layout((cam_w.lens, cam_t.lens), tuple(sizes), len(wide_views), stereo=True)
    # Mono refinement first, so the relative pose starts from good intrinsics.
    mono = CalibrationOptions(options.model, options.n_radial, reject_outliers=False)
    res_w = calibrate_camera(wv, sizes[0], mono)
    res_t = calibrate_camera(tv, sizes[1], mono)
    pw = dict(
        zip([i for i, v in enumerate(wide_views) if v is not None], res_w.board_poses, strict=True)
    )
    pt = dict(
        zip([i for i, v in enumerate(tele_views) if v is not None], res_t.board_poses, strict=True)
    )
    rels = [pt[i] @ pw[i].inverse() for i in both]
    rotvec = np.median(np.stack([r.rotvec for r in rels]), axis=0)
    t_rel = np.median(np.stack([r.t for r in rels]), axis=0)
    rel = Transform.from_rotvec(rotvec, t_rel)
    poses = tuple(pw[i] if i in pw else rel.inverse() @ pt[i] for i in range(len(wide_views)))
    obs = _observations([wide_views, tele_views])
    x0 = layout.pack((res_w.cameras[0], res_t.cameras[0]), rel, poses)
    x, inliers, rounds, w = _solve(layout, obs, x0, options)
    del cam_w, cam_t, poses_w, poses_t
    return _finish(layout, obs, x, inliers, rounds, t0, w)


def intrinsic_extrinsic_covariance(result: CalibrationResult) -> tuple[tuple[str, ...], np.ndarray]:
    """The covariance block of camera and rig parameters (board poses dropped), for files."""
    keep = [i for i, n in enumerate(result.parameter_names) if not n.startswith("view")]
    names = tuple(result.parameter_names[i] for i in keep)
    cov = result.covariance[np.ix_(keep, keep)]
    return names, 0.5 * (cov + cov.T)
