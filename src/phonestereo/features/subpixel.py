"""Sub-pixel disparity by 2-D Lucas–Kanade on a cubic B-spline of the right image (§1.2.1).

The thesis refines each NCC peak ("peak refinement on the windows"); here the refinement is a
Gauss–Newton fit of a window of the left image (at its own integer pixels, never resampled) to
the right image, so it measures both the disparity ``d`` and the non-disparity error ``e``::

    L(x0 + u, y0 + v) ≈ a · R(x0 + u − d − s_x·u − s_y·v,  y0 + v − e) + b

over the window |u|, |v| ≤ r with Gaussian weights w(u, v) (σ = ``sigma_w``). ``a, b`` absorb a
gain and offset between the cameras; ``(s_x, s_y)`` is the disparity gradient of a slanted
surface, so that ``d`` at the window centre is not biased by the slant. Conventions
(docs/conventions.md): ``d = x_left − x_right``, ``e = y_left − y_right``.

The Jacobian is taken from the left window's own spline gradients (at the solution
``a·∂R/∂x·(1 − s_x) = ∂L/∂x``), as in inverse-compositional / ESM alignment: only values of R
are resampled per iteration, the normal equations and their right side are assembled from
fixed per-window moments plus five dot products with the resampled values (no residual image),
and the fit converges in 2–3 iterations from the NCC start. The fixed point is the same as
with R's own gradients (the residual vanishes there for noise-free data).

Pixel locking: R is evaluated by exact cubic B-spline interpolation (coefficients from the
recursive prefilter of Unser et al., applied as a 21-tap FIR whose truncation error is < 1e-6 of
the signal), not on the NCC grid, so nothing pulls the estimate toward integer disparities: on a
band-limited texture shifted by an exact Fourier shift the bias is < 0.004 px at every fraction
(``tests/features/test_match_subpixel.py``).
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray

from phonestereo.errors import InputError
from phonestereo.features._threads import background
from phonestereo.features.crlb import einsum, sandwich, solve_spd
from phonestereo.features.refinement import Refinement
from phonestereo.features.spline_gradients import PREFILTER, TAPS, image_gradients
from phonestereo.heap import keep_large_arrays_on_the_heap

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

__all__ = [
    "Refinement",
    "bspline_coefficients",
    "cubic_bspline_weights",
    "gaussian_window",
    "refine_lk",
    "sample_windows",
]

_TAPS, _PREFILTER = TAPS, PREFILTER  # the spline prefilter (features/spline_gradients.py)
PREFILTER_MARGIN = _TAPS + 2
N_PARAMS = 6  # d, e, gain, offset, s_x, s_y
_SIXTH = np.float32(1.0 / 6.0)
SPLIT_AT = 96  #: from this many windows, two halves (the second on the helper thread)


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


def cubic_bspline_weights(f: NDArray[Any]) -> NDArray[Any]:
    """Cubic B-spline weights (..., 4) of the taps at offsets −1, 0, 1, 2 from floor(x);
    f = x − floor(x), float32 or float64 (the weights keep its precision)."""
    f2 = f * f
    f3 = f2 * f
    g = 1 - f
    return np.stack([g * g * g, 4 - 6 * f2 + 3 * f3, 1 + 3 * (f + f2 - f3), f3], -1) * _SIXTH


def _block(coef: F32, iy: I64, c0: I64, rows: int, cols: int) -> tuple[F32, NDArray[np.bool_]]:
    """Blocks coef[iy + i, c0 + j] (n, rows, cols), moved inside; ok = fully inside the image."""
    h, w = coef.shape
    ok = (iy >= 0) & (iy + rows <= h) & (c0 >= 0) & (c0 + cols <= w)
    # blocks of a strided view: no (n, rows, cols) index array to build and read
    blocks = sliding_window_view(coef, (rows, cols))
    return blocks[np.clip(iy, 0, h - rows), np.clip(c0, 0, w - cols)], ok


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
    wy = cubic_bspline_weights((yc - iy).astype(np.float32))
    idx = np.arange(m)
    band_y = np.zeros((n, m, m + 3), np.float32)
    for k in range(4):
        band_y[:, idx, idx + k] = wy[:, k, None]
    if not slant:
        xc = x0 - d
        ix = np.floor(xc).astype(np.int64)
        wx = cubic_bspline_weights((xc - ix).astype(np.float32))
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
    wx = cubic_bspline_weights(xs - fl).reshape(-1, 4)
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


def _wsum(a: NDArray[Any], w: NDArray[Any]) -> NDArray[Any]:
    """Σ_p a[k, p]·w[p] per row, without BLAS (its gemv wakes a second thread per call)."""
    return einsum("kp,p->k", a, w)


def _with_const(basis_part: F64, const: F64) -> F64:
    """(k, q) = [basis_part (k, q − 1), const (k,)]: a moment over the basis with its constant
    row appended last."""
    return np.concatenate([basis_part, const[:, None]], axis=1)


def _moments(bw: F64, b: NDArray[Any], w: F64, corner: float) -> F64:
    """Σ_p bw_i·b_j over a basis with its constant row appended last, shape (k, q, q):
    ``bw`` (k, q − 1, M²) the weighted rows, ``b`` their partners, ``w`` (M²,) the weight
    that makes a row of ``b`` one of ``bw`` (so Σ bw_const·b_j = Σ w·b_j) and ``corner`` the
    constant row's own moment."""
    k, q = bw.shape[0], bw.shape[1] + 1
    g = np.empty((k, q, q))
    g[:, :-1, :-1] = einsum("kqp,krp->kqr", bw, b)
    g[:, :-1, -1] = g[:, -1, :-1] = _wsum(b.reshape(-1, b.shape[-1]), w).reshape(k, q - 1)
    g[:, -1, -1] = corner
    return g


