"""Sub-pixel disparity by 2-D Lucas–Kanade on a cubic B-spline of the right image (§1.2.1).

The thesis refines each NCC peak ("peak refinement on the windows"); here the refinement is a
Gauss–Newton fit of a window of the left image (at its own integer pixels, never resampled) to
the right image, so it measures both the disparity ``d`` and the non-disparity error ``e``::

    L(x0 + u, y0 + v) ≈ a · R(x0 + u − d − s_x·u − s_y·v,  y0 + v − e) + b

over the window |u|, |v| ≤ r with Gaussian weights w(u, v) (σ = ``sigma_w``). ``a, b`` absorb a
gain and offset between the cameras; ``(s_x, s_y)`` is the disparity gradient of a slanted
surface, so that ``d`` at the window centre is not biased by the slant. Conventions (DESIGN §5):
``d = x_left − x_right``, ``e = y_left − y_right``.

The Jacobian is taken from the left window's own spline gradients (at the solution
``a·∂R/∂x·(1 − s_x) = ∂L/∂x``), as in inverse-compositional / ESM alignment: only values of R
are resampled per iteration, the normal equations are assembled from fixed per-window moments
(:func:`_basis_gram`) plus the resampled values, and the fit converges in 2–3 iterations from
the NCC start. The fixed point is the same as with R's own gradients (the residual vanishes
there for noise-free data).

Pixel locking: R is evaluated by exact cubic B-spline interpolation (coefficients from the
recursive prefilter of Unser et al., applied as a 21-tap FIR whose truncation error is < 1e-6 of
the signal), not on the NCC grid, so nothing pulls the estimate toward integer disparities: on a
band-limited texture shifted by an exact Fourier shift the bias is < 0.004 px at every fraction
(``tests/features/test_match_subpixel.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError
from phonestereo.features.crlb import sandwich, solve_spd

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

_Z = np.sqrt(3.0) - 2.0  # pole of the cubic B-spline prefilter
_TAPS = 10  # |z|^11 ≈ 5e-7: the FIR truncation is invisible in 8-bit data
_PREFILTER = np.sqrt(3.0) * _Z ** np.abs(np.arange(-_TAPS, _TAPS + 1))
PREFILTER_MARGIN = _TAPS + 2
N_PARAMS = 6  # d, e, gain, offset, s_x, s_y
_SIXTH = np.float32(1.0 / 6.0)


def bspline_coefficients(image: F32) -> F32:
    """Cubic B-spline coefficients c of ``image`` (interpolating: Σ c[k]·β³(x − k) = image[x]).

    Mirror boundary; exact to < 1e-6 relative beyond :data:`PREFILTER_MARGIN` px of the border.

    >>> img = np.random.default_rng(0).uniform(0, 255, (40, 50)).astype(np.float32)
    >>> c = bspline_coefficients(img)
    >>> k = np.array([1, 4, 1], np.float32) / 6          # β³ at the integers
    >>> back = cv2.sepFilter2D(c, cv2.CV_32F, k, k, borderType=cv2.BORDER_REFLECT_101)
    >>> bool(np.abs(back - img)[12:-12, 12:-12].max() < 1e-3)      # DN
    True
    """
    k = (_PREFILTER / _PREFILTER.sum()).astype(np.float32)
    out = cv2.sepFilter2D(
        np.asarray(image, np.float32), cv2.CV_32F, k, k, borderType=cv2.BORDER_REFLECT_101
    )
    return np.asarray(out, dtype=np.float32)


def _weights(f: F32) -> F32:
    """Cubic B-spline weights of the taps at offsets −1, 0, 1, 2 from floor(x); f = x − floor(x)."""
    f2 = f * f
    f3 = f2 * f
    g = 1 - f
    return np.stack([g * g * g, 4 - 6 * f2 + 3 * f3, 1 + 3 * (f + f2 - f3), f3], -1) * _SIXTH


def _block(coef: F32, iy: I64, c0: I64, rows: int, cols: int) -> tuple[F32, NDArray[np.bool_]]:
    """Blocks coef[iy + i, c0 + j] (n, rows, cols), clipped; ok = fully inside the image."""
    h, w = coef.shape
    r = iy[:, None] + np.arange(rows)[None, :]
    c = c0[:, None] + np.arange(cols)[None, :]
    ok = (r[:, 0] >= 0) & (r[:, -1] < h) & (c[:, 0] >= 0) & (c[:, -1] < w)
    return coef[np.clip(r, 0, h - 1)[:, :, None], np.clip(c, 0, w - 1)[:, None, :]], ok


def sample_windows(
    coef: F32, x0: I64, y0: I64, theta: F64, r: int, slant: bool
) -> tuple[F32, NDArray[np.bool_]]:
    """Spline values at the warped windows of :func:`refine_lk`, shape (n, M, M), and ``inside``.

    Rows share one fractional y offset per window (y weights are applied to a gathered block).
    Without slant the x offset is shared too and both passes are banded matrix products; with
    slant every sample has its own x weights.
    """
    n, m = len(x0), 2 * r + 1
    d, e = theta[:, 0], theta[:, 1]
    yc = y0 - e
    iy = np.floor(yc).astype(np.int64)
    wy = _weights((yc - iy).astype(np.float32))
    idx = np.arange(m)
    band_y = np.zeros((n, m, m + 3), np.float32)
    for k in range(4):
        band_y[:, idx, idx + k] = wy[:, k, None]
    if not slant:
        xc = x0 - d
        ix = np.floor(xc).astype(np.int64)
        wx = _weights((xc - ix).astype(np.float32))
        blk, ok = _block(coef, iy - r - 1, ix - r - 1, m + 3, m + 3)
        band_x = np.zeros((n, m + 3, m), np.float32)
        for k in range(4):
            band_x[:, idx + k, idx] = wx[:, k, None]
        return band_y @ blk @ band_x, ok
    sx, sy = theta[:, 4], theta[:, 5]
    u = np.arange(-r, r + 1, dtype=np.float64)
    xs = (x0 - d)[:, None, None] + u[None, None, :] * (1 - sx)[:, None, None]
    xs = (xs - sy[:, None, None] * u[None, :, None]).astype(np.float32)
    fl = np.floor(xs)
    wx = _weights(xs - fl).reshape(-1, 4)
    ix = fl.astype(np.int64)
    c0 = ix.reshape(n, -1).min(axis=1) - 1
    width = int((ix.reshape(n, -1).max(axis=1) - c0).max()) + 3
    blk, ok = _block(coef, iy - r - 1, c0, m + 3, width)
    rowsum = (band_y @ blk).ravel()  # (n, M, width): y-interpolated rows
    base = (np.arange(n)[:, None, None] * m + idx[None, :, None]) * width - c0[:, None, None] - 1
    flat = (base + ix).ravel()
    val = wx[:, 0] * rowsum[flat]
    for k in range(1, 4):
        val += wx[:, k] * rowsum[flat + k]
    return val.reshape(n, m, m), ok


@dataclass(frozen=True, eq=False)
class Refinement:
    """Result of :func:`refine_lk` for N windows.

    Attributes
    ----------
    d, e : ndarray, shape (N,)
        Disparity and non-disparity error at the window centre, px.
    gain, offset : ndarray, shape (N,)
        Photometric map left ≈ gain · right + offset.
    slant : ndarray, shape (N, 2)
        Disparity gradient (∂d/∂x, ∂d/∂y) over the window, px/px (zeros without slant).
    converged : ndarray of bool, shape (N,)
        The (d, e) update fell below ``tol`` within ``max_iter`` steps, the window stayed in the
        image, the normal equations were well conditioned and the slant within bounds.
    iterations : ndarray of int, shape (N,)
    cov_unit : ndarray, shape (N, 2, 2)
        Covariance of (d, e) per unit residual variance, px²/DN²
        (:func:`~phonestereo.features.crlb.weighted_ls_covariance`); NaN where not converged.
    residual_var : ndarray, shape (N,)
        A-posteriori residual variance Σ w r² / (Σ w − tr(H⁻¹ JᵀW²J)), DN².
    zncc : ndarray, shape (N,)
        Weighted zero-mean NCC of the left window with the warped right window at the solution.
    template_std : ndarray, shape (N,)
        Weighted standard deviation of the left window, DN.
    """

    d: F64
    e: F64
    gain: F64
    offset: F64
    slant: F64
    converged: NDArray[np.bool_]
    iterations: I64
    cov_unit: F64
    residual_var: F64
    zncc: F64
    template_std: F64


def gaussian_window(radius: int, sigma_w: float) -> F64:
    """Weights exp(−(u² + v²) / 2σ²) on the (2r + 1)² window, peak 1, shape (M, M)."""
    u = np.arange(-radius, radius + 1, dtype=np.float64)
    return np.exp(-0.5 * (u[:, None] ** 2 + u[None, :] ** 2) / float(sigma_w) ** 2)


def _windows(img: F32, x0: I64, y0: I64, r: int) -> F32:
    u = np.arange(-r, r + 1)
    out = img[y0[:, None, None] + u[None, :, None], x0[:, None, None] + u[None, None, :]]
    return np.ascontiguousarray(out.reshape(len(x0), -1), dtype=np.float32)


def _template_gradients(coef: F32, x0: I64, y0: I64, r: int) -> tuple[F32, F32]:
    """Exact spline derivatives ∂L/∂x, ∂L/∂y at the window pixels, each (n, M²), DN/px."""
    m = 2 * r + 1
    h, w = coef.shape
    k = np.arange(-r - 1, r + 2)
    rows = np.clip(y0[:, None] + k[None, :], 0, h - 1)
    cols = np.clip(x0[:, None] + k[None, :], 0, w - 1)
    blk = coef[rows[:, :, None], cols[:, None, :]]  # (n, M + 2, M + 2)
    dx = 0.5 * (blk[:, :, 2:] - blk[:, :, :-2])
    sm = (blk[:, :, :-2] + 4 * blk[:, :, 1:-1] + blk[:, :, 2:]) / 6
    gx = (dx[:, :-2] + 4 * dx[:, 1:-1] + dx[:, 2:]) / 6
    gy = 0.5 * (sm[:, 2:] - sm[:, :-2])
    return gx.reshape(len(x0), m * m), gy.reshape(len(x0), m * m)


def _chain(theta: F64, npar: int) -> F64:
    """C (k, p, 6): J = C · [∂L/∂x, ∂L/∂y, u·∂L/∂x, v·∂L/∂x, 1, R(warp)] (module docstring).

    At the solution a·∂R/∂x·(1 − s_x) = ∂L/∂x and a·∂R/∂y = ∂L/∂y + s_y·a·∂R/∂x, so
    J_d = −f·L_x, J_e = −L_y − s_y·f·L_x, J_a = R, J_b = 1, J_sx = −f·u·L_x, J_sy = −f·v·L_x
    with f = 1 / (1 − s_x).
    """
    k = len(theta)
    f = 1.0 / (1.0 - theta[:, 4])
    c = np.zeros((k, npar, 6))
    c[:, 0, 0] = -f
    c[:, 1, 0], c[:, 1, 1] = -theta[:, 5] * f, -1.0
    c[:, 2, 5] = 1.0
    c[:, 3, 4] = 1.0
    if npar == N_PARAMS:
        c[:, 4, 2], c[:, 5, 3] = -f, -f
    return c


def _projections(gx: F32, gy: F32, x: F32, uu: F32, vv: F32) -> F32:
    """Σ over the window of [L_x, L_y, u·L_x, v·L_x, 1] · x, shape (k, 5)."""
    gxx = gx * x
    return np.stack([gxx.sum(1), (gy * x).sum(1), gxx @ uu, gxx @ vv, x.sum(1)], axis=1)


def _basis_gram(gx: F64, gy: F64, w: F64, uu: F64, vv: F64) -> F64:
    """Σ w·b_i·b_j over the window for the fixed basis [L_x, L_y, u·L_x, v·L_x, 1], (n, 5, 5)."""
    mom = np.stack([np.ones_like(uu), uu, vv, uu * uu, uu * vv, vv * vv], axis=1) * w[:, None]
    xx = (gx * gx) @ mom  # Σ w L_x² · [1, u, v, u², uv, v²]
    xy = (gx * gy) @ mom[:, :3]
    x1 = gx @ mom[:, :3]
    g = np.empty((len(gx), 5, 5))
    rows = [
        (0, 0, xx[:, 0]), (0, 1, xy[:, 0]), (0, 2, xx[:, 1]), (0, 3, xx[:, 2]), (0, 4, x1[:, 0]),
        (1, 1, (gy * gy) @ mom[:, 0]), (1, 2, xy[:, 1]), (1, 3, xy[:, 2]), (1, 4, gy @ mom[:, 0]),
        (2, 2, xx[:, 3]), (2, 3, xx[:, 4]), (2, 4, x1[:, 1]),
        (3, 3, xx[:, 5]), (3, 4, x1[:, 2]),
        (4, 4, np.full(len(gx), mom[:, 0].sum())),
    ]  # fmt: skip
    for i, j, v in rows:
        g[:, i, j] = g[:, j, i] = v
    return g


def _gram(basis_gram: F64, proj: NDArray[np.floating], self_term: NDArray[np.floating]) -> F64:
    """The 6 × 6 Gram matrix of [fixed basis, R(warp)] from its blocks, shape (k, 6, 6)."""
    k = len(proj)
    g = np.empty((k, 6, 6))
    g[:, :5, :5] = basis_gram
    g[:, :5, 5] = g[:, 5, :5] = proj
    g[:, 5, 5] = self_term
    return g


def refine_lk(
    left: F32,
    left_coef: F32,
    right_coef: F32,
    xy: I64,
    d0: F64,
    e0: F64,
    *,
    radius: int = 7,
    sigma_w: float = 3.0,
    slant: bool = True,
    max_slant: float = 0.5,
    max_iter: int = 10,
    tol: float = 1e-3,
    max_step: float = 1.5,
) -> Refinement:
    """Refine integer-pixel matches to sub-pixel (d, e) by Gauss–Newton.

    Parameters
    ----------
    left : ndarray, shape (H, W), float32
        Left (wide) image, rectified.
    left_coef, right_coef : ndarray, shape (H, W), float32
        :func:`bspline_coefficients` of the left and right images, in the same pixel frame.
    xy : ndarray of int, shape (N, 2)
        Window centres (x, y) in the left image, integer pixels.
    d0, e0 : ndarray, shape (N,)
        Starting disparity and non-disparity error, px (e.g. the NCC peak + parabola).
    radius, sigma_w : int, float
        Window half size (M = 2r + 1) and Gaussian weight σ, px.
    slant : bool
        Fit the disparity gradient (s_x, s_y); False fits a translation (faster).
    max_slant : float
        |s_x| or |s_y| above this is not a surface but a failure (not converged).
    max_iter, tol : int, float
        Iteration limit and convergence threshold on the (d, e) update, px.
    max_step : float
        A window that wanders farther than this from (d0, e0) is not converged, px.

    Returns
    -------
    Refinement

    Raises
    ------
    InputError
        A window is not inside ``left``.
    """
    xy = np.asarray(xy, dtype=np.int64).reshape(-1, 2)
    n, r = len(xy), int(radius)
    h, w = left.shape
    x0, y0 = xy[:, 0], xy[:, 1]
    if n and (x0.min() < r or y0.min() < r or x0.max() >= w - r or y0.max() >= h - r):
        raise InputError(f"windows of radius {r} must lie inside the left image {w}×{h}")
    npar = N_PARAMS if slant else 4
    tmpl = _windows(left, x0, y0, r)
    tgx, tgy = _template_gradients(left_coef, x0, y0, r)
    wts = gaussian_window(r, sigma_w).ravel()
    wn = wts / wts.sum()
    u = np.arange(-r, r + 1, dtype=np.float64)
    uu, vv = np.tile(u, 2 * r + 1), np.repeat(u, 2 * r + 1)
    gx64, gy64 = tgx.astype(np.float64), tgy.astype(np.float64)
    gram1 = _basis_gram(gx64, gy64, wts, uu, vv)  # Σ w b_i b_j
    gram2 = _basis_gram(gx64, gy64, wts**2, uu, vv)  # Σ w² b_i b_j
    # per-iteration products in float32 (sums of ≤ 4 k terms; the normal equations in float64)
    w32, wn32, uu32, vv32 = (a.astype(np.float32) for a in (wts, wn, uu, vv))
    theta = np.zeros((n, N_PARAMS))
    theta[:, 0], theta[:, 1] = d0, e0
    start = theta[:, :2].copy()
    ok_out, iters = np.zeros(n, bool), np.zeros(n, np.int64)
    cov, rvar, zncc = np.full((n, 2, 2), np.nan), np.full(n, np.nan), np.full(n, np.nan)
    active = np.arange(n)
    for it in range(max_iter):
        if not len(active):
            break
        th = theta[active]
        val, inside = sample_windows(right_coef, x0[active], y0[active], th, r, slant)
        val32 = val.reshape(len(active), -1)
        t = tmpl[active]
        if it == 0:  # photometric start: match the weighted mean and standard deviation
            mt, mr = t @ wn32, val32 @ wn32
            st = np.sqrt(np.maximum(((t - mt[:, None]) ** 2) @ wn32, 0))
            sr = np.sqrt(np.maximum(((val32 - mr[:, None]) ** 2) @ wn32, 0))
            th[:, 2] = st / np.maximum(sr, 1e-6)
            th[:, 3] = mt - th[:, 2] * mr
        ab = th[:, 2:4].astype(np.float32)
        res = t - ab[:, :1] * val32 - ab[:, 1:]
        gx, gy = tgx[active], tgy[active]
        wval, wres = val32 * w32, res * w32
        chain = _chain(th, npar)
        gram = _gram(gram1[active], _projections(gx, gy, wval, uu32, vv32), (wval * val32).sum(1))
        proj_res = np.concatenate(
            [_projections(gx, gy, wres, uu32, vv32), (wres * val32).sum(1)[:, None]], axis=1
        )
        hess = chain @ gram @ chain.transpose(0, 2, 1)
        step, spd = solve_spd(hess, (chain @ proj_res[:, :, None])[:, :, 0])
        good = inside & spd & np.isfinite(step).all(axis=1)
        step[~good] = 0.0
        th[:, :npar] += step
        theta[active], iters[active] = th, it + 1
        small = np.abs(step[:, :2]).max(axis=1) < tol
        bad = ~good | (np.abs(th[:, :2] - start[active]).max(axis=1) > max_step)
        bad |= np.abs(th[:, 4:]).max(axis=1) > max_slant
        fin = small & ~bad
        if fin.any():  # statistics from this (last) evaluation: the step was below tol
            i = np.flatnonzero(fin)
            w2v = wval[i] * w32
            g2 = _gram(
                gram2[active[i]],
                _projections(gx[i], gy[i], w2v, uu32, vv32),
                (w2v * val32[i]).sum(1),
            )
            c = chain[i]
            c_cov, dof = sandwich(hess[i], c @ g2 @ c.transpose(0, 2, 1), wts.sum())
            cov[active[i]] = c_cov[:, :2, :2]
            rvar[active[i]] = (res[i] * wres[i]).sum(1) / np.maximum(dof, 1.0)
            tc = t[i] - (t[i] @ wn32)[:, None]
            vc = val32[i] - (val32[i] @ wn32)[:, None]
            den = np.sqrt(((tc**2) @ wn32) * ((vc**2) @ wn32))
            zncc[active[i]] = ((tc * vc) @ wn32) / np.maximum(den, 1e-12)
            ok_out[active[i]] = True
        active = active[~(fin | bad)]
    tc = tmpl - (tmpl @ wn)[:, None]
    return Refinement(
        d=theta[:, 0].copy(),
        e=theta[:, 1].copy(),
        gain=theta[:, 2].copy(),
        offset=theta[:, 3].copy(),
        slant=theta[:, 4:6].copy(),
        converged=ok_out,
        iterations=iters,
        cov_unit=cov,
        residual_var=rvar,
        zncc=zncc,
        template_std=np.sqrt((tc**2) @ wn),
    )
