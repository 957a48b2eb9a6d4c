"""Sub-pixel left–right consistency: each match fitted again from the right image back to the left.

The NCC search already checks left–right consistency at the integer level (``lr_tolerance``,
:mod:`~phonestereo.features.search`). This is the same check after the sub-pixel fit: the right
window at the integer pixel nearest the match (x − d, y − e) is fitted to the left image's
spline by :func:`~phonestereo.features.subpixel.refine_lk` (the roles swapped), and its
disparity is compared with the left→right one at the same left point (the left fit's slant
carries d from the left window's centre to where the right window's centre lands).

With the roles swapped, refine_lk fits R(x_r + u) ≈ a·L(x_r + u − d′ − …), so the right pixel
x_r is the left point x_r − d′ and its disparity is −d′ (d′ = −d, e′ = −e).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from phonestereo.features.subpixel import refine_lk

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]

__all__ = ["ReverseFit", "reverse_fit"]


@dataclass(frozen=True, eq=False)
class ReverseFit:
    """The right→left fit of N matches, compared with their left→right fit."""

    #: ndarray, shape (N,). d_RL − d_LR at the left point the right window lands on, px (NaN
    #: where the reverse fit did not converge or its window left the image).
    delta_d: F64
    #: ndarray, shape (N,). The same for e, px.
    delta_e: F64
    #: ndarray of bool, shape (N,). The reverse fit converged.
    converged: NDArray[np.bool_]


def reverse_fit(
    right: F32,
    left_coef: F32,
    xy: NDArray[np.int64],
    d: F64,
    e: F64,
    slant: F64,
    *,
    radius: int,
    sigma_w: float,
    fit_slant: bool = True,
    max_slant: float = 0.5,
    max_iter: int = 10,
    tol: float = 1e-3,
) -> ReverseFit:
    """Fit each match's right window back to the left image and compare the disparities.

    Parameters
    ----------
    right : ndarray, shape (H, W), float32
        The right image fitted by the left→right fit (same filtering as its spline).
    left_coef : ndarray, shape (H, W), float32
        :func:`~phonestereo.features.subpixel.bspline_coefficients` of the left image fitted.
    xy : ndarray of int, shape (N, 2)
        The matches' left window centres.
    d, e : ndarray, shape (N,)
        Their left→right disparity and row error, px.
    slant : ndarray, shape (N, 2)
        Their left→right disparity gradient (∂d/∂x, ∂d/∂y), px/px.
    radius, sigma_w, fit_slant, max_slant, max_iter, tol
        As the left→right fit's (:func:`~phonestereo.features.subpixel.refine_lk`).

    Returns
    -------
    ReverseFit

    Examples
    --------
    A texture shifted by 5.3 px: both directions agree.

    >>> from phonestereo.features.subpixel import bspline_coefficients
    >>> rng = np.random.default_rng(0)
    >>> f = np.fft.fft2(rng.standard_normal((80, 120)))
    >>> fx = np.fft.fftfreq(120)[None, :]
    >>> lp = np.exp(-2 * np.pi**2 * 1.5**2 * (fx**2 + np.fft.fftfreq(80)[:, None] ** 2))
    >>> left = (128 + 600 * np.real(np.fft.ifft2(f * lp))).astype(np.float32)
    >>> right = (128 + 600 * np.real(np.fft.ifft2(f * lp * np.exp(2j * np.pi * fx * 5.3))))
    >>> right = right.astype(np.float32)
    >>> xy = np.array([[60, 40], [70, 30]])
    >>> lr = refine_lk(left, None, bspline_coefficients(right), xy, np.full(2, 5.0), np.zeros(2))
    >>> rev = reverse_fit(right, bspline_coefficients(left), xy, lr.d, lr.e, lr.slant,
    ...                   radius=7, sigma_w=3.0)
    >>> bool(np.all(np.abs(rev.delta_d) < 1e-3)), bool(rev.converged.all())
    (True, True)
    """
    xy = np.asarray(xy, np.int64).reshape(-1, 2)
    n, r = len(xy), int(radius)
    h, w = right.shape
    xr, yr = np.rint(xy[:, 0] - d), np.rint(xy[:, 1] - e)
    inside = np.isfinite(xr) & np.isfinite(yr)
    inside &= (xr >= r) & (yr >= r) & (xr < w - r) & (yr < h - r)
    delta_d, delta_e = np.full(n, np.nan), np.full(n, np.nan)
    conv = np.zeros(n, bool)
    idx = np.flatnonzero(inside)
    pts = np.column_stack([xr[idx], yr[idx]]).astype(np.int64)
    rev = refine_lk(
        right,
        None,
        left_coef,
        pts,
        -d[idx],
        -e[idx],
        radius=r,
        sigma_w=sigma_w,
        slant=fit_slant,
        max_slant=max_slant,
        max_iter=max_iter,
        tol=tol,
    )
    # the right centre lands on the left point (x_r − d′, y_r − e′); the left fit's disparity
    # there is d + s_x·Δx + s_y·Δy (its slant is ∂d/∂x, ∂d/∂y in left pixels), e unchanged
    dx = pts[:, 0] - rev.d - xy[idx, 0]
    dy = pts[:, 1] - rev.e - xy[idx, 1]
    s = np.asarray(slant)[idx]
    d_lr = d[idx] + s[:, 0] * dx + s[:, 1] * dy
    ok = rev.converged
    delta_d[idx] = np.where(ok, -rev.d - d_lr, np.nan)
    delta_e[idx] = np.where(ok, -rev.e - e[idx], np.nan)
    conv[idx] = ok
    return ReverseFit(delta_d, delta_e, conv)