def gaussian_window(radius: int, sigma_w: float) -> F64:
    """Weights exp(−(u² + v²) / 2σ²) on the (2r + 1)² window, peak 1, shape (M, M)."""
    u = np.arange(-radius, radius + 1, dtype=np.float64)
    return np.exp(-0.5 * (u[:, None] ** 2 + u[None, :] ** 2) / float(sigma_w) ** 2)


def _chain(theta: F64, slant: bool) -> F64:
    """C (k, p, q): J = C · basis, the basis [L_x, L_y, (u·L_x, v·L_x,) 1, R(warp)].

    At the solution a·∂R/∂x·(1 − s_x) = ∂L/∂x and a·∂R/∂y = ∂L/∂y + s_y·a·∂R/∂x, so
    J_d = −f·L_x, J_e = −L_y − s_y·f·L_x, J_a = R, J_b = 1, J_sx = −f·u·L_x, J_sy = −f·v·L_x
    with f = 1 / (1 − s_x); without slant (p = q = 4) f = 1 and s_y = 0.
    """
    k = len(theta)
    if not slant:
        c = np.zeros((k, 4, 4))
        c[:, 0, 0] = c[:, 1, 1] = -1.0
        c[:, 2, 3] = c[:, 3, 2] = 1.0
        return c
    f = 1.0 / (1.0 - theta[:, 4])
    c = np.zeros((k, N_PARAMS, 6))
    c[:, 0, 0] = -f
    c[:, 1, 0], c[:, 1, 1] = -theta[:, 5] * f, -1.0
    c[:, 2, 5] = 1.0
    c[:, 3, 4] = 1.0
    c[:, 4, 2], c[:, 5, 3] = -f, -f
    return c


def _gram(basis_gram: F64, proj: F64, self_term: F64) -> F64:
    """The Gram matrix of [fixed basis, R(warp)] from its blocks, shape (k, q, q)."""
    k, q = proj.shape[0], proj.shape[1] + 1
    g = np.empty((k, q, q))
    g[:, :-1, :-1] = basis_gram
    g[:, :-1, -1] = g[:, -1, :-1] = proj
    g[:, -1, -1] = self_term
    return g


