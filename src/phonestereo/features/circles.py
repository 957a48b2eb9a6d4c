"""The circle pairs of the verification chart (thesis §1.2.2), found coarse to fine.

Per pyramid level: the image is split into dark and light masks about its local mean (a box of
31 px, with a dead band of a few noise σ), and each mask into 4-connected components
(:func:`cv2.connectedComponentsWithStats`). A component is a circle candidate when

- its size and bounding box fit a small compact blob;
- its area equals that of its moment ellipse, π·a·b = 4π·√det C (the area–circumference
  relation of a circle, in a form that survives perspective: a circle images as an ellipse,
  and the relation holds for the ellipse's moments; a square gives 0.955, an L or a merged
  blob much less);
- it is enclosed: a ring at 1.35 × its ellipse lies wholly in a region of the opposite colour
  (the chart's square around the circle), with a contrast well above the noise.

Two candidates of the same polarity form a pair when their radii are similar and their
centres are two squares apart: with the circle radius 0.3 square, that is 6.67 radii, i.e.
13.3 in units of the ellipse's σ (an affine-invariant distance); the square between them has
the circles' colour. Pairs are matched greedily by how well they fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.features._image import F32, F64, level_to_base, sample

#: Pair spacing in units of the ellipse σ: 2 squares / (0.3 square / 2).
PAIR_SIGMAS = 2.0 / (0.3 / 2.0)
_WINDOW = 31  # local-mean box, px of the level image
_R_MIN, _R_MAX = 1.3, 12.0  # circle radius accepted on one level, px of that level
_RING = 1.35  # enclosure ring, in circle radii


@dataclass(frozen=True, eq=False)
class Circles:
    """Circle candidates of one pyramid level, in level-0 pixels."""

    #: ndarray, shape (N, 2). Blob centroids (x, y), level-0 px.
    centers: F64
    #: ndarray, shape (N, 2, 2). Second central moments of the blob area, level-0 px² (a disc of
    #: radius r: r²/4 · I).
    cov: F64
    #: ndarray of bool, shape (N,). True for dark circles (in white squares).
    dark: NDArray[np.bool_]
    #: ndarray, shape (N,). |ring − centre| intensity difference.
    contrast: F64
    #: ndarray of int, shape (M, 2). Indices of paired candidates, best pair first.
    pairs: NDArray[np.intp]
    #: ndarray, shape (M,). Misfit of each pair (0 = ideal).
    pair_score: F64
    #: The pyramid level they were found on.
    level: int

    @property
    def radius(self) -> F64:
        """Geometric-mean radius 2·(det C)^¼ of every candidate, level-0 px (N,)."""
        det = np.linalg.det(self.cov)
        return np.asarray(2.0 * np.sqrt(np.sqrt(np.clip(det, 0, None))), dtype=np.float64)


def _moments(labels: NDArray[np.int32], keep: NDArray[np.bool_]) -> tuple[F64, F64, F64]:
    """Area, centroid (n, 2) and central second moments (n, 2, 2) of the kept labels."""
    n = len(keep)
    lut = np.zeros(n, dtype=np.int32)
    idx = np.flatnonzero(keep)
    lut[idx] = np.arange(1, len(idx) + 1, dtype=np.int32)
    sel = lut[labels]
    ys, xs = np.nonzero(sel)
    lab = sel[ys, xs]
    m = len(idx) + 1
    x, y = xs.astype(np.float64), ys.astype(np.float64)
    area = np.bincount(lab, minlength=m)[1:].astype(np.float64)
    sx = np.bincount(lab, x, m)[1:] / area
    sy = np.bincount(lab, y, m)[1:] / area
    cxx = np.bincount(lab, x * x, m)[1:] / area - sx * sx + 1.0 / 12.0
    cyy = np.bincount(lab, y * y, m)[1:] / area - sy * sy + 1.0 / 12.0
    cxy = np.bincount(lab, x * y, m)[1:] / area - sx * sy
    cov = np.stack([np.stack([cxx, cxy], -1), np.stack([cxy, cyy], -1)], -2)
    return area, np.stack([sx, sy], axis=1), cov


def _ellipse_points(centers: F64, cov: F64, scale: float, n: int) -> F64:
    """Points on the ellipses ``(p − c)ᵀ C⁻¹ (p − c) = (2·scale)²``, shape (N, n, 2)."""
    t = 2 * np.pi * (np.arange(n) + 0.5) / n
    unit = np.stack([np.cos(t), np.sin(t)], axis=1)
    L = np.linalg.cholesky(cov)  # C = L Lᵀ: L maps the unit circle to the σ ellipse
    return np.asarray(centers[:, None, :] + 2.0 * scale * unit @ np.swapaxes(L, 1, 2))


def _candidates(
    img: F32, mean: F32, dark: bool, delta: float
) -> tuple[F64, F64, F64]:  # centers, cov, contrast (level px)
    mask = (img < mean - delta) if dark else (img > mean + delta)
    _, labels, stats, _ = cv2.connectedComponentsWithStats(
        mask.view(np.uint8), connectivity=4, ltype=cv2.CV_32S
    )
    h, w = img.shape
    x0, y0, bw, bh, area = (stats[:, k].astype(np.float64) for k in range(5))
    fill = area / np.maximum(bw * bh, 1.0)
    aspect = np.maximum(bw, bh) / np.maximum(np.minimum(bw, bh), 1.0)
    keep = (
        (area >= np.pi * _R_MIN**2 * 0.5)
        & (area <= np.pi * _R_MAX**2)
        & (fill >= 0.35)
        & (fill <= 0.97)
        & (aspect <= 4.0)
        & (x0 > 1)
        & (y0 > 1)
        & (x0 + bw < w - 1)
        & (y0 + bh < h - 1)
    )
    keep[0] = False
    if not keep.any():
        return np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0)
    area_k, c, cov = _moments(labels, keep)
    ev = np.linalg.eigvalsh(cov)  # ascending
    ratio = area_k / (4 * np.pi * np.sqrt(np.clip(ev[:, 0] * ev[:, 1], 1e-12, None)))
    r_minor = 2 * np.sqrt(np.clip(ev[:, 0], 0, None))
    r_geo = 2 * np.sqrt(np.sqrt(np.clip(ev[:, 0] * ev[:, 1], 0, None)))
    ok = (
        (ratio > 0.86)
        & (ratio < 1.12)
        & (r_minor >= 0.7)
        & (r_geo >= _R_MIN)
        & (r_geo <= _R_MAX)
        & (ev[:, 1] <= 12.0 * ev[:, 0])
    )
    c, cov = c[ok], cov[ok]
    if len(c) == 0:
        return c, cov, np.zeros(0)
    ring = sample(img, _ellipse_points(c, cov, _RING, 48)).astype(np.float64)
    inner = sample(img, _ellipse_points(c, cov, 0.35, 6)).astype(np.float64)
    centre = np.concatenate([inner, sample(img, c)[:, None].astype(np.float64)], axis=1)
    sign = 1.0 if dark else -1.0
    contrast = sign * (np.median(ring, axis=1) - np.median(centre, axis=1))
    mid = 0.5 * (np.median(ring, axis=1) + np.median(centre, axis=1))
    enclosed = (
        (contrast > 4.0 * delta)
        & np.all(sign * (ring - mid[:, None]) > 0.25 * contrast[:, None], axis=1)
        & np.all(sign * (mid[:, None] - centre) > 0.25 * contrast[:, None], axis=1)
    )
    return c[enclosed], cov[enclosed], contrast[enclosed]


def _pairs(
    img: F32, c: F64, cov: F64, dark: NDArray[np.bool_], con: F64
) -> tuple[NDArray[np.intp], F64]:
    """Greedy pairing → (M, 2) indices and misfit scores, best first."""
    n = len(c)
    if n < 2:
        return np.zeros((0, 2), np.intp), np.zeros(0)
    i, j = np.triu_indices(n, 1)
    det = np.linalg.det(cov)
    r = np.sqrt(np.sqrt(det))
    log_r = np.abs(np.log(r[i] / r[j]))
    cbar = 0.5 * (cov[i] + cov[j])
    d = c[j] - c[i]
    dw = np.sqrt(np.einsum("ka,kab,kb->k", d, np.linalg.inv(cbar), d))
    rel = np.abs(dw / PAIR_SIGMAS - 1.0)
    ok = (dark[i] == dark[j]) & (log_r < np.log(1.35)) & (rel < 0.25)
    i, j, log_r, rel = i[ok], j[ok], log_r[ok], rel[ok]
    if len(i) == 0:
        return np.zeros((0, 2), np.intp), np.zeros(0)
    # the square between the circles has their colour
    mid = sample(img, 0.5 * (c[i] + c[j])).astype(np.float64)
    ring = sample(img, _ellipse_points(c[i], cov[i], _RING, 8)).astype(np.float64)
    centre = sample(img, c[i]).astype(np.float64)
    thr = 0.5 * (np.median(ring, axis=1) + centre)
    sign = np.where(dark[i], 1.0, -1.0)
    between = sign * (thr - mid) > 0.25 * con[i]
    i, j = i[between], j[between]
    score = (rel + log_r)[between]
    order = np.argsort(score)
    used = np.zeros(n, dtype=bool)
    out, sc = [], []
    for k in order:  # greedy over the (few) plausible pairs
        if not (used[i[k]] or used[j[k]]):
            used[i[k]] = used[j[k]] = True
            out.append((i[k], j[k]))
            sc.append(score[k])
    return np.array(out, dtype=np.intp).reshape(-1, 2), np.array(sc, dtype=np.float64)


def find_circles(img: F32, level: int, noise_sigma: float) -> Circles:
    """Circle candidates and pairs on one pyramid level image ``img`` (see module docstring).

    Parameters
    ----------
    img : ndarray, shape (h, w), float32
        The level-``level`` image.
    level : int
        Its pyramid level (coordinates are returned on level 0).
    noise_sigma : float
        Noise σ of this level, intensity units.
    """
    mean = cv2.blur(img, (_WINDOW, _WINDOW), borderType=cv2.BORDER_REPLICATE)
    delta = 3.0 * noise_sigma
    parts = [_candidates(img, mean, dark, delta) for dark in (True, False)]
    c = np.concatenate([p[0] for p in parts])
    cov = np.concatenate([p[1] for p in parts])
    con = np.concatenate([p[2] for p in parts])
    dark = np.concatenate(
        [np.full(len(p[0]), d) for p, d in zip(parts, (True, False), strict=True)]
    )
    pairs, score = _pairs(img, c, cov, dark, con)
    k2 = float(4**level)
    return Circles(level_to_base(c, level), cov * k2, dark, con, pairs, score, level)
