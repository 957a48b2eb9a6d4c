"""Integer NCC search along the epipolar row band, with the peak tests of §1.2.1.

For each left keypoint, the (2r + 1)² window is correlated (``cv2.matchTemplate``,
zero-mean NCC) with the right image over disparities ``[min_d, max_d]`` and rows within
``± row_tolerance`` (rectification is never perfect). The peak gives:

* the integer match and a parabola sub-pixel start in x and y (refined later by
  :func:`~phonestereo.features.subpixel.refine_lk`);
* **convexity**: the peak's curvature −∂²NCC/∂x² (per px²) and −∂²NCC/∂y²;
* **uniqueness**: the best score in any other column of the band, away from the peak;
* **left–right consistency**: the right window searched back along the left row must land
  within ``lr_tolerance`` px of the keypoint.

The loop is over keypoints (not pixels); each search is one OpenCV call.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SearchResult:
    """Integer NCC search for N keypoints (NaN / False where the band left the image).

    Attributes
    ----------
    searched : ndarray of bool, shape (N,)
        The band fit in the images and had room for a parabola.
    d0, e0 : ndarray, shape (N,)
        Disparity and non-disparity error at the peak, parabola-refined, px.
    score : ndarray, shape (N,)
        NCC at the peak.
    second : ndarray, shape (N,)
        Best NCC in the band more than ``exclusion`` px (in x) from the peak.
    curvature_x, curvature_y : ndarray, shape (N,)
        −second differences of the NCC at the peak along x and y (NCC per px²).
    at_edge : ndarray of bool, shape (N,)
        The peak is on the border of the band (disparity or row range too small).
    lr_ok : ndarray of bool, shape (N,)
        Left–right consistency holds.
    """

    searched: NDArray[np.bool_]
    d0: F64
    e0: F64
    score: F64
    second: F64
    curvature_x: F64
    curvature_y: F64
    at_edge: NDArray[np.bool_]
    lr_ok: NDArray[np.bool_]


def _parabola(a: float, b: float, c: float) -> tuple[float, float]:
    """Vertex offset and curvature −(a − 2b + c) of the parabola through (−1, a), (0, b), (1, c)."""
    den = a - 2.0 * b + c
    if den >= 0:
        return 0.0, -den
    return 0.5 * (a - c) / den, -den


def ncc_search(
    left: F32,
    right: F32,
    xy: NDArray[np.int64],
    *,
    radius: int,
    min_d: int,
    max_d: int,
    row_tolerance: int,
    exclusion: int = 2,
    lr_tolerance: int = 1,
    lr_min_score: float = -1.0,
    lr_uniqueness: float = np.inf,
) -> SearchResult:
    """NCC search of each left window along its row band in the right image.

    Parameters
    ----------
    left, right : ndarray, shape (H, W), float32
        Rectified images (left = wide, right = tele), disparity along +x: x_right = x − d.
    xy : ndarray of int, shape (N, 2)
        Keypoints (x, y), whose windows lie inside ``left``.
    radius : int
        Window half size, px (window 2r + 1).
    min_d, max_d : int
        Disparity search range, px (inclusive).
    row_tolerance : int
        Rows searched above and below, px.
    exclusion : int
        Half width around the peak ignored by the uniqueness score, px.
    lr_tolerance : int
        Allowed difference of the back-matched x, px.
    lr_min_score, lr_uniqueness : float
        The left–right search (half the cost) is skipped, with ``lr_ok`` False, for peaks below
        ``lr_min_score`` or with ``second ≥ lr_uniqueness · score``, which fail anyway.

    Returns
    -------
    SearchResult

    Examples
    --------
    A random texture shifted by 7 px:

    >>> rng = np.random.default_rng(0)
    >>> img = cv2.GaussianBlur(rng.uniform(0, 255, (60, 120)).astype(np.float32), (0, 0), 1.5)
    >>> res = ncc_search(img, np.roll(img, -7, axis=1), np.array([[60, 30]]), radius=7,
    ...                  min_d=0, max_d=20, row_tolerance=2)
    >>> round(float(res.d0[0]), 1), abs(round(float(res.e0[0]), 1)), bool(res.lr_ok[0])
    (7.0, 0.0, True)
    """
    n, r = len(xy), int(radius)
    h, w = left.shape
    # one row per keypoint: d0, e0, score, second, curvature_x, curvature_y, searched, edge, lr
    rows = np.full((n, 9), np.nan)
    rows[:, 6:] = 0.0
    ty = int(row_tolerance)
    pts = np.asarray(xy, dtype=np.int64).tolist()
    ccoeff = cv2.TM_CCOEFF_NORMED
    for i, (x, y) in enumerate(pts):
        xa, xb = max(x - max_d - r, 0), min(x - min_d + r + 1, w)
        ya, yb = y - ty - r, y + ty + r + 1
        if xb - xa < 2 * r + 3 or ya < 0 or yb > h:
            continue
        c = cv2.matchTemplate(
            right[ya:yb, xa:xb], left[y - r : y + r + 1, x - r : x + r + 1], ccoeff
        )
        _, best, _, (ix, iy) = cv2.minMaxLoc(c)
        nr, nc = c.shape
        inner = 0 < ix < nc - 1 and (ty == 0 or 0 < iy < nr - 1)
        if inner:
            fx, cx = _parabola(float(c[iy, ix - 1]), best, float(c[iy, ix + 1]))
            fy, cy = (
                _parabola(float(c[iy - 1, ix]), best, float(c[iy + 1, ix])) if ty else (0.0, np.nan)
            )
        c[:, max(ix - exclusion, 0) : ix + exclusion + 1] = -1.0
        second = cv2.minMaxLoc(c)[1]
        if not inner:
            rows[i, 2:4], rows[i, 6:8] = (best, second), (1.0, 1.0)
            continue
        xr, yr = xa + r + ix, ya + r + iy
        rows[i, :8] = (x - (xr + fx), y - (yr + fy), best, second, cx, cy, 1.0, 0.0)
        if best < lr_min_score or second >= lr_uniqueness * best:
            continue
        # left–right: the right window back along the left row y
        la, lb = max(xr + min_d - r, 0), min(xr + max_d + r + 1, w)
        if lb - la >= 2 * r + 1:
            back = cv2.matchTemplate(
                left[y - r : y + r + 1, la:lb],
                right[yr - r : yr + r + 1, xr - r : xr + r + 1],
                ccoeff,
            )
            rows[i, 8] = abs(la + r + cv2.minMaxLoc(back)[3][0] - x) <= lr_tolerance
    return SearchResult(
        searched=rows[:, 6] > 0,
        d0=rows[:, 0].copy(),
        e0=rows[:, 1].copy(),
        score=rows[:, 2].copy(),
        second=rows[:, 3].copy(),
        curvature_x=rows[:, 4].copy(),
        curvature_y=rows[:, 5].copy(),
        at_edge=rows[:, 7] > 0,
        lr_ok=rows[:, 8] > 0,
    )