def refine_lk(
    left: F32,
    left_coef: F32 | None,
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
    influence: bool = False,
) -> Refinement:
    """Refine integer-pixel matches to sub-pixel (d, e) by Gauss–Newton.

    Parameters
    ----------
    left : ndarray, shape (H, W), float32
        Left (wide) image, rectified.
    left_coef : None
        Unused (kept for compatibility): the template gradients are filtered from ``left``.
    right_coef : ndarray, shape (H, W), float32
        :func:`bspline_coefficients` of the right image, in the same pixel frame as ``left``.
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
    influence : bool
        Also return the influence images of d, e and the residual images
        (:attr:`Refinement.influence`, :attr:`Refinement.residual`; None otherwise).

    Returns
    -------
    Refinement

    Raises
    ------
    InputError
        A window is not inside ``left``.
    """
    keep_large_arrays_on_the_heap()  # the windows' arrays are megabytes (phonestereo.heap)
    xy = np.asarray(xy, dtype=np.int64).reshape(-1, 2)
    n, r = len(xy), int(radius)
    h, w = left.shape
    x0, y0 = xy[:, 0], xy[:, 1]
    if n and (x0.min() < r or y0.min() < r or x0.max() >= w - r or y0.max() >= h - r):
        raise InputError(f"windows of radius {r} must lie inside the left image {w}×{h}")
    left = np.asarray(left, np.float32)
    d0, e0 = np.broadcast_to(d0, (n,)), np.broadcast_to(e0, (n,))
    opts = (r, sigma_w, slant, max_slant, max_iter, tol, max_step, influence)
    if n < SPLIT_AT:
        return _refine(left, right_coef, xy, d0, e0, *opts)
    # two halves always (the same numbers with one thread or two), the second on the helper
    # thread: independent windows, and NumPy releases the GIL in their array work
    k = n // 2
    other = background(_refine, left, right_coef, xy[k:], d0[k:], e0[k:], *opts)
    first = _refine(left, right_coef, xy[:k], d0[:k], e0[:k], *opts)
    return Refinement.concat([first, other.result()])


