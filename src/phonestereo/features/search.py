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

The loop is over keypoints (not pixels): each search is one OpenCV call writing into one
(N, rows, disparities) array; the peak, parabola and uniqueness tests are vectorised over it.
The loops are split over two threads (:func:`~phonestereo.features._threads.run_split`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.features._threads import run_split

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SearchResult:
    """Integer NCC search for N keypoints (NaN / False where the band left the image)."""

    #: ndarray of bool, shape (N,). The band fit in the images and had room for a parabola.
    searched: NDArray[np.bool_]
    #: ``d0``, ``e0``: ndarray, shape (N,). Disparity and non-disparity error at the peak,
    #: parabola-refined, px.
    d0: F64
    #: See ``d0`` above.
    e0: F64
    #: ndarray, shape (N,). NCC at the peak.
    score: F64
    #: ndarray, shape (N,). Best NCC in the band more than ``exclusion`` px (in x) from the peak.
    second: F64
    #: ``curvature_x``, ``curvature_y``: ndarray, shape (N,). −second differences of the NCC at the
    #: peak along x and y (NCC per px²).
    curvature_x: F64
    #: See ``curvature_x`` above.
    curvature_y: F64
    #: ndarray of bool, shape (N,). The peak is on the border of the band (disparity or row range
    #: too small).
    at_edge: NDArray[np.bool_]
    #: ndarray of bool, shape (N,). Left–right consistency holds.
    lr_ok: NDArray[np.bool_]


def _parabola(
    c: F32,
    k: NDArray[np.int64],
    iy: NDArray[np.int64],
    ix: NDArray[np.int64],
    dy: int,
    dx: int,
    size: int,
) -> tuple[F64, F64]:
    """Vertex offset and curvature −(a − 2b + c) of the parabola through the peak and its two
    neighbours along y (dy = 1) or x (dx = 1); offset 0 where it is not concave."""
    along = iy if dy else ix
    lo, hi = np.clip(along - 1, 0, size - 1), np.clip(along + 1, 0, size - 1)
    b = c[k, iy, ix].astype(np.float64)
    a = c[k, lo, ix] if dy else c[k, iy, lo]
    e = c[k, hi, ix] if dy else c[k, iy, hi]
    den = a - 2.0 * b + e
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(den < 0, 0.5 * (a - e) / den, 0.0)
    return off, -den


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
    n, r, ty = len(xy), int(radius), int(row_tolerance)
    h, w = left.shape
    pts = np.asarray(xy, dtype=np.int64).reshape(-1, 2)
    nr, nc = 2 * ty + 1, max_d - min_d + 1
    # NCC of every band in one array (n, rows, disparities), column j ↔ d = max_d − j;
    # disparities whose window leaves the right image hold −1 (below any NCC)
    cs = np.full((n, nr, nc), -1.0, np.float32)
    lo, hi = np.zeros(n, np.int64), np.full(n, nc - 1)
    searched = np.zeros(n, bool)
    ccoeff = cv2.TM_CCOEFF_NORMED

    # each band's columns xa … xb − 1 in the right image, its first disparity column `off`
    # (vectorised: the loop below only slices and calls OpenCV)
    xa = np.maximum(pts[:, 0] - max_d - r, 0)
    xb = np.minimum(pts[:, 0] - min_d + r + 1, w)
    off = xa - (pts[:, 0] - max_d - r)
    fits = (xb - xa >= 2 * r + 3) & (pts[:, 1] - ty - r >= 0) & (pts[:, 1] + ty + r + 1 <= h)
    lo[fits], hi[fits], searched[fits] = off[fits], (off + xb - xa - 2 * r - 1)[fits], True
    rows = zip(pts[:, 0].tolist(), pts[:, 1].tolist(), xa.tolist(), xb.tolist(), off.tolist(),
               strict=True)
    bands = [(i, *b) for i, (b, ok) in enumerate(zip(rows, fits.tolist(), strict=True)) if ok]

    def forward(chunk: Sequence[tuple[int, int, int, int, int, int]]) -> None:  # row i of cs
        for i, x, y, a, b, o in chunk:
            cv2.matchTemplate(
                right[y - ty - r : y + ty + r + 1, a:b],
                left[y - r : y + r + 1, x - r : x + r + 1],
                ccoeff,
                result=cs[i, :, o : o + b - a - 2 * r],
            )

    run_split(forward, bands)
    k = np.arange(n)
    flat = cs.reshape(n, -1).argmax(axis=1)
    iy, ix = flat // nc, flat % nc
    best = cs[k, iy, ix].astype(np.float64)
    inner = searched & (lo < ix) & (ix < hi) & ((ty == 0) | ((0 < iy) & (iy < nr - 1)))
    fx, cx = _parabola(cs, k, iy, ix, 0, 1, nc)
    if ty:
        fy, cy = _parabola(cs, k, iy, ix, 1, 0, nr)
    else:
        fy, cy = np.zeros(n), np.full(n, np.nan)
    far = np.abs(np.arange(nc)[None, :] - ix[:, None]) > exclusion  # (n, nc)
    second = np.where(far[:, None, :], cs, -1.0).reshape(n, -1).max(axis=1).astype(np.float64)
    nan = np.full(n, np.nan)
    d0 = np.where(inner, max_d - ix - fx, nan)
    e0 = np.where(inner, ty - iy - fy, nan)
    lr_ok = np.zeros(n, bool)
    # with lr_uniqueness = ∞, second ≥ ∞ · score holds only for a negative score (∞ · 0 is NaN)
    unique = best >= 0 if np.isinf(lr_uniqueness) else ~(second >= lr_uniqueness * best)
    lr_run = inner & (best >= lr_min_score) & unique

    run_i = np.flatnonzero(lr_run)
    xr = pts[run_i, 0] - max_d + ix[run_i]  # the right window's centre (xr, yr)
    yr = pts[run_i, 1] - ty + iy[run_i]
    la, lb = np.maximum(xr + min_d - r, 0), np.minimum(xr + max_d + r + 1, w)
    back_ok = lb - la >= 2 * r + 1
    backs = [
        b for b, ok in zip(
            zip(run_i.tolist(), pts[run_i, 0].tolist(), pts[run_i, 1].tolist(), xr.tolist(),
                yr.tolist(), la.tolist(), lb.tolist(), strict=True),
            back_ok.tolist(), strict=True,
        ) if ok
    ]

    def backward(chunk: Sequence[tuple[int, ...]]) -> None:  # right window back along row y
        for i, x, y, u, v, a, b in chunk:
            back = cv2.matchTemplate(
                left[y - r : y + r + 1, a:b], right[v - r : v + r + 1, u - r : u + r + 1], ccoeff
            )
            lr_ok[i] = abs(a + r + cv2.minMaxLoc(back)[3][0] - x) <= lr_tolerance

    run_split(backward, backs)
    return SearchResult(
        searched=searched,
        d0=d0,
        e0=e0,
        score=np.where(searched, best, nan),
        second=np.where(searched, second, nan),
        curvature_x=np.where(inner, cx, nan),
        curvature_y=np.where(inner, cy, nan),
        at_edge=searched & ~inner,
        lr_ok=lr_ok,
    )
