"""Chart labels for a grown lattice: which chart (row, col) each node is, checked three ways.

1. **Square codes.** Every lattice square with four labelled corners is sampled at its centre
   (through the bilinear map of its corners) and compared with its neighbours' centres:
   *circle* if it has the colour of its edge neighbours, *plain* if it has that of its
   diagonal neighbours, *unknown* in between.
2. **Hypotheses.** The lattice maps to the chart by one of four rotations (a mirror is
   impossible: the chart is seen from its printed side) and an integer shift. Shifts are those
   that put an observed circle onto a chart circle of the same colour. Each hypothesis is
   scored by its contradictions: a square observed as circle/plain where the chart has the
   other, and any square or node that would fall outside the chart. The best must contradict
   (almost) nothing and must explain ≥ 2 observed circles; a close second is resolved by the
   rotation hint (the chart's +u axis is within ±45° of it in the image) or the detection is
   rejected as ambiguous.
3. **Smooth mapping.** A homography plus a cubic polynomial from chart to image must fit every
   node to a fraction of its square; nodes that do not are dropped (a wrong label is off by a
   whole square).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.charts.verification import VerificationChart
from phonestereo.features._image import F32, F64, sample

_ROT = np.array([[[1, 0], [0, 1]], [[0, -1], [1, 0]], [[-1, 0], [0, -1]], [[0, 1], [-1, 0]]])
_CENTRE = np.array([[0.5, 0.5], [0.42, 0.42], [0.58, 0.42], [0.58, 0.58], [0.42, 0.58]])
PLAIN, CIRCLE, UNKNOWN = 0, 1, -1
#: Reference squares of the square's own colour (diagonal and two-apart) and of the other colour
#: (edge-adjacent and a knight's move away): at most 2 of them hold a circle (a pair's squares
#: are two apart, other pairs three or more), so their medians are clean.
_SAME = [(1, 1), (1, -1), (-1, 1), (-1, -1), (2, 0), (-2, 0), (0, 2), (0, -2)]
_OTHER = [(0, 1), (0, -1), (1, 0), (-1, 0)] + [
    (a * di, b * dj) for di, dj in ((1, 2), (2, 1)) for a in (1, -1) for b in (1, -1)
]


@dataclass(frozen=True, eq=False)
class Squares:
    """Lattice squares with four known corners: (i, j) (K, 2), code (K,), centre px (K, 2)."""

    ij: NDArray[np.int64]
    code: NDArray[np.int64]
    centre: F64


def classify_squares(img: F32, ij: NDArray[np.int64], pts: F64) -> Squares:
    """Code every complete lattice square (see module docstring, step 1).

    ``pts`` are node positions on ``img``'s pixel grid. A square's centre value ``v`` is
    compared with the centres of nearby squares: the median of those of its own colour
    (``same``, see ``_SAME``) and of the other colour (``other``); with
    ``t = (v − same) / (other − same)``, t < 0.25 is plain, t > 0.45 a circle. Blur and
    uneven light move both references with the square, so the test holds at any scale.
    """
    lo = ij.min(axis=0) - 1
    shape = tuple(ij.max(axis=0) - lo + 2)
    P = np.full((*shape, 2), np.nan)
    a = ij - lo
    P[a[:, 0], a[:, 1]] = pts
    P = _fill_holes(P)  # nodes missing next to circles (small, blurred squares), for sampling
    # square (i, j): corners TL (i-1, j-1), TR (i-1, j), BR (i, j), BL (i, j-1)
    quad = np.stack([P[:-1, :-1], P[:-1, 1:], P[1:, 1:], P[1:, :-1]], axis=2)  # (h, w, 4, 2)
    have = np.isfinite(quad).all(axis=(2, 3))
    al, be = _CENTRE[:, 0], _CENTRE[:, 1]
    wts = np.stack([(1 - al) * (1 - be), al * (1 - be), al * be, (1 - al) * be], axis=1)
    si, sj = np.nonzero(have)
    cen = np.einsum("sc,kcx->ksx", wts, quad[si, sj])  # (K, 5, 2)
    h, w = img.shape
    inside = np.all((cen >= 1.0) & (cen <= np.array([w - 2.0, h - 2.0])), axis=(1, 2))
    si, sj, cen = si[inside], sj[inside], cen[inside]
    V = np.full(have.shape, np.nan)
    V[si, sj] = sample(img, cen).astype(np.float64).mean(axis=1)
    Vp = np.pad(V, 2, constant_values=np.nan)
    n = V.shape

    def nb(offsets: list[tuple[int, int]]) -> F64:
        st = np.stack([Vp[2 + di : 2 + di + n[0], 2 + dj : 2 + dj + n[1]] for di, dj in offsets])
        srt = np.sort(st, axis=0)
        cnt = np.isfinite(srt).sum(axis=0)
        med = np.take_along_axis(srt, np.maximum((cnt - 1) // 2, 0)[None], axis=0)[0]
        med2 = np.take_along_axis(srt, np.maximum(cnt // 2, 0)[None], axis=0)[0]
        return np.where(cnt >= 3, 0.5 * (med + med2), np.nan)

    same = nb(_SAME)[si, sj]
    other = nb(_OTHER)[si, sj]
    v = V[si, sj]
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (v - same) / (other - same)
    code = np.full(len(si), UNKNOWN, dtype=np.int64)
    code[t < 0.25] = PLAIN
    code[t > 0.45] = CIRCLE
    ij_sq = np.stack([si, sj], axis=1) + lo + 1
    return Squares(ij_sq.astype(np.int64), code, cen[:, 0])


def _fill(P: F64) -> F64:
    """Fill missing nodes of a (h, w, 2) grid from known neighbours: the mean of the midpoints
    of opposite neighbours and of the parallelograms of three neighbours that are known."""
    Q = np.pad(P, ((2, 2), (2, 2), (0, 0)), constant_values=np.nan)
    h, w = P.shape[:2]

    def at(di: int, dj: int) -> F64:
        return np.asarray(Q[2 + di : 2 + di + h, 2 + dj : 2 + dj + w])

    est = [0.5 * (at(0, -1) + at(0, 1)), 0.5 * (at(-1, 0) + at(1, 0))]
    est += [at(di, 0) + at(0, dj) - at(di, dj) for di in (1, -1) for dj in (1, -1)]
    st = np.stack(est)
    n = np.isfinite(st[..., 0]).sum(axis=0)
    with np.errstate(invalid="ignore"):
        mean = np.nansum(np.nan_to_num(st, nan=0.0), axis=0) / np.maximum(n, 1)[..., None]
    out = P.copy()
    miss = ~np.isfinite(P[..., 0]) & (n >= 1)
    out[miss] = mean[miss]
    return out


def _fill_holes(P: F64, reach: int = 4) -> F64:
    """Fill the holes of a node grid: missing nodes with known nodes within ``reach`` on both
    sides along a row or a column (never the outside of the lattice)."""
    known = np.isfinite(P[..., 0])
    h, w = known.shape
    K = np.pad(known, reach)

    def side(di: int, dj: int) -> NDArray[np.bool_]:
        return np.any(
            [K[reach + k * di : reach + k * di + h, reach + k * dj : reach + k * dj + w]
             for k in range(1, reach + 1)],
            axis=0,
        )

    hole = ~known & ((side(0, -1) & side(0, 1)) | (side(-1, 0) & side(1, 0)))
    out = P
    for _ in range(reach):
        if not (hole & ~np.isfinite(out[..., 0])).any():
            break
        f = _fill(out)
        take = hole & ~np.isfinite(out[..., 0]) & np.isfinite(f[..., 0])
        out = out.copy()
        out[take] = f[take]
    return out


@dataclass(frozen=True)
class Hypothesis:
    """Lattice → chart: chart corner point (x, y) = R_k · (j, i) + t; (row, col) = (y−1, x−1)."""

    k: int
    t: tuple[int, int]
    mismatches: int
    circles: int


def _chart_codes(chart: VerificationChart) -> NDArray[np.int64]:
    cols, rows = chart.squares
    codes = np.zeros((rows, cols), np.int64)
    for p in chart.circle_pairs:
        codes[p.square_ids[:, 0], p.square_ids[:, 1]] = CIRCLE
    return codes


def corner_ids(h: Hypothesis, ij: NDArray[np.int64]) -> NDArray[np.int64]:
    """Chart (row, col) of lattice nodes ``ij`` (N, 2) under hypothesis ``h``."""
    x = ij[:, ::-1] @ _ROT[h.k].T + np.array(h.t)
    return np.stack([x[:, 1] - 1, x[:, 0] - 1], axis=1).astype(np.int64)


def square_ids(h: Hypothesis, ij: NDArray[np.int64]) -> NDArray[np.int64]:
    """Chart (row, col) of lattice squares ``ij`` (N, 2) under ``h``."""
    x = (ij[:, ::-1] - 0.5) @ _ROT[h.k].T + np.array(h.t)
    return np.rint(np.stack([x[:, 1] - 0.5, x[:, 0] - 0.5], axis=1)).astype(np.int64)


def hypotheses(
    chart: VerificationChart, sq: Squares, nodes: NDArray[np.int64], parity: int
) -> list[Hypothesis]:
    """Every plausible lattice → chart hypothesis, fewest contradictions first."""
    codes = _chart_codes(chart)
    cols, rows = chart.squares
    obs = sq.code != UNKNOWN
    circ = sq.ij[sq.code == CIRCLE]
    out = []
    seen = set()
    for k in range(4):
        for o in circ:
            xo = (o[::-1] - 0.5) @ _ROT[k].T
            for p in chart.circle_pairs:
                for r, c in p.square_ids:
                    t = (round(float(c + 0.5 - xo[0])), round(float(r + 0.5 - xo[1])))
                    if (k, t) in seen:
                        continue
                    seen.add((k, t))
                    h = Hypothesis(k, t, 0, 0)
                    s = square_ids(h, sq.ij[obs])
                    # colour parity: lattice square black iff (i+j+parity) even, chart (r+c)
                    if (o[0] + o[1] + parity) % 2 != (r + c) % 2:
                        continue
                    inside = (s[:, 0] >= 0) & (s[:, 0] < rows) & (s[:, 1] >= 0) & (s[:, 1] < cols)
                    exp = np.full(len(s), -2)
                    exp[inside] = codes[s[inside, 0], s[inside, 1]]
                    got = sq.code[obs]
                    n = corner_ids(h, nodes)
                    out_nodes = np.count_nonzero(
                        (n[:, 0] < 0) | (n[:, 0] > rows - 2) | (n[:, 1] < 0) | (n[:, 1] > cols - 2)
                    )
                    mis = int(np.count_nonzero(exp != got)) + int(out_nodes)
                    hits = int(np.count_nonzero((exp == CIRCLE) & (got == CIRCLE)))
                    out.append(Hypothesis(k, t, mis, hits))
    out.sort(key=lambda h: (h.mismatches, -h.circles))
    return out


def u_axis_angle_deg(h: Hypothesis, e1: F64, e2: F64) -> float:
    """In-image angle of the chart's +u axis under ``h``, degrees from +x towards +y."""
    d = _ROT[h.k].T @ np.array([1.0, 0.0])  # lattice (j, i) step of one chart column
    v = d[0] * e1 + d[1] * e2
    return float(np.degrees(np.arctan2(v[1], v[0])))