def _refine(
    left: F32, right_coef: F32, xy: I64, d0: F64, e0: F64, r: int, sigma_w: float, slant: bool,
    max_slant: float, max_iter: int, tol: float, max_step: float, influence: bool,
) -> Refinement:
    """:func:`refine_lk` of a batch of windows (checked inside ``left``)."""
    n, x0, y0 = len(xy), xy[:, 0], xy[:, 1]
    npar = N_PARAMS if slant else 4
    tmpl, tgx, tgy = image_gradients(left, x0, y0, r)
    wts = gaussian_window(r, sigma_w).ravel()
    wn = wts / wts.sum()
    u = np.arange(-r, r + 1, dtype=np.float64)
    uu, vv = np.tile(u, 2 * r + 1), np.repeat(u, 2 * r + 1)
    # fixed basis [L_x, L_y, (u·L_x, v·L_x,) 1] and its weighted moments (float64 sums, per
    # window). The constant row is not stored and only the weighted rows are float64: these
    # (n, q, M²) arrays are megabytes, and fresh megabytes cost page faults on every call.
    parts = [tgx, tgy, uu * tgx, vv * tgx] if slant else [tgx, tgy]
    base = np.stack(np.broadcast_arrays(*parts), axis=1)  # float32 without slant (exact)
    bw = base * wts  # (n, q − 2, M²), float64: Σ over p of bw·x is Σ w b_i x
    gram1 = _moments(bw, base, wts, wts.sum())  # Σ w b_i b_j, the constant row included
    gram2 = _moments(bw, bw, wts, (wts * wts).sum())  # Σ w² b_i b_j
    bt = _with_const(einsum("kqp,kp->kq", bw, tmpl), _wsum(tmpl, wts))  # Σ w b_i L
    wn32 = wn.astype(np.float32)
    theta = np.zeros((n, N_PARAMS))
    theta[:, 0], theta[:, 1] = d0, e0
    start = theta[:, :2].copy()
    ok_out, iters = np.zeros(n, bool), np.zeros(n, np.int64)
    cov, rvar, zncc = np.full((n, 2, 2), np.nan), np.full(n, np.nan), np.full(n, np.nan)
    infl = np.full((n if influence else 0, 2, len(wts)), np.nan, np.float32)
    resid = np.full((n if influence else 0, len(wts)), np.nan, np.float32)
    active = np.arange(n)
    for it in range(max_iter):
        if not len(active):
            break
        th = theta[active]
        # all windows still active: views of the per-window arrays instead of copies (the
        # (n, q, M²) float64 basis is megabytes; the same numbers either way)
        sel: Any = slice(None) if len(active) == n else active
        val, inside = sample_windows(right_coef, x0[sel], y0[sel], th, r, slant)
        val32 = val.reshape(len(active), -1)
        t = tmpl[sel]
        if it == 0:  # photometric start: match the weighted mean and standard deviation
            mt, mr = _wsum(t, wn32), _wsum(val32, wn32)
            st = np.sqrt(np.maximum(_wsum((t - mt[:, None]) ** 2, wn32), 0))
            sr = np.sqrt(np.maximum(_wsum((val32 - mr[:, None]) ** 2, wn32), 0))
            th[:, 2] = st / np.maximum(sr, 1e-6)
            th[:, 3] = mt - th[:, 2] * mr
        vw = val32 * wts  # w·R, float64
        a, b = th[:, 2].copy(), th[:, 3].copy()
        g1 = gram1[sel]
        pv = _with_const(einsum("kqp,kp->kq", bw[sel], val32), vw.sum(axis=1))  # Σ w b_i R
        rr, rl = einsum("kp,kp->k", vw, val32), einsum("kp,kp->k", vw, t)  # Σ w R², R L
        # Σ w [b, R] res with res = L − a·R − b, from the moments (no residual image)
        proj_res = np.concatenate(
            [
                bt[sel] - a[:, None] * pv - b[:, None] * g1[:, :, -1],
                (rl - a * rr - b * pv[:, -1])[:, None],
            ],
            axis=1,
        )
        chain = _chain(th, slant)
        hess = chain @ _gram(g1, pv, rr) @ chain.transpose(0, 2, 1)
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
            ai = active[i]
            vwi = vw[i]
            g2 = _gram(  # Σ w² [b, R] [b, R]
                gram2[ai],
                _with_const(einsum("kqp,kp->kq", bw[ai], vwi), _wsum(vwi, wts)),
                einsum("kp,kp->k", vwi, vwi),
            )
            c = chain[i]
            c_cov, dof = sandwich(hess[i], c @ g2 @ c.transpose(0, 2, 1), wts.sum())
            cov[ai] = c_cov[:, :2, :2]
            res = tmpl[ai] - a[i, None] * val32[i] - b[i, None]  # float64
            rvar[ai] = _wsum(res * res, wts) / np.maximum(dof, 1.0)
            if influence:  # G = rows (d, e) of H⁻¹·C times the weighted basis [b, R]
                resid[ai] = res
                hc, _ = solve_spd(hess[i], c)
                const = np.broadcast_to(wts, (len(i), 1, len(wts)))
                full = np.concatenate([bw[ai], const, vwi[:, None, :]], axis=1)
                infl[ai] = hc[:, :2] @ full
            tc = t[i] - _wsum(t[i], wn32)[:, None]
            vc = val32[i] - _wsum(val32[i], wn32)[:, None]
            den = np.sqrt(_wsum(tc**2, wn32) * _wsum(vc**2, wn32))
            zncc[ai] = _wsum(tc * vc, wn32) / np.maximum(den, 1e-12)
            ok_out[ai] = True
        active = active[~(fin | bad)]
    tc = tmpl - _wsum(tmpl, wn)[:, None]
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
        template_std=np.sqrt(_wsum(tc**2, wn)),
        influence=infl if influence else None,
        residual=resid if influence else None,
    )
