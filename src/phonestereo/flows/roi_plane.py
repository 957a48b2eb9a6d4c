"""The ROI's surface: the fine matches about the coarse disparity, their majority disparity,
the matches along its plane, and the disparity surface fitted to them with its σ (thesis
§4.1.3; used by :func:`~phonestereo.flows.roi_disparity.measure_roi`)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from phonestereo.features.matching import match_rectified
from phonestereo.flows.roi_config import RoiConfig
from phonestereo.geometry.checks import Array

F64 = Array

#: Fewest matches for the disparity surface's curvature terms (6 parameters with a margin).
CURVED_MIN_MATCHES = 40
#: Length unit of the curvature terms, px (conditioning only).
_CURVE_UNIT_PX = 100.0


def _design(p: F64, x0: float, y0: float, n_coef: int) -> F64:
    """Columns 1, dx, dy (and (dx², dx·dy, dy²) / 100² px when ``n_coef`` is 6)."""
    dx, dy = p[:, 0] - x0, p[:, 1] - y0
    cols = [np.ones(len(p)), dx, dy]
    if n_coef == 6:
        u, v = dx / _CURVE_UNIT_PX, dy / _CURVE_UNIT_PX
        cols += [u * u, u * v, v * v]
    return np.column_stack(cols)


@dataclass(frozen=True)
class PlaneFit:
    """Robust disparity surface d = a + b·(x − x0) + c·(y − y0) [+ curvature] over the kept
    matches (:func:`fit_plane`); ``coef`` has 3 entries, or 6 with the curvature terms."""

    coef: F64
    cov: F64
    x0: float
    y0: float
    scatter_px: float
    n: int

    def predict(self, xy: Any) -> tuple[F64, F64]:
        """(d, σ_d) at reference-frame points (N, 2)."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        A = _design(p, self.x0, self.y0, len(self.coef))
        var = np.einsum("ij,jk,ik->i", A, self.cov, A)
        return A @ self.coef, np.sqrt(np.clip(var, 0.0, None))


def majority(d: Any, *, bin_px: float, tol_px: float, tol_rel: float) -> tuple[float, np.ndarray]:
    """Majority disparity (thesis §4.1.3): the most populated histogram bin (smoothed over its
    neighbours), refined to the median of the matches within the band; (value, mask).

    Examples
    --------
    >>> v, m = majority([9.9, 10.0, 10.1, 10.05, 3.0, 3.1], bin_px=0.5, tol_px=0.5, tol_rel=0)
    >>> round(v, 3), m.tolist()
    (10.025, [True, True, True, True, False, False])
    """
    x = np.asarray(d, dtype=np.float64)
    if x.size == 0:
        return float("nan"), np.zeros(0, bool)
    lo = np.floor(x.min() / bin_px) - 1
    idx = (np.floor(x / bin_px) - lo).astype(np.int64)
    counts = np.bincount(idx, minlength=int(idx.max()) + 2).astype(np.float64)
    smooth = np.convolve(counts, [0.5, 1.0, 0.5], mode="same")
    peak = (int(np.argmax(smooth)) + lo + 0.5) * bin_px
    tol = max(tol_px, tol_rel * abs(peak))
    mask = np.abs(x - peak) <= tol
    value = float(np.median(x[mask]))
    mask = np.abs(x - value) <= tol
    return float(np.median(x[mask])), mask


#: Soft-L1 scale of the weighted residuals (in σ units).
_F_SCALE = 2.0


