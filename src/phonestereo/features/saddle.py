"""Sub-pixel chessboard corners by a saddle-point fit (thesis §1.2.2 "sub-pixel accurate").

A chessboard corner is a saddle of the (slightly blurred) image intensity. Around each corner a
quadratic surface ``f(u, v) = a u² + b u v + c v² + d u + e v + g`` is fitted by weighted least
squares over a disc of samples; its stationary point is the new estimate, and the fit is
repeated around it. An ideal corner is point-symmetric, so a window centred on it yields zero
linear terms: the fixed point is the corner. The fit uses the image's own pixels with weights
centred on the sub-pixel estimate (no resampling, so no pull toward pixel centres). All corners
are fitted at once with batched 6 × 6 normal equations.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from phonestereo.errors import InputError, ShapeError


@dataclass(frozen=True, eq=False)
class SaddleCorners:
    """Refined corners and how trustworthy each is.

    Attributes
    ----------
    points : ndarray, shape (N, 2)
        Refined (x, y) pixels; the input position where the fit failed.
    ok : ndarray of bool, shape (N,)
        The fit converged to a saddle (opposite-sign curvatures) within the window.
    saddle_strength : ndarray, shape (N,)
        √(−det H) of the fitted Hessian, in intensity units per px²; low for weak or blurred
        corners.
    shift_px : ndarray, shape (N,)
        Distance moved from the starting point.
    """

    points: np.ndarray
    ok: np.ndarray
    saddle_strength: np.ndarray
    shift_px: np.ndarray


def _fit(f: np.ndarray, centres: np.ndarray, radius: float) -> np.ndarray:
    """Weighted quadratic fit on the integer pixel grid around each centre → (k, 6) coefficients.

    Samples are the image's own pixels (no interpolation, which would pull estimates toward
    pixel centres); the Gaussian weights (σ = radius / 2, cut at the radius) are centred on the
    current sub-pixel estimate, so the fit moves smoothly with it.
    """
    h, w = f.shape
    r = int(np.ceil(radius))
    k = np.arange(-r, r + 1)
    gx, gy = np.meshgrid(k, k)
    base = np.round(centres).astype(np.int64)  # (k, 2)
    xs = np.clip(base[:, 0, None] + gx.ravel()[None, :], 0, w - 1)
    ys = np.clip(base[:, 1, None] + gy.ravel()[None, :], 0, h - 1)
    samples = f[ys, xs].astype(np.float64)  # (k, n)
    u = xs - centres[:, 0, None]
    v = ys - centres[:, 1, None]
    d2 = u * u + v * v
    sigma = radius / 2.0
    wts = np.exp(-d2 / (2 * sigma**2)) * np.clip(radius + 0.5 - np.sqrt(d2), 0.0, 1.0)
    A = np.stack([u * u, u * v, v * v, u, v, np.ones_like(u)], axis=2)  # (k, n, 6)
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
    return SaddleCorners(out, ok, strength, shift)
