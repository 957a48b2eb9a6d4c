"""The misfit a saddle fit leaves in its own window: the chessboard corner σ on real images.

A saddle's position σ from the image noise alone
(:func:`~phonestereo.features.saddle.position_covariance`) holds on linear, noise-limited
images. A phone's JPEG is not one: CFA
sampling and demosaicing, denoising, sharpening and compression displace each corner by a
deterministic few hundredths of a pixel that the noise estimate does not see (a denoised image
reads nearly noise-free). Measured on ``folded-x3`` calibration renders through the phone ISP,
the noise-only σ was 16–35× too small (RMS z 19 / 37, wide / tele; the error stays with sensor
noise off), and on the OpenCV stereo sample (real JPEGs) it reads 0.002 px per coordinate.

What displaces a point-symmetric corner is the *odd* part of the image about it: an ideal
(blurred) chessboard corner is even under the point reflection p → 2c − p, and so is the
quadratic model's misfit, which therefore does not move the estimate. The odd part left once
the fit's linear terms are zero (the fixed point) is noise plus any structured misfit. This
module measures its weighted mean square in each fit window, with the reflected samples from a
cubic B-spline of the (blurred) image, and converts it to the white pixel-noise variance that
would leave the same odd residual (:func:`white_noise_odd_m2`). The image's misfit variance is
the median of that over its corners (one corner's window is a noisy estimate, and the ISP's
misfit is a property of the image); the covariance then uses max(noise variance, misfit
variance) per corner, so noise-limited images keep their σ (the median of the white-noise ratio
is ≈ 0.9, under 1) while processed ones get the misfit they carry. On the ISP renders the RMS z
is then 1.05 / 0.97 (wide / tele; linear renders 0.95 / 0.86, 1.26 / 1.66 before, from the
renderer's own sub-0.01 px corner error), and the OpenCV sample's corners read 0.032 / 0.039 px.
It errs on the side of caution where the odd structure is the pixel grid's own (small
area-sampled synthetic boards: RMS z 0.69–0.85), which moves a corner less than white noise
of its energy would.

Hand-written: SciPy gives the spline's prefilter (``ndimage.spline_filter1d``), but no library
estimates a fit's odd misfit or its white-noise equivalent; the spline is evaluated by 16 gathers
(``map_coordinates`` over the stack of patches would interpolate across the stack too).
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np
from scipy import ndimage

from phonestereo.features.saddle_window import fit_window
from phonestereo.features.subpixel import cubic_bspline_weights

#: Corners read for an image's median misfit (a verification chart has ~1000): beyond this
#: the median is no better known than its spread over images, and the time is ~1/4.
MAX_CORNERS = 256

#: Pixels beyond the fit window kept around each corner for the B-spline (its prefilter's
#: mirror boundary decays by 0.27 per pixel: < 0.5 % at the window).
_MARGIN = 4


def odd_residual_m2(f: np.ndarray, centres: np.ndarray, radius: float) -> np.ndarray:
    """Weighted mean square of the odd part of ``f`` about each centre, linear terms removed.

    Parameters
    ----------
    f : ndarray, shape (H, W)
        The (blurred) image the saddle fit ran on.
    centres : ndarray, shape (N, 2)
        Converged corner positions (x, y), px.
    radius : float
        Fit window radius, px (the fit's Gaussian weights, :func:`fit_window`).

    Returns
    -------
    ndarray, shape (N,)
        Σ w·r² / Σ w of r(p) = (f(p) − f(2c − p)) / 2 over the window's pixels p, less its
        weighted fit in u and v; intensity units².

    Examples
    --------
    An even surface about the centre has no odd part; a tilt is the linear terms, removed:

    >>> y, x = np.mgrid[0:40, 0:40].astype(float)
    >>> f = (x - 20.3) ** 2 - (y - 19.6) ** 2 + 0.5 * (x - 20.3)
    >>> float(odd_residual_m2(f, np.array([[20.3, 19.6]]), 5.0)[0]) < 1e-4  # of f² ~ 1e4
    True
    """
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
    if not len(c):
        return np.zeros(0)
    h = int(np.ceil(radius)) + _MARGIN
    base = np.round(c).astype(np.int64)
    k = np.arange(-h, h + 1)
    rows, cols = f.shape
    ys = np.clip(base[:, 1, None, None] + k[None, :, None], 0, rows - 1)
    xs = np.clip(base[:, 0, None, None] + k[None, None, :], 0, cols - 1)
    coef = np.asarray(f, dtype=np.float64)[ys, xs]  # (N, P, P) patches
    for axis in (1, 2):
        coef = ndimage.spline_filter1d(coef, 3, axis=axis, mode="mirror")
    xw, yw, A, wts = fit_window(c, radius, f.shape)
    px = 2 * c[:, 0, None] - xw - (base[:, 0, None] - h)  # reflected points, patch coordinates
    py = 2 * c[:, 1, None] - yw - (base[:, 1, None] - h)
    refl = _spline_at(coef, px, py)
    odd = (np.asarray(f, dtype=np.float64)[yw, xw] - refl) / 2
    lin = A[..., 3:5]  # u, v
    lw = lin * wts[..., None]
    coeffs = np.linalg.solve(np.swapaxes(lw, 1, 2) @ lin, np.swapaxes(lw, 1, 2) @ odd[..., None])
    odd -= (lin @ coeffs)[..., 0]
    return np.asarray((wts * odd * odd).sum(axis=1) / wts.sum(axis=1))


def _spline_at(coef: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Cubic B-spline of coefficient patches ``coef`` (N, P, P) at (px, py) (N, n), patch
    coordinates at least 1 px inside: 16 gathers, not ``map_coordinates`` over the stack (whose
    third axis would cost 4× the taps)."""
    n, p, _ = coef.shape
    ix, iy = np.floor(px).astype(np.int64), np.floor(py).astype(np.int64)
    wx, wy = cubic_bspline_weights(px - ix), cubic_bspline_weights(py - iy)
    flat = coef.reshape(-1)
    start = (np.arange(n)[:, None] * p + iy - 1) * p + ix - 1
    out = np.zeros(px.shape)
    for a in range(4):
        row = np.zeros(px.shape)
        for b in range(4):
            row += wx[..., b] * flat[start + a * p + b]
        out += wy[..., a] * row
    return out


@lru_cache(maxsize=128)
def white_noise_odd_m2(radius: float, blur_sigma_px: float) -> float:
    """:func:`odd_residual_m2` per unit variance of white pixel noise blurred by a Gaussian of
    ``blur_sigma_px`` (the fit's pre-blur), at a random sub-pixel centre.

    A fixed-seed Monte Carlo over 576 windows of one noise image (known to ~3 %): the
    expectation through the fit, the linear-term removal and the spline has no closed form worth
    the code. Cached per (radius, blur); ~40 ms each on this project's 2-core machine.
    """
    rng = np.random.default_rng(0)
    side, grid = 2 * (int(np.ceil(radius)) + _MARGIN) + 2, 24  # patches side by side
    g = np.arange(grid) * side + side / 2
    cx, cy = np.meshgrid(g, g)
    centres = np.column_stack([cx.ravel(), cy.ravel()]) + rng.uniform(-0.5, 0.5, (grid**2, 2))
    img = rng.standard_normal((side * grid, side * grid), dtype=np.float32)
    f = cv2.GaussianBlur(img, (0, 0), blur_sigma_px) if blur_sigma_px > 0 else img
    return float(np.mean(odd_residual_m2(f, centres, radius)))


def misfit_variance(
    f: np.ndarray, centres: np.ndarray, radius: float, blur_sigma_px: float
) -> float:
    """The image's misfit as a white pixel-noise variance: the median over ``centres`` (at most
    :data:`MAX_CORNERS` of them, evenly taken) of their odd residual per
    :func:`white_noise_odd_m2`; intensity units² of the unblurred image, 0 without corners.
    Pure white noise reads ≈ 0.9 of its variance (the median of a skewed spread)."""
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
    if len(c) > MAX_CORNERS:  # a median of 256 is known to ~±8 % in variance: every k-th one
        c = c[:: -(-len(c) // MAX_CORNERS)]
    m2 = odd_residual_m2(f, c, radius)
    if not len(m2):
        return 0.0
    return float(np.median(m2)) / white_noise_odd_m2(float(radius), float(blur_sigma_px))


__all__ = ["MAX_CORNERS", "misfit_variance", "odd_residual_m2", "white_noise_odd_m2"]