def _soft_l1(Aw: F64, bw: F64, p: F64, max_iter: int = 50) -> F64 | None:
    """The minimiser of Σ 2c²(√(1 + (r/c)²) − 1), r = Aw·p − bw, c = :data:`_F_SCALE` (the
    cost of SciPy's ``least_squares(loss="soft_l1")``) by Newton's method with a backtracking
    line search from ``p``; None when the Hessian is singular or it does not converge.

    The cost is strictly convex in p (full-rank Aw), so its minimiser is unique; this one is
    converged to a relative step ≤ 1e-9 (4-6 Newton steps) where ``least_squares`` stops at a
    relative cost change of 1e-8 (the ROI's plane agrees to 6e-10 px on the 2 MP bench set,
    2.5e-7 px on random planes with outliers) at a fifth of the time: the ROI flow fits 3-4
    planes per capture.
    """
    c2 = _F_SCALE * _F_SCALE

    def cost(q: F64) -> tuple[float, F64, F64]:
        r = Aw @ q - bw
        s = np.sqrt(1.0 + r * r / c2)
        return float(np.sum(s - 1.0)), r / s, s  # cost / (2c²), ρ'·r, and √(1 + (r/c)²)

    f, g_r, s = cost(p)
    for _ in range(max_iter):
        g = Aw.T @ g_r
        H = (Aw * (1.0 / s**3)[:, None]).T @ Aw
        try:
            step = np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            return None
        if not np.all(np.isfinite(step)):
            return None
        if np.max(np.abs(step)) <= 1e-9 * (1.0 + np.max(np.abs(p))):
            return p - step  # quadratic convergence: the next step would be rounding noise
        t, slope = 1.0, float(g @ step) / c2
        for _ in range(30):
            f_new, g_new, s_new = cost(p - t * step)
            if f_new <= f - 1e-4 * t * slope:
                break
            t *= 0.5
        else:
            return p if slope <= 1e-20 * (1.0 + f) else None
        p, f, g_r, s = p - t * step, f_new, g_new, s_new
    return None


def fit_plane(xy: F64, d: F64, sigma: F64, curved: bool | None = None) -> PlaneFit:
    """Robust (soft-L1) weighted plane of d over (x, y); σ from the scatter and Jacobian.

    A planar surface's disparity is affine only in a perfectly rectified frame. Through a
    factory calibration whose distortion (and its change with focus) is off, the chart's
    true disparity over the 1.6× ROI box departs from a plane by 0.03 px RMS, 0.1-0.18 px at
    the box's edges (random-1011: a cubic leaves 0.007 px), and a plane through matches
    spread differently from capture to capture carries that into the ROI. With at least
    :data:`CURVED_MIN_MATCHES` matches (``curved`` None) the quadratic terms are fitted too
    (random-1011's ROI error SD 0.029 → 0.016 px, folded-x3 0.009 → 0.005 px), and σ is
    the 6-parameter one.
    """
    x0, y0 = float(np.mean(xy[:, 0])), float(np.mean(xy[:, 1]))
    if curved is None:
        curved = len(d) >= CURVED_MIN_MATCHES
    A = _design(xy, x0, y0, 6 if curved else 3)
    w = 1.0 / np.clip(sigma, 1e-3, None)
    Aw, bw = A * w[:, None], d * w
    p0 = np.linalg.lstsq(Aw, bw, rcond=None)[0]
    coef = _soft_l1(Aw, bw, p0)
    if coef is None:  # singular or not converged: SciPy's trust region
        # the residual is linear: its Jacobian is Aw (not SciPy's finite differences)
        coef = least_squares(
            lambda p: Aw @ p - bw, p0, jac=lambda p: Aw, loss="soft_l1", f_scale=_F_SCALE
        ).x
    r = d - A @ coef
    rw = r * w
    inl = np.abs(rw) <= 4.0 * max(1.0, 1.4826 * float(np.median(np.abs(rw))))
    dof = max(int(inl.sum()) - A.shape[1], 1)
    chi2 = float(np.sum(rw[inl] ** 2)) / dof
    # σ: Cramér–Rao weights, inflated by the observed scatter when it exceeds them.
    cov = np.linalg.pinv(Aw[inl].T @ Aw[inl]) * max(chi2, 1.0)
    scatter = float(1.4826 * np.median(np.abs(r[inl] - np.median(r[inl])))) if inl.any() else 0.0
    return PlaneFit(np.asarray(coef), cov, x0, y0, scatter, int(inl.sum()))


