"""The window of the saddle fit (:mod:`~phonestereo.features.saddle`): pixels, design, weights."""

from __future__ import annotations

import numpy as np


def fit_window(
    centres: np.ndarray, radius: float, shape: tuple[int, ...] | None = None
) -> tuple[np.ndarray, ...]:
    """Sample pixels, design matrix and weights of the fit's (2⌈radius⌉ + 1)² window.

    Parameters
    ----------
    centres : ndarray, shape (N, 2)
        Window centres (x, y), px; the pixels are those about their rounded positions.
    radius : float
        Window radius, px: Gaussian weights of σ = radius / 2, cut (with a 1 px ramp) at it.
    shape : (int, int), optional
        Image (H, W): pixel indices clipped into it.

    Returns
    -------
    xs, ys : ndarray of int, shape (N, n)
        Pixel columns and rows, n = (2⌈radius⌉ + 1)².
    A : ndarray, shape (N, n, 6)
        Design [u², u·v, v², u, v, 1] of (u, v) = pixel − centre.
    wts : ndarray, shape (N, n)
        Weights.
    """
    r = int(np.ceil(radius))
    k = np.arange(-r, r + 1)
    gx, gy = np.meshgrid(k, k)
    base = np.round(centres).astype(np.int64)  # (k, 2)
    xs = base[:, 0, None] + gx.ravel()[None, :]
    ys = base[:, 1, None] + gy.ravel()[None, :]
    if shape is not None:
        xs = np.clip(xs, 0, shape[1] - 1)
        ys = np.clip(ys, 0, shape[0] - 1)
    u = xs - centres[:, 0, None]
    v = ys - centres[:, 1, None]
    d2 = u * u + v * v
    sigma = radius / 2.0
    wts = np.exp(-d2 / (2 * sigma**2)) * np.clip(radius + 0.5 - np.sqrt(d2), 0.0, 1.0)
    A = np.stack([u * u, u * v, v * v, u, v, np.ones_like(u)], axis=2)  # (k, n, 6)
    return xs, ys, A, wts


__all__ = ["fit_window"]
