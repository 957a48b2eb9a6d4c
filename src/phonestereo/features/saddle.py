"""Sub-pixel chessboard corners by a saddle-point fit (thesis §1.2.2 "sub-pixel accurate").

A chessboard corner is a saddle of the (slightly blurred) image intensity. Around each corner a
quadratic surface ``f(u, v) = a u² + b u v + c v² + d u + e v + g`` is fitted by weighted least
squares over a disc of samples; its stationary point is the new estimate, and the fit is
repeated around it. An ideal corner is point-symmetric, so a window centred on it yields zero
linear terms: the fixed point is the corner. The fit uses the image's own pixels with weights
centred on the sub-pixel estimate (no resampling, so no pull toward pixel centres). All corners
are fitted at once with batched 6 × 6 normal equations.

Each refined corner also gets the covariance the image noise gives it
(:func:`position_covariance`, with the signal-dependent noise level of
:mod:`phonestereo.features.noise_level`): on rendered charts its σ is within 4 % of the scatter
that noise causes (verification chart, wide chessboards) and 11–19 % low on the blurrier tele.
A processed image (a phone's JPEG) displaces corners by more than its noise does; the fit's own
odd residual measures that misfit (:mod:`phonestereo.features.saddle_misfit`), and the
covariance uses it where it exceeds the noise.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from phonestereo.errors import InputError, ShapeError
from phonestereo.features.noise_level import NoiseLevel, estimate_noise_level
from phonestereo.features.saddle_misfit import misfit_variance
from phonestereo.features.saddle_window import fit_window


@dataclass(frozen=True, eq=False)
class SaddleCorners:
    """Refined corners and how trustworthy each is."""

    #: ndarray, shape (N, 2). Refined (x, y) pixels; the input position where the fit failed.
    points: np.ndarray
    #: ndarray of bool, shape (N,). The fit converged to a saddle (opposite-sign curvatures) within
    #: the window.
    ok: np.ndarray
    #: ndarray, shape (N,). √(−det H) of the fitted Hessian, in intensity units per px²; low for
    #: weak or blurred corners.
    saddle_strength: np.ndarray
    #: ndarray, shape (N,). Distance moved from the starting point.
    shift_px: np.ndarray
    #: ndarray, shape (N, 2, 2). Predicted covariance of each point from the image noise, or the
    #: image's misfit where larger (first order through the fit, see :func:`position_covariance`
    #: and ``misfit_var``), px²; NaN where the fit failed.
    covariance_px2: np.ndarray
    #: The image's noise level used for it (σ² = a + b·I, at each corner's intensity).
    noise: NoiseLevel
    #: The corners' misfit as a pixel-noise variance, intensity units²
    #: (:func:`~phonestereo.features.saddle_misfit.misfit_variance`): the covariance uses it
    #: where it exceeds the noise (processed images: demosaicing, denoising, sharpening, JPEG).
    misfit_var: float = 0.0

    @property
    def sigma_px(self) -> np.ndarray:
        """Predicted position σ per coordinate, √(trace / 2) of each covariance, px; (N,)."""
        return np.sqrt(np.trace(self.covariance_px2, axis1=1, axis2=2) / 2)


@lru_cache(maxsize=32)
def _blur_correlation(side: int, blur_sigma_px: float) -> np.ndarray:
    """R = B Bᵀ over a side × side window: the correlation the Gaussian pre-blur B (OpenCV's
    kernel size for float images) gives unit white noise; (n, n), n = side²."""
    if blur_sigma_px <= 0:
        return np.eye(side * side)
    ksize = round(blur_sigma_px * 8 + 1) | 1
    g = cv2.getGaussianKernel(ksize, blur_sigma_px).ravel()
    h = ksize // 2
    # 1-D: the window's side pixels as mixtures of the side + 2h noisy ones
    b = np.zeros((side, side + 2 * h))
    for i in range(side):
        b[i, i : i + ksize] = g
    r1 = b @ b.T
    R = np.kron(r1, r1)  # separable kernel: rows (y) ⊗ columns (x), row-major like the window
    R.setflags(write=False)
    return R


def position_covariance(
    f: np.ndarray,
    centres: np.ndarray,
    radius: float,
    blur_sigma_px: float,
    noise_var: np.ndarray | float,
    gradient: np.ndarray | None = None,
) -> np.ndarray:
    """Covariance of saddle positions caused by white image noise, first order, px².

    The fitted gradient (d, e) at the window centre is linear in the samples, (d, e) = L f, and
    the fixed point of the re-centred fit moves by δp = −J⁻¹ δ(d, e), J the derivative of the
    fitted gradient with respect to the centre. The pre-blur B correlates the samples, so
    Cov(p) = σ² J⁻¹ (L B)(L B)ᵀ J⁻ᵀ. Checked against Monte Carlo (``tests/features``): within
    5 % of the scatter of refined corners. Hand-written: no library propagates noise through a
    weighted polynomial fit.

    Parameters
    ----------
    f : ndarray, shape (H, W)
        The blurred image the fit ran on.
    centres : ndarray, shape (N, 2)
        Converged positions, px.
    radius : float
        Fit window radius, px.
    blur_sigma_px : float
        Total Gaussian blur between the noisy pixels and ``f``, px.
    noise_var : float or ndarray, shape (N,)
        Pixel noise variance of the unblurred image around each corner, intensity units².
    gradient : ndarray, shape (N, 2), optional
        The fitted gradient (d, e) at (or within ~1e-4 px of) the centres, if already known:
        saves one fit.

    Returns
    -------
    ndarray, shape (N, 2, 2)
    """
    _, _, A, wts = fit_window(centres, radius)
    Aw = A * wts[..., None]
    N = np.swapaxes(Aw, 1, 2) @ A
    L = np.linalg.solve(N, np.swapaxes(Aw, 1, 2))[:, 3:5]  # (k, 2, n): rows of d and e
    R = _blur_correlation(2 * int(np.ceil(radius)) + 1, blur_sigma_px)
    LR = (L.reshape(-1, R.shape[0]) @ R).reshape(L.shape)  # one BLAS call, not k small ones
    K = LR @ np.swapaxes(L, 1, 2)  # (k, 2, 2)
    # J = ∂(fitted gradient at the window centre)/∂(centre): how the fixed point moves. The
    # fitted Hessian is not it (the blurred junction is not quadratic over the window), so J
    # is taken by differences of the fit itself (3 more batched fits).
    eps = 0.05
    g0 = _fit(f, centres, radius)[:, 3:5] if gradient is None else gradient
    cols = []
    for axis in range(2):  # forward differences: the fit is smooth in the centre (3 fits, not 4)
        step = np.zeros(2)
        step[axis] = eps
        cols.append((_fit(f, centres + step, radius)[:, 3:5] - g0) / eps)
    J = np.stack(cols, axis=2)  # (k, 2, 2): d(d, e)/d(x, y)
    det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
    size = np.max(np.abs(J), axis=(1, 2))
    at = np.clip(np.round(centres).astype(np.int64), 0, np.array(f.shape[::-1]) - 1)
    tiny = 1e-6 * (1.0 + np.abs(f[at[:, 1], at[:, 0]]))  # intensity / px²: no junction at all
    flat = (size <= tiny) | ~(np.abs(det) > 1e-12 * size**2)  # no saddle: no σ
    J[flat] = np.eye(2)
    Ji = np.linalg.inv(J)
    var = np.broadcast_to(np.asarray(noise_var, dtype=np.float64), (centres.shape[0],))
    cov = var[:, None, None] * (Ji @ K @ np.swapaxes(Ji, 1, 2))
    cov[flat] = np.nan
    return cov


def _fit(f: np.ndarray, centres: np.ndarray, radius: float) -> np.ndarray:
    """Weighted quadratic fit on the integer pixel grid around each centre → (k, 6) coefficients.

    Samples are the image's own pixels (no interpolation, which would pull estimates toward
    pixel centres); the Gaussian weights (σ = radius / 2, cut at the radius) are centred on the
    current sub-pixel estimate, so the fit moves smoothly with it.
    """
    xs, ys, A, wts = fit_window(centres, radius, f.shape)
    samples = f[ys, xs].astype(np.float64)  # (k, n)
    Aw = A * wts[..., None]
    AwT = np.swapaxes(Aw, 1, 2)  # batched matmul: 2x faster than the equivalent einsum
    N = AwT @ A
    rhs = (AwT @ samples[..., None])[..., 0]
    N += np.eye(6)[None] * 1e-9 * np.trace(N, axis1=1, axis2=2)[:, None, None]
    return np.linalg.solve(N, rhs[..., None])[..., 0]


def refine_saddle(
    image: np.ndarray,
    points: np.ndarray,
    *,
    radius_px: float = 5.0,
    blur_sigma_px: float = 1.5,
    iterations: int = 6,
    tol_px: float = 1e-4,
    min_strength: float | None = None,
    noise: NoiseLevel | None = None,
    prefilter_sigma_px: float = 0.0,
) -> SaddleCorners:
    """Refine chessboard corners to sub-pixel by iterated quadratic saddle fits.

    Parameters
    ----------
    image : ndarray, shape (H, W)
        Grayscale image (uint8 or float).
    points : array_like, shape (N, 2)
        Starting (x, y) pixels, within ~radius/2 of the corners.
    radius_px : float
        Fit window radius; keep it below ~0.4 of the square size in pixels so that no other
        corner enters the window.
    blur_sigma_px : float
        Gaussian pre-blur (OpenCV ``GaussianBlur``) making the saddle smooth; ~1.5 px for sharp
        images, 0 to skip.
    iterations : int
        Maximum re-centred fits.
    tol_px : float
        Stop when every corner moved less than this.
    min_strength : float, optional
        Saddle strength below which a corner is not ``ok``; default 0.2 % of the image's
        1–99 % intensity range (a flat or featureless patch fails).
    noise : NoiseLevel, optional
        Noise level of the unblurred image for the covariance; default
        :func:`~phonestereo.features.noise_level.estimate_noise_level` of ``image``.
    prefilter_sigma_px : float
        Gaussian blur the caller already applied to ``image`` (the noise is then correlated
        over it; pass the unblurred image's ``noise`` too).

    Returns
    -------
    SaddleCorners
    """
    img = np.asarray(image)
    if img.ndim != 2:
        raise ShapeError(f"image must be a 2-D grayscale array, got shape {img.shape}")
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ShapeError(f"points must be (N, 2) pixels, got {pts.shape}")
    if radius_px < 1.5:
        raise InputError(f"radius_px must be >= 1.5 px to fit a saddle, got {radius_px}")
    f = img.astype(np.float32)
    if blur_sigma_px > 0:
        f = cv2.GaussianBlur(f, (0, 0), blur_sigma_px)
    start = pts.copy()
    cur = pts.copy()
    active = np.isfinite(cur).all(axis=1)
    coef = np.zeros((pts.shape[0], 6))
    rejected = np.zeros(pts.shape[0], dtype=bool)  # a fit whose step was not a saddle step
    for _ in range(iterations):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        c = _fit(f, cur[idx], radius_px)
        coef[idx] = c
        a, b, cc, d, e = c[:, 0], c[:, 1], c[:, 2], c[:, 3], c[:, 4]
        det = 4 * a * cc - b * b
        with np.errstate(divide="ignore", invalid="ignore"):
            du = (-2 * cc * d + b * e) / det
            dv = (b * d - 2 * a * e) / det
        step = np.stack([du, dv], axis=1)
        bad = ~np.isfinite(step).all(axis=1) | (np.hypot(du, dv) > radius_px)
        step[bad] = 0.0
        rejected[idx[bad]] = True
        cur[idx] += step
        done = bad | (np.hypot(step[:, 0], step[:, 1]) < tol_px)
        active[idx[done]] = False
    det = 4 * coef[:, 0] * coef[:, 2] - coef[:, 1] ** 2
    shift = np.hypot(*(cur - start).T)
    strength = np.sqrt(np.clip(-det, 0, None))
    if min_strength is None:
        lo, hi = np.percentile(f, [1, 99])
        min_strength = 2e-3 * max(float(hi - lo), 1e-12)
    ok = np.isfinite(cur).all(axis=1) & (det < 0) & (shift <= radius_px) & (strength > min_strength)
    ok &= ~rejected
    out = np.where(ok[:, None], cur, start)
    level = estimate_noise_level(img) if noise is None else noise
    cov = np.full((pts.shape[0], 2, 2), np.nan)
    misfit = 0.0
    if ok.any():
        total_blur = float(np.hypot(blur_sigma_px, prefilter_sigma_px))  # Gaussians compose
        # the fit's constant term is the intensity at the junction: the mean of its squares
        var = level.variance(coef[ok, 5])
        # a processed image's misfit, as a pixel-noise variance (saddle_misfit), where it
        # exceeds the noise
        misfit = misfit_variance(f, cur[ok], radius_px, total_blur)
        var = np.maximum(var, misfit)
        # the last fit ran < tol_px from the final point: its gradient serves as the base
        cov[ok] = position_covariance(f, cur[ok], radius_px, total_blur, var, coef[ok, 3:5])
    return SaddleCorners(out, ok, strength, shift, cov, level, misfit)