def follow_plane(xy: F64, d: F64, sigma: F64, idx: np.ndarray, tol: float,
                  rounds: int = 3) -> np.ndarray:
    """The majority surface's matches along its slant: within ``tol`` of its plane, not of
    one disparity.

    A band of constant disparity cuts a strip out of a slanted surface (a tilted chart, or a
    tele whose scale is off: random-1011's 1.7 % focus breathing makes d run 0.012 px/px, 5 px
    over the box), and where the strip lies moves from capture to capture; the plane then
    extrapolates its slope over the ROI (−0.27 … +0.19 px at the ROI, 0.14 px SD against a
    claimed 0.03). Refitting the plane to the selection and reselecting about it, a few
    times, keeps the whole surface.

    Examples
    --------
    >>> x = np.linspace(0, 400, 81)
    >>> xy, d = np.column_stack([x, np.zeros(81)]), 5 + 0.012 * x   # 4.8 px across
    >>> start = np.flatnonzero(np.abs(d - 7.4) <= 0.75)              # the constant band
    >>> len(start), len(follow_plane(xy, d, np.full(81, 0.05), start, 0.75))
    (25, 81)
    """
    for _ in range(rounds):
        if len(idx) < 6:
            break
        plane = fit_plane(xy[idx], d[idx], sigma[idx], curved=False)
        new = np.flatnonzero(np.abs(d - plane.predict(xy)[0]) <= tol)
        if len(new) < len(idx) or np.array_equal(new, idx):
            break
        idx = new
    return idx


def match_majority(
    left: Any,
    right: Any,
    box: tuple[int, int, int, int],
    d0: float,
    e0: float,
    slo: F64,
    shi: F64,
    cfg: RoiConfig,
) -> tuple[Any, np.ndarray, np.ndarray, float, dict[str, int]]:
    """Fine matching around the coarse disparity (d0, e0), then majority → expansion → majority
    (Fig. 4-2): (matches, in the ROI's small box ``slo``…``shi`` (N,) bool, the surface's match
    indices, the final majority disparity, counts)."""
    counts: dict[str, int] = {}
    mcfg = cfg.match
    if abs(e0) + 2 > mcfg.row_tolerance:  # a calibration off across the baseline (refocus)
        mcfg = replace(mcfg, row_tolerance=int(abs(e0)) + 2)
    lo_d = int(np.floor(d0)) - cfg.fine_range_px
    hi_d = int(np.ceil(d0)) + cfg.fine_range_px
    res = match_rectified(left, right, max_disparity=hi_d, min_disparity=lo_d, roi=box,
                          config=mcfg)
    counts["matches"] = len(res.d)
    in_roi = np.all((res.xy >= slo) & (res.xy <= shi), axis=1)
    counts["in_roi"] = int(in_roi.sum())
    empty = np.zeros(0, np.int64)
    if counts["in_roi"] < 3:
        return res, in_roi, empty, float("nan"), counts
    kw = {"bin_px": cfg.majority_bin_px, "tol_px": cfg.majority_tol_px,
          "tol_rel": cfg.majority_tol_rel}
    m1, _ = majority(res.d[in_roi], **kw)
    tol = max(cfg.majority_tol_px, cfg.majority_tol_rel * abs(m1))
    keep = np.abs(res.d - m1) <= 3 * tol  # expanded ROI: matches on the majority surface
    m2, sel = majority(res.d[keep], **kw)
    idx = follow_plane(res.xy, res.d, res.sigma_d, np.flatnonzero(keep)[sel], tol)
    counts["majority"] = len(idx)
    return res, in_roi, idx, m2, counts


__all__ = [
    "CURVED_MIN_MATCHES", "PlaneFit", "fit_plane", "follow_plane", "majority", "match_majority",
]