def choose(
    hyps: list[Hypothesis], n_obs: int, e1: F64, e2: F64, hint_deg: float
) -> tuple[Hypothesis | None, str]:
    """Pick the hypothesis (see module docstring, step 2) or say why none can be trusted.

    The best must contradict at most max(1, 1 %) of the coded squares and explain ≥ 2
    circles. A rival within one contradiction of it is tolerated only if the rotation hint
    rules the rival out (and not the best); a best that the hint rules out needs every
    plausible rival to have ≥ 3 more contradictions.
    """
    if not hyps:
        return None, "no circle inside the detected chessboard lattice"
    best = hyps[0]
    allowed = max(1, int(0.01 * n_obs))
    if best.mismatches > allowed:
        return None, (
            f"the detected lattice contradicts the chart layout in {best.mismatches} squares "
            f"(is it the verification chart? is it partly occluded?)"
        )

    def plausible(h: Hypothesis) -> bool:
        diff = (u_axis_angle_deg(h, e1, e2) - hint_deg + 180.0) % 360.0 - 180.0
        return abs(diff) < 45.0

    rivals = [h for h in hyps[1:] if h.mismatches <= best.mismatches + 1]
    if rivals and not (plausible(best) and not any(plausible(h) for h in rivals)):
        return None, (
            "the visible circles do not identify the chart uniquely; show more of the chart "
            "or pass a rotation hint"
        )
    if not plausible(best) and any(
        plausible(h) and h.mismatches <= best.mismatches + 2 for h in hyps[1:]
    ):
        return None, "the chart's orientation contradicts the rotation hint; check the hint"
    if best.circles < 2:
        return None, "fewer than two chart circles are inside the detected lattice"
    return best, ""


