"""The template windows of :func:`~phonestereo.features.subpixel.refine_lk` and their exact
cubic-B-spline derivatives, filtered from the left image (no prefilter of the whole image).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]
I64 = NDArray[np.int64]

__all__ = ["PREFILTER", "TAPS", "box_gradients", "image_gradients", "window_gradients"]

_Z = np.sqrt(3.0) - 2.0  # pole of the cubic B-spline prefilter
TAPS = 10  #: |z|^11 ≈ 5e-7: the FIR truncation is invisible in 8-bit data
#: The cubic B-spline's recursive prefilter as a (2·TAPS + 1)-tap FIR (unnormalised).
PREFILTER = np.sqrt(3.0) * _Z ** np.abs(np.arange(-TAPS, TAPS + 1))
_TAPS, _PREFILTER = TAPS, PREFILTER


def _derivative_fir(r: int) -> F32:
    """(M + 2T, M) matrix D with (row of image) @ D = spline ∂/∂x at the M window pixels.

    The spline's y smoothing undoes its y prefilter, so ∂L/∂x at the integers is the image
    filtered along x only by prefilter ∗ central difference (2T + 1 taps, T = taps + 1).
    """
    t, m = _TAPS + 1, 2 * r + 1
    k = np.pad(_PREFILTER / _PREFILTER.sum(), 1)
    kd = 0.5 * (np.roll(k, 1) - np.roll(k, -1))  # tap o: 0.5·(k[o − 1] − k[o + 1])
    mat = np.zeros((m + 2 * t, m))
    for i in range(2 * t + 1):
        mat[np.arange(m) + i, np.arange(m)] = kd[i]
    return mat.astype(np.float32)


def _derivative_kernel() -> F32:
    """The 2T + 1 taps of :func:`_derivative_fir` (prefilter ∗ central difference), as a
    correlation kernel for cv2.sepFilter2D (tap o + T multiplies the pixel at offset o)."""
    k = np.pad(_PREFILTER / _PREFILTER.sum(), 1)
    return (0.5 * (np.roll(k, 1) - np.roll(k, -1))).astype(np.float32)


def image_gradients(img: F32, x0: I64, y0: I64, r: int) -> tuple[F32, F32, F32]:
    """Windows and the exact spline derivatives ∂L/∂x, ∂L/∂y there, each (n, M²), DN, DN/px.

    Filtered from the image (mirror border) by :func:`_derivative_fir`: the same values as
    differentiating :func:`bspline_coefficients`, without prefiltering the whole image. Where
    the windows cover their bounding box densely (the matcher's keypoints), the box is
    filtered once (cv2.sepFilter2D) and the windows gathered from it; sparse windows (faces
    far apart in a large image) are filtered window by window. The two agree to float32
    rounding (~1e-6 relative).
    """
    t, m, n = _TAPS + 1, 2 * r + 1, len(x0)
    h, w = img.shape
    if n:
        bx0, by0 = max(int(x0.min()) - r - t, 0), max(int(y0.min()) - r - t, 0)
        bx1, by1 = min(int(x0.max()) + r + t + 1, w), min(int(y0.max()) + r + t + 1, h)
        if (bx1 - bx0) * (by1 - by0) <= 2 * n * m * (m + 2 * t):
            return box_gradients(img, x0, y0, r, (bx0, by0, bx1, by1))
    return window_gradients(img, x0, y0, r)


def window_gradients(img: F32, x0: I64, y0: I64, r: int) -> tuple[F32, F32, F32]:
    """:func:`image_gradients` window by window (each row and column gathered, then the
    derivative FIR as a matrix product per window)."""
    t, m, n = _TAPS + 1, 2 * r + 1, len(x0)
    h, w = img.shape
    u, v = np.arange(-r, r + 1), np.arange(-r - t, r + t + 1)

    def mirror(i: I64, size: int) -> I64:
        i = np.abs(i)
        return np.where(i > size - 1, 2 * (size - 1) - i, i)

    mat = _derivative_fir(r)
    ys, xs = mirror(y0[:, None] + v, h), mirror(x0[:, None] + v, w)
    px = img[(y0[:, None] + u)[:, :, None], xs[:, None, :]]  # (n, M, M + 2t)
    py = img[ys[:, None, :], (x0[:, None] + u)[:, :, None]]  # (n, M cols, M + 2t rows)
    # one small product per window: a single (n·M, M + 2t) product is big enough for
    # OpenBLAS to wake its second thread, which then spins for milliseconds after the call
    gx = px.astype(np.float32) @ mat
    gy = (py.astype(np.float32) @ mat).transpose(0, 2, 1).reshape(n, m * m)
    return np.ascontiguousarray(px[:, :, t : t + m].reshape(n, m * m)), gx.reshape(n, m * m), gy


def box_gradients(
    img: F32, x0: I64, y0: I64, r: int, box: tuple[int, int, int, int]
) -> tuple[F32, F32, F32]:
    """:func:`image_gradients` by filtering the box (x0, y0, x1, y1) that holds every window
    and its T-px filter reach (the reach clipped at the image border, where OpenCV's
    BORDER_REFLECT_101 is the mirror of :func:`image_gradients`)."""
    bx0, by0, bx1, by1 = box
    sub = np.ascontiguousarray(img[by0:by1, bx0:bx1], dtype=np.float32)
    kd, one = _derivative_kernel(), np.ones(1, np.float32)
    border = cv2.BORDER_REFLECT_101
    gx = cv2.sepFilter2D(sub, cv2.CV_32F, kd, one, borderType=border)
    gy = cv2.sepFilter2D(sub, cv2.CV_32F, one, kd, borderType=border)
    m, bw = 2 * r + 1, bx1 - bx0
    start = (y0 - r - by0) * bw + (x0 - r - bx0)
    offs = (np.arange(m)[:, None] * bw + np.arange(m)[None, :]).ravel()
    flat = start[:, None] + offs[None, :]
    return (np.take(sub.ravel(), flat), np.take(gx.ravel(), flat), np.take(gy.ravel(), flat))
