"""Histogram and global heuristic filters on a set of matches (thesis §1.2.1, §4.1.3).

After every match passed its own tests (NCC peak, uniqueness, convexity, left–right, the
sub-pixel fit), these look at the matches together:

* :func:`row_error_filter` — after rectification the non-disparity error e is a smooth,
  nearly constant field (calibration error, not scene); a match whose e departs from a robust
  affine fit e ≈ c₀ + c₁x + c₂y is a mismatch on a repetitive texture.
* :func:`histogram_filter` — real surfaces fill neighbouring disparity bins; a disparity whose
  bin and both neighbours hold fewer than a few matches is an isolated outlier.
* :func:`support_filter` — a match needs at least one neighbour in the image (among its k
  nearest) with a similar disparity; a lone window that disagrees with all its neighbours is
  rejected (the surfaces of a scene are larger than a window).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

F64 = NDArray[np.float64]
Mask = NDArray[np.bool_]

_MAD = 1.4826


def row_error_filter(
    xy: F64, e: F64, *, floor_px: float = 0.5, k_mad: float = 5.0, iterations: int = 3
) -> Mask:
    """Keep matches whose e is within max(floor, k·σ_MAD) of a robust affine fit over (x, y).

    >>> xy = np.stack([np.arange(10.0) * 50, np.zeros(10)], 1)
    >>> e = 0.001 * xy[:, 0]; e[4] += 3.0                   # one mismatch 3 px off its row
    >>> row_error_filter(xy, e).tolist()
    [True, True, True, True, False, True, True, True, True, True]
    """
    n = len(e)
    keep = np.ones(n, bool)
    if n < 4:
        return keep
    a = np.column_stack([np.ones(n), xy - xy.mean(axis=0)])
    for _ in range(iterations):
        coef, *_ = np.linalg.lstsq(a[keep], e[keep], rcond=None)
        dev = np.abs(e - a @ coef)
        tol = max(floor_px, k_mad * _MAD * float(np.median(dev[keep])))
        new = dev <= tol
        if (new == keep).all() or new.sum() < 4:
            break
        keep = new
    return keep


def histogram_filter(d: F64, *, bin_px: float = 1.0, min_count: int = 3) -> Mask:
    """Keep disparities whose bin plus its two neighbours hold at least ``min_count`` matches.

    >>> histogram_filter(np.array([10.2, 10.4, 10.9, 11.3, 30.0])).tolist()
    [True, True, True, True, False]
    """
    if len(d) == 0:
        return np.zeros(0, bool)
    b = np.floor((d - d.min()) / bin_px).astype(np.int64) + 1
    counts = np.bincount(b, minlength=int(b.max()) + 2)
    near = counts[b - 1] + counts[b] + counts[b + 1]
    return np.asarray(near >= min_count, dtype=bool)


def support_filter(
    xy: F64, d: F64, *, k: int = 8, tol_px: float = 1.0, min_support: int = 1
) -> Mask:
    """Keep matches with ≥ ``min_support`` of their k nearest neighbours within ``tol_px`` in d.

    >>> xy = np.array([[0.0, 0.0], [5, 0], [0, 5], [5, 5], [2, 2]])
    >>> support_filter(xy, np.array([10.0, 10.2, 9.9, 10.1, 25.0]), k=3).tolist()
    [True, True, True, True, False]
    """
    n = len(d)
    if n <= min_support:
        return np.zeros(n, bool)
    kk = min(k, n - 1)
    _, idx = cKDTree(xy).query(xy, k=kk + 1)
    near = np.abs(d[idx[:, 1:]] - d[:, None]) <= tol_px
    return np.asarray(near.sum(axis=1) >= min_support, dtype=bool)