def smooth_residuals(ids: NDArray[np.int64], pts: F64) -> F64:
    """|image − fit| (N,) of a homography + cubic polynomial from chart (col, row) to pixels."""
    obj = ids[:, ::-1].astype(np.float64)
    H, _ = cv2.findHomography(obj, pts, 0)
    if H is None:
        return np.full(len(pts), np.inf)
    ph = np.c_[obj, np.ones(len(obj))] @ H.T
    proj = ph[:, :2] / ph[:, 2:]
    d = pts - proj
    if len(pts) < 30:
        return np.asarray(np.hypot(*d.T), dtype=np.float64)
    u = (obj - obj.mean(axis=0)) / max(float(np.ptp(obj)), 1.0)
    A = np.stack([u[:, 0] ** a * u[:, 1] ** b for a in range(4) for b in range(4 - a)], axis=1)
    w = np.ones(len(pts), bool)
    for _ in range(3):
        coef, *_ = np.linalg.lstsq(A[w], d[w], rcond=None)
        res = np.hypot(*(d - A @ coef).T)
        mad = float(np.median(res[w])) * 1.4826 + 1e-3
        w = res < max(5.0 * mad, 0.05)
        if w.sum() < A.shape[1] * 2:
            break
    return np.asarray(res, dtype=np.float64)


