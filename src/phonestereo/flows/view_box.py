"""The part of a rectified box the tele sees (ROI disparity's coarse step, issue 18).

A diagonal baseline turns the canonical rectified frame by ~45°, and a ×5 tele sees less than
an expanded ROI: the bounding box of a raw box then holds pixels the tele never saw (black after
the remap), which decorrelate the whole-box correlation. :func:`inscribed_box` shrinks it into
the raw box's outline and the tele's view over the searched disparities; :func:`tele_view_box`
is the raw-wide box the whole tele view covers (the face captures' W-T measurement).
"""

from __future__ import annotations

import numpy as np

from phonestereo.geometry.checks import Array
from phonestereo.rectification import Rectification

F64 = Array


def outline(box: tuple[int, int, int, int], n: int = 8) -> F64:
    """Points along the border of a raw box (x, y, w, h), (4n, 2)."""
    x, y, w, h = box
    t = np.linspace(0.0, 1.0, n, endpoint=False)
    x1, y1 = x + w - 1.0, y + h - 1.0
    return np.concatenate([
        np.column_stack([x + t * (x1 - x), np.full(n, y)]),
        np.column_stack([np.full(n, x1), y + t * (y1 - y)]),
        np.column_stack([x1 - t * (x1 - x), np.full(n, y1)]),
        np.column_stack([np.full(n, x), y1 - t * (y1 - y)]),
    ])


def tele_outline(rect: Rectification, n: int = 16) -> F64:
    """The raw tele image's border in ``rect``'s rectified frame, a closed polygon (4n, 2)."""
    w, h = rect.rig.tele.size
    pts = rect.points_tele(outline((0, 0, w, h), n))
    return pts[np.isfinite(pts).all(axis=1)]


def _inside(poly: F64, pts: F64) -> np.ndarray:
    """Points (N, 2) inside a closed polygon (M, 2)."""
    from matplotlib.path import Path

    return np.asarray(Path(poly).contains_points(pts), dtype=bool)


def inscribed_box(
    outline: F64,
    tele_poly: F64,
    d_range: tuple[float, float],
    size: tuple[int, int],
    min_side_px: float = 24.0,
) -> tuple[int, int, int, int] | None:
    """An axis-aligned rectified box (x, y, w, h) inside a raw box's outline, whose tele
    counterparts at every disparity of ``d_range`` stay inside the tele image; None when no
    such box with sides of at least ``min_side_px`` remains.

    The bounding box of a raw box is not the raw box once the rectification rotates it (a
    diagonal baseline turns the images by ~45°): its corners then hold pixels the tele never
    saw (black after the remap), and a narrow tele (×5) sees less than an expanded ROI. Both
    decorrelate the coarse step; the box is shrunk about the outline's centre until every
    corner is inside the outline and, shifted by −d for d at both ends of the range (the
    tele's outline is convex), inside the tele's.

    Parameters
    ----------
    outline : ndarray, shape (M, 2)
        The raw box's border in the rectified frame (a closed polygon).
    tele_poly : ndarray, shape (K, 2)
        The tele image's border in the same frame (:func:`tele_outline`).
    d_range : (float, float)
        Disparities searched, px.
    size : (int, int)
        Rectified image (W, H).

    Examples
    --------
    >>> sq = np.array([[0.0, 0], [100, 0], [100, 100], [0, 100]])
    >>> inscribed_box(sq, sq + [-1000, 0], (0.0, 10.0), (2000, 2000)) is None
    True
    >>> x, y, w, h = inscribed_box(sq, sq - 50, (0.0, 0.0), (2000, 2000))  # tele: a quarter
    >>> x >= 0 and y >= 0 and x + w <= 51 and y + h <= 51 and min(w, h) >= 40
    True
    """
    if not np.isfinite(outline).all() or len(tele_poly) < 3:
        return None
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    lo, hi = np.maximum(lo, 0.0), np.minimum(hi, np.array(size, dtype=np.float64) - 1)
    if np.any(hi - lo < 8):
        return None
    polys = [outline, tele_poly + np.array([d_range[0], 0.0]),
             tele_poly + np.array([d_range[1], 0.0])]
    # The valid region (convex: an intersection of convex outlines) sampled on a grid; its
    # centroid and extent start the search.
    g = _outline_grid(lo, hi, 25)
    valid = np.logical_and.reduce([_inside(p, g) for p in polys])
    if not valid.any():
        return None
    c = g[valid].mean(axis=0)
    ext = [np.ptp(g[valid], axis=0) + (hi - lo) / 24, hi - lo]

    def corners(half: F64) -> F64:
        return np.array([c - half, [c[0] + half[0], c[1] - half[1]], c + half,
                         [c[0] - half[0], c[1] + half[1]]])

    def fits(half: F64) -> bool:
        q = corners(half)
        return all(_inside(p, q).all() for p in polys)

    best = np.zeros(2)
    for e in ext:  # the valid region's aspect and the box's
        half = 0.5 * e
        a_, b_ = 0.0, 1.0
        if fits(half):
            a_ = 1.0
        else:
            for _ in range(12):
                m = 0.5 * (a_ + b_)
                a_, b_ = (m, b_) if fits(m * half) else (a_, m)
        if np.prod(a_ * half) > np.prod(best):
            best = a_ * half
    if np.any(2 * best < min_side_px):
        return None
    q = corners(best)
    q_lo, q_hi = np.ceil(q.min(axis=0)).astype(int), np.floor(q.max(axis=0)).astype(int)
    return int(q_lo[0]), int(q_lo[1]), int(q_hi[0] - q_lo[0] + 1), int(q_hi[1] - q_lo[1] + 1)


def _outline_grid(lo: F64, hi: F64, n: int = 9) -> F64:
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
    return np.column_stack([gx.ravel(), gy.ravel()])


def tele_view_box(ref: Rectification, margin_px: int = 40) -> tuple[int, int, int, int]:
    """The raw-wide box the tele sees (the reference window unrectified), shrunk by a margin."""
    w, h = ref.wide_rect.size
    edge = np.concatenate([
        np.column_stack([np.linspace(0, w - 1, 32), np.zeros(32)]),
        np.column_stack([np.linspace(0, w - 1, 32), np.full(32, h - 1.0)]),
        np.column_stack([np.zeros(32), np.linspace(0, h - 1, 32)]),
        np.column_stack([np.full(32, w - 1.0), np.linspace(0, h - 1, 32)]),
    ])
    raw = ref.unrectify_wide(edge)
    raw = raw[np.isfinite(raw).all(axis=1)]
    lo = np.maximum(raw.min(axis=0) + margin_px, 0)
    hi = np.minimum(raw.max(axis=0) - margin_px, np.array(ref.rig.wide.size) - 1)
    return int(lo[0]), int(lo[1]), int(max(hi[0] - lo[0], 0)), int(max(hi[1] - lo[1], 0))


__all__ = [
    "inscribed_box",
    "outline",
    "tele_outline",
    "tele_view_box",
]
