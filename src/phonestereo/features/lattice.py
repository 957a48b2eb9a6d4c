"""The chessboard lattice grown from a circle pair (thesis §1.2.2: Harris + crossing check).

Corner candidates are Harris maxima (:func:`cv2.cornerHarris`, 3 × 3 non-maximum suppression,
a quadratic sub-pixel peak). The lattice starts at the square that holds the anchor circle:
the pair gives one lattice step (half the vector between the circles) and the circle's moment
ellipse gives the other (a circle of radius 0.3 square maps to the ellipse by the local affine
map of the chart, so the ellipse fixes that map up to a rotation, and the pair fixes the
rotation). It then grows in waves: every unlabelled lattice node next to labelled ones is
predicted by linear extrapolation along rows and columns, by parallelograms and by the local
step vectors (their median, which follows perspective and distortion), and takes the nearest
candidate within 0.3 of the local square size; the candidate (Harris peaks ring a junction
rather than sit on it) is moved onto the junction by :func:`cv2.cornerSubPix` and must pass
the **crossing check**: four sample groups, one inside each of the four squares around the
node, must alternate dark/light/dark/light with the diagonal pairs equal, the dark diagonal
must be the one the lattice's colour parity predicts, and the pattern must be point-symmetric
about the node. So every labelled node is an X-junction of the right parity. (While growing
the check is lenient on symmetry: next to a circle on small squares cornerSubPix is pulled by
a few tenths of a pixel; the refined corners are checked strictly later.)

Sizes are the smallest stretch of the local map (:func:`square_size`), so windows stay clear
of neighbouring corners and circles on sheared, foreshortened squares.

Lattice indices (i, j) follow the chart's convention: node (i, j) is the corner at the bottom
right of lattice square (i, j); j runs along the first step vector ``e1``, i along ``e2``, and
``det[e1, e2] > 0`` (the chart is seen from its printed side). Square (0, 0) holds the anchor.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from phonestereo.features._image import F32, F64, sample

_TOL = 0.3  # match tolerance, in local square sizes
_HALF = 42  # grid half-size: a chart has at most 41 squares per side from any start
#: (a, b) offsets of the crossing-check samples in one quadrant, in square units.
_QOFF = np.array(
    [[r * np.cos(t), r * np.sin(t)] for r in (0.2, 0.3) for t in np.radians([22.0, 45.0, 68.0])]
)
#: Point-symmetry probes (a, b), each compared with its mirror through the node: near the four
#: edges, where an off-junction point breaks the symmetry most and circles (which sit on the
#: diagonals) do not reach.
_SYM = np.array(
    [
        [r * np.cos(t), r * np.sin(t)]
        for r in (0.2, 0.3)
        for t in np.radians([-15.0, 0.0, 15.0, 75.0, 90.0, 105.0])
    ]
)
_QSIGN = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)  # TL, TR, BR, BL


@dataclass(frozen=True, eq=False)
class Lattice:
    """Labelled chessboard nodes of one image, in lattice indices (see module docstring)."""

    #: ndarray of int, shape (N, 2). Lattice (i, j) of each node.
    ij: NDArray[np.int64]
    #: ndarray, shape (N, 2). Node positions (x, y), pixels of ``level`` (Harris-peak accuracy, ~0.2
    #: px).
    points: F64
    #: ``e1``, ``e2``: ndarray, shape (N, 2). Local lattice steps along j and i at each node, pixels
    #: of ``level``.
    e1: F64
    #: See ``e1`` above.
    e2: F64
    #: ndarray, shape (N,). Dark/light difference of the crossing check, intensity units.
    contrast: F64
    #: Lattice square (i, j) is black iff (i + j + parity) is even.
    parity: int
    #: Pyramid level of the coordinates.
    level: int
    #: Harris candidates considered.
    candidates: int


def harris_candidates(img: F32, block: int) -> F64:
    """Harris maxima (M, 2) of ``img`` with a quadratic sub-pixel peak, pixels (x, y)."""
    R = cv2.cornerHarris(img, block, 3, 0.04)
    peak = float(R.max())
    if peak <= 0:
        return np.zeros((0, 2))
    dil = cv2.dilate(R, np.ones((3, 3), np.uint8))
    m = (R >= dil) & (R > 1e-5 * peak)
    m[0, :] = m[-1, :] = m[:, 0] = m[:, -1] = False
    ys, xs = np.nonzero(m)
    c = R[ys, xs]
    dx = _vertex(R[ys, xs - 1], c, R[ys, xs + 1])
    dy = _vertex(R[ys - 1, xs], c, R[ys + 1, xs])
    return np.stack([xs + dx, ys + dy], axis=1).astype(np.float64)


def _vertex(a: F32, b: F32, c: F32) -> F64:
    den = a.astype(np.float64) - 2.0 * b + c
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(den < 0, 0.5 * (a - c) / den, 0.0)
    return np.clip(np.nan_to_num(off), -0.5, 0.5)


def crossing_check(
    img: F32,
    pts: F64,
    e1: F64,
    e2: F64,
    tl_dark: NDArray[np.bool_],
    noise: float,
    strict: bool = True,
) -> tuple[NDArray[np.bool_], F64]:
    """The white/black crossing check of candidate nodes → (ok, contrast), each (N,).

    ``tl_dark``: whether the square up-left of each node (−e1 − e2) should be the dark one.
    Besides the four alternating quadrants, the pattern must be point-symmetric about the node
    (a ring of samples equals its mirror image): a point off the junction breaks the symmetry
    along the edges, whatever the error of ``e1``/``e2``. ``strict`` (for refined corners):
    diagonal pairs within 0.4 of the contrast, mean mirror difference below 0.15 (rejects a
    node ~0.05 square off the junction); otherwise (while growing) 0.6 and 0.6.
    """
    off = _QSIGN[:, None, :] * _QOFF[None, :, :]  # (4, 6, 2) in (a, b)
    d = off[None, ..., 0:1] * e1[:, None, None, :] + off[None, ..., 1:2] * e2[:, None, None, :]
    v = sample(img, pts[:, None, None, :] + d).astype(np.float64)  # (N, 4, 6)
    ds = _SYM[None, :, 0:1] * e1[:, None, :] + _SYM[None, :, 1:2] * e2[:, None, :]
    vs = sample(img, np.stack([pts[:, None, :] + ds, pts[:, None, :] - ds])).astype(np.float64)
    asym = np.abs(vs[0] - vs[1]).mean(axis=1)  # 0 at a point-symmetric junction
    q = v.mean(axis=2)
    spread = v.max(axis=2) - v.min(axis=2)
    d_light = 0.5 * ((q[:, 1] + q[:, 3]) - (q[:, 0] + q[:, 2]))  # > 0: TL/BR dark
    c = np.where(tl_dark, d_light, -d_light)
    t_diag, t_asym = (0.4, 0.15) if strict else (0.6, 0.6)
    ok = (
        (c > max(3.0 * noise, 1e-6))
        & (np.abs(q[:, 0] - q[:, 2]) < t_diag * c)
        & (np.abs(q[:, 1] - q[:, 3]) < t_diag * c)
        & (spread.max(axis=1) < 0.8 * c)
        & (asym < t_asym * c)
    )
    return ok, c


def square_size(e1: F64, e2: F64) -> F64:
    """Smallest stretch of the local chart → image map [e1 e2] (..., 2) → (...), pixels.

    The image distance between points one square apart is at least this, in any direction,
    so windows scaled by it stay clear of neighbouring corners and circles.

    >>> round(float(square_size(np.array([20.0, 0.0]), np.array([5.0, 10.0]))), 3)  # sheared
    9.617
    """
    a = np.sum(e1 * e1, axis=-1) + np.sum(e2 * e2, axis=-1)
    det = e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]
    return np.sqrt(np.clip(0.5 * (a - np.sqrt(np.clip(a * a - 4 * det * det, 0, None))), 0, None))


def subpix(img: F32, pts: F64, size: F64) -> tuple[F64, NDArray[np.bool_]]:
    """Move points onto the nearby X-junction with cv2.cornerSubPix (window 0.25 · size, 3–8 px).

    Harris peaks ring an X-junction rather than sit on it; this puts them on it. Returns the
    points (N, 2) and whether each converged (OpenCV silently returns the start point when the
    junction is farther than the window).
    """
    # a start nudged off any pixel-symmetric position: OpenCV returns its input bit for bit
    # only when it gave up, so "unchanged" then means "not converged"
    start = (pts + np.array([0.0123, -0.0077])).astype(np.float32)
    out = pts.copy()
    win = np.clip(np.rint(0.25 * size), 3, 8).astype(int)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 10, 0.05)
    h, w_img = img.shape
    inside = (
        np.isfinite(pts).all(axis=1)
        & (pts[:, 0] >= win)
        & (pts[:, 1] >= win)
        & (pts[:, 0] <= w_img - 1 - win)
        & (pts[:, 1] <= h - 1 - win)
    )
    for w in np.unique(win[inside]):
        m = (win == w) & inside
        c = start[m].reshape(-1, 1, 2)
        out[m] = cv2.cornerSubPix(img, c.copy(), (int(w), int(w)), (-1, -1), crit).reshape(-1, 2)
    moved = np.any(out.astype(np.float32) != start, axis=1) & inside
    return out, moved


def _nanmedian0(a: F64) -> F64:
    """Median over axis 0 ignoring NaN (NaN where all are NaN); fast for small first axes."""
    srt = np.sort(a, axis=0)  # NaN sort last
    n = np.isfinite(srt).sum(axis=0)
    lo = np.take_along_axis(srt, np.maximum((n - 1) // 2, 0)[None], axis=0)[0]
    hi = np.take_along_axis(srt, np.maximum(n // 2, 0)[None], axis=0)[0]
    return np.where(n > 0, 0.5 * (lo + hi), np.nan)


_DIRS = ((0, 1), (0, -1), (1, 0), (-1, 0))
_PAD = 2


class _Grid:
    """Node positions and step vectors on a padded (G, G) grid centred on lattice (0, 0)."""

    def __init__(self) -> None:
        g = 2 * (_HALF + _PAD) + 1
        self.o = _HALF + _PAD
        self.P = np.full((g, g, 2), np.nan)
        self.E = np.full((2, g, g, 2), np.nan)  # E[0]: step along j (e1), E[1]: along i (e2)
        self.C = np.full((g, g), np.nan)
        self.known = np.zeros((g, g), bool)
        self.tried = np.full((g, g), -1)
        inner = np.zeros((g, g), bool)
        inner[_PAD:-_PAD, _PAD:-_PAD] = True
        self.inner = inner

    def neighbours(self) -> NDArray[np.int64]:
        """Number of known 4-neighbours of every cell (G, G)."""
        k = self.known.astype(np.int64)
        n = np.zeros_like(k)
        n[1:] += k[:-1]
        n[:-1] += k[1:]
        n[:, 1:] += k[:, :-1]
        n[:, :-1] += k[:, 1:]
        return n

    def predict(self, fi: NDArray[np.intp], fj: NDArray[np.intp]) -> tuple[F64, F64, F64]:
        """Median position prediction (n, 2) and local steps e1, e2 (n, 2) of cells (fi, fj)."""
        P, E = self.P, self.E
        preds = []
        for di, dj in _DIRS:
            p1 = P[fi - di, fj - dj]
            preds.append(2 * p1 - P[fi - 2 * di, fj - 2 * dj])
            preds.append(p1 + (dj + di) * E[0 if di == 0 else 1][fi - di, fj - dj])
        for di in (1, -1):
            for dj in (1, -1):
                preds.append(P[fi - di, fj] + P[fi, fj - dj] - P[fi - di, fj - dj])
        pred = _nanmedian0(np.stack(preds))
        e = [_nanmedian0(np.stack([E[k][fi - di, fj - dj] for di, dj in _DIRS])) for k in (0, 1)]
        return pred, e[0], e[1]

    def update_steps(self, fi: NDArray[np.intp], fj: NDArray[np.intp]) -> None:
        """Re-estimate the steps at new nodes and their neighbours from node differences."""
        ci = np.concatenate([fi + di for di, _ in ((0, 0), *_DIRS)])
        cj = np.concatenate([fj + dj for _, dj in ((0, 0), *_DIRS)])
        keep = self.known[ci, cj] & self.inner[ci, cj]
        ci, cj = ci[keep], cj[keep]
        P = self.P
        for k, (di, dj) in enumerate(((0, 1), (1, 0))):
            est = _nanmedian0(
                np.stack([P[ci + di, cj + dj] - P[ci, cj], P[ci, cj] - P[ci - di, cj - dj]])
            )
            have = np.isfinite(est).all(axis=1)
            self.E[k][ci[have], cj[have]] = est[have]


def grow(
    img: F32,
    cand: F64,
    seed_pts: F64,
    e1: F64,
    e2: F64,
    parity: int,
    noise: float,
    level: int,
    max_waves: int = 200,
) -> Lattice:
    """Grow the lattice from predicted seed nodes (see the module docstring).

    Parameters
    ----------
    img : ndarray, shape (h, w), float32
        Image of pyramid ``level``.
    cand : ndarray, shape (M, 2)
        Harris candidates on that level.
    seed_pts : ndarray, shape (4, 6, 2)
        Predicted nodes (i, j) for i ∈ {−2, …, 1}, j ∈ {−2, …, 3} (:func:`seed_from_pair`).
    e1, e2 : ndarray, shape (2,)
        Lattice steps at the anchor, pixels.
    parity : int
        Square (i, j) is black iff (i + j + parity) is even.
    noise : float
        Noise σ on this level, intensity units.
    """
    grid = _Grid()
    o = grid.o
    tree = cKDTree(cand) if len(cand) else None
    used = np.zeros(len(cand), bool)
    # seed: the 4 × 6 predicted nodes around the pair, with the anchor's steps
    si, sj = np.mgrid[o - 2 : o + 2, o - 2 : o + 4]
    fi, fj = si.ravel(), sj.ravel()
    p = seed_pts.reshape(-1, 2)
    s1 = np.broadcast_to(e1, p.shape)
    s2 = np.broadcast_to(e2, p.shape)
    for _ in range(max_waves):
        if tree is None or len(fi) == 0:
            break
        size = square_size(s1, s2)
        ok = np.isfinite(p).all(axis=1) & np.isfinite(size)
        fi, fj, p, s1, s2, size = fi[ok], fj[ok], p[ok], s1[ok], s2[ok], size[ok]
        dist, idx = tree.query(p, k=1) if len(p) else (np.zeros(0), np.zeros(0, np.intp))
        hit = dist < _TOL * size
        hit[hit] &= ~used[idx[hit]]
        # two nodes claiming one candidate: neither gets it this wave
        taken, counts = np.unique(idx[hit], return_counts=True)
        hit[hit] &= np.isin(idx[hit], taken[counts == 1])
        fi, fj, k, s1, s2 = fi[hit], fj[hit], idx[hit], s1[hit], s2[hit]
        x, conv = subpix(img, cand[k], size[hit])
        if not conv.all():  # retry the stuck ones from the prediction
            x2, conv2 = subpix(img, p[hit][~conv], size[hit][~conv])
            x[~conv], conv[~conv] = x2, conv2
        tl_dark = (fi + fj - 2 * o + parity) % 2 == 0
        # lenient: cornerSubPix is pulled by circles next to small squares; the refined
        # corners get the strict check at the end
        good, con = crossing_check(img, x, s1, s2, tl_dark, noise, strict=False)
        good &= conv & (np.hypot(*(x - p[hit]).T) < _TOL * size[hit])
        fi, fj, k, x = fi[good], fj[good], k[good], x[good]
        if len(fi):
            used[k] = True
            grid.P[fi, fj] = x
            grid.C[fi, fj] = con[good]
            grid.E[0][fi, fj] = s1[good]
            grid.E[1][fi, fj] = s2[good]
            grid.known[fi, fj] = True
            grid.update_steps(fi, fj)
        if not grid.known.any():
            break
        nbr = grid.neighbours()
        front = ~grid.known & grid.inner & (nbr > grid.tried)
        fi, fj = np.nonzero(front)
        grid.tried[fi, fj] = nbr[fi, fj]
        p, s1, s2 = grid.predict(fi, fj)
    ii, jj = np.nonzero(grid.known)
    return Lattice(
        ij=np.stack([ii - o, jj - o], axis=1).astype(np.int64),
        points=grid.P[ii, jj],
        e1=grid.E[0][ii, jj],
        e2=grid.E[1][ii, jj],
        contrast=grid.C[ii, jj],
        parity=int(parity),
        level=level,
        candidates=len(cand),
    )


def seed_from_pair(c1: F64, c2: F64, cov: F64) -> tuple[F64, F64, F64]:
    """Lattice steps at the anchor and the 4 × 6 seed nodes around a circle pair.

    ``c1, c2``: the pair's centres (2,); ``cov``: their mean moment covariance (2, 2), pixels².
    Returns ``(e1, e2, seed)`` with ``seed`` (4, 6, 2) for i ∈ {−2, …, 1}, j ∈ {−2, …, 3}
    (the nodes of the three squares from circle to circle and a ring of squares around them,
    so that some seeds are clear of the circles).

    >>> e1, e2, seed = seed_from_pair(np.array([10.0, 10.0]), np.array([50.0, 10.0]),
    ...                               np.eye(2) * (0.3 * 20) ** 2 / 4)
    >>> e2.round(6).tolist(), seed[2, 2].tolist()        # 20 px squares, node (0, 0)
    ([0.0, 20.0], [20.0, 20.0])
    """
    e1 = 0.5 * (c2 - c1)
    S = cov / (0.3**2 / 4.0)  # J Jᵀ of the local chart → image map, px² per square²
    w, V = np.linalg.eigh(S)
    sq = (V * np.sqrt(np.clip(w, 1e-12, None))) @ V.T
    isq = (V / np.sqrt(np.clip(w, 1e-12, None))) @ V.T
    u = isq @ e1
    u = u / np.linalg.norm(u)
    e2 = sq @ np.array([-u[1], u[0]])
    i = np.arange(-2, 2)[:, None, None]
    j = np.arange(-2, 4)[None, :, None]
    seed = c1 + (j + 0.5) * e1 + (i + 0.5) * e2
    return e1, e2, np.asarray(seed, dtype=np.float64)