_STENCIL = np.array([(di, dj) for di in range(-2, 3) for dj in range(-2, 3) if (di, dj) != (0, 0)])


def local_residuals(ids: NDArray[np.int64], pts: F64, min_neighbours: int = 10) -> F64:
    """|corner − its prediction from the 5 × 5 neighbourhood| (N,) px; NaN where too few.

    Each corner is predicted by a quadratic in (Δrow, Δcol) fitted to the other corners of its
    5 × 5 block (perspective and lens distortion are smooth at that scale: the fit's own error
    is ~10⁻³ square); a corner pulled by an occluder edge or glare stands out by tenths of a
    pixel, where a clean one is off by its noise (~0.01–0.05 px).
    """
    lo = ids.min(axis=0) - 2
    shape = tuple(ids.max(axis=0) - lo + 3)
    P = np.full((*shape, 2), np.nan)
    a = ids - lo
    P[a[:, 0], a[:, 1]] = pts
    nb = P[a[:, 0, None] + _STENCIL[None, :, 0], a[:, 1, None] + _STENCIL[None, :, 1]]  # (N, 24, 2)
    w = np.isfinite(nb[..., 0]).astype(np.float64)
    di, dj = _STENCIL[:, 0].astype(np.float64), _STENCIL[:, 1].astype(np.float64)
    A = np.stack([np.ones_like(di), di, dj, di * di, di * dj, dj * dj], axis=1)  # (24, 6)
    N = np.einsum("nk,ki,kj->nij", w, A, A) + 1e-9 * np.eye(6)
    rhs = np.einsum("nk,ki,nkx->nix", w, A, np.nan_to_num(nb - pts[:, None, :]))
    ok = w.sum(axis=1) >= min_neighbours
    # rows and columns present on ≥ 3 distinct offsets each, or the quadratic is not fixed
    ok &= (np.stack([(w * (di == d)).any(axis=1) for d in range(-2, 3)]).sum(axis=0) >= 3) & (
        np.stack([(w * (dj == d)).any(axis=1) for d in range(-2, 3)]).sum(axis=0) >= 3
    )
    out = np.full(len(pts), np.nan)
    if ok.any():
        coef = np.linalg.solve(N[ok], rhs[ok])  # (n, 6, 2): offsets from the corner itself
        out[ok] = np.hypot(*coef[:, 0, :].T)
    return out
