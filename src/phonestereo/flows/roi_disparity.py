"""ROI disparity: the application phase's measuring blocks (thesis §4.1.3, Fig. 4-2).

"Features in the ROI, matched into the tele → majority disparity → ROI expansion → majority
again → W-T scale in the ROI": the pair is rectified (canonical, §3.3) only in a window around
the expanded ROI (no full-frame remap), sparse sub-pixel matches are found there
(:func:`~phonestereo.features.matching.match_rectified`), the majority disparity of the ROI's
own matches selects the surface the user pointed at, the expanded ROI's matches on that
surface are kept, and a robust plane d = a + b·x + c·y (exact for a planar surface: 1/Z is
affine in the image) gives the disparity over the ROI with its σ. Every coordinate returned is
in the *reference* rectified frame (:func:`reference_rectification`: canonical, shared field
of view), the frame the fix store's observations live in.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np
from scipy.optimize import least_squares

from phonestereo.errors import InputError
from phonestereo.features.matching import MatchConfig, match_rectified
from phonestereo.fixes.focus import WTScale, fit_wt_scale
from phonestereo.geometry import Rig
from phonestereo.geometry._checks import Array
from phonestereo.rectification import Rectification, RectifyOptions

F64 = Array


def reference_rectification(rig: Rig, mode: str = "canonical") -> Rectification:
    """The reference rectified frame of a calibration: ``mode``, shared field of view."""
    return Rectification.from_rig(rig, mode)


@dataclass(frozen=True)
class RoiConfig:
    """Parameters of the ROI measurement.

    Attributes
    ----------
    mode : str
        Rectification mode (canonical, §3.3; the others for ablation).
    expand : float
        ROI expansion factor per side (Fig. 4-2), ≥ 1.
    z_min_m : float
        Nearest depth searched (sets the largest disparity).
    majority_bin_px, majority_tol_px, majority_tol_rel : float
        Histogram bin of the majority vote and the band kept about it (max of px, relative).
    min_matches : int
        Fewest matches on the surface for a measurement.
    coarse_min_zncc, fine_range_px : float, int
        The coarse whole-box correlation must reach this ZNCC; the fine search is then
        ±``fine_range_px`` around it (repetitive texture stays unambiguous).
    coarse_expand, max_ambiguity : float
        The coarse box is the ROI expanded this much; a second correlation peak (> 2 px
        away, a separate local maximum) above ``max_ambiguity`` × the first makes the
        measurement fail as ambiguous.
    wt_scale : bool
        Fit and apply the W-T scale in the ROI (§3.5.1).
    match : MatchConfig
    """

    mode: str = "canonical"
    expand: float = 1.6
    z_min_m: float = 0.4
    majority_bin_px: float = 0.5
    majority_tol_px: float = 0.75
    majority_tol_rel: float = 0.04
    min_matches: int = 12
    coarse_min_zncc: float = 0.5
    equalise_blur: bool = True
    coarse_rows: int = 8
    coarse_expand: float = 3.0
    max_ambiguity: float = 0.97
    fine_range_px: int = 3
    wt_scale: bool = True
    # Wide and tele have different optics: a window never fits to the noise level (the
    # Middlebury-tuned residual-to-noise test would reject every match on a high-contrast
    # chart), so only the contrast-relative residual test is kept; σ_d still includes misfit.
    match: MatchConfig = field(
        default_factory=lambda: MatchConfig(
            max_keypoints=1200, max_residual_ratio=1e9, max_normalized_residual=0.35
        )
    )


@dataclass(frozen=True)
class PlaneFit:
    """Robust disparity plane d = a + b·(x − x0) + c·(y − y0) over the kept matches."""

    coef: F64
    cov: F64
    x0: float
    y0: float
    scatter_px: float
    n: int

    def predict(self, xy: Any) -> tuple[F64, F64]:
        """(d, σ_d) at reference-frame points (N, 2)."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        A = np.column_stack([np.ones(len(p)), p[:, 0] - self.x0, p[:, 1] - self.y0])
        var = np.einsum("ij,jk,ik->i", A, self.cov, A)
        return A @ self.coef, np.sqrt(np.clip(var, 0.0, None))


@dataclass(frozen=True)
class RoiMeasurement:
    """What the ROI blocks measured.

    Attributes
    ----------
    ok : bool
    reason : str
        Why not ok (no texture, no surface, ...).
    xy : (N, 2)
        Kept matches, reference rectified wide pixels.
    d, e, sigma_d : (N,)
        Their disparity (W-T corrected when enabled), non-disparity error, 1σ, px.
    in_roi : (N,) bool
        Match inside the original ROI.
    majority_px : float
        The final majority disparity.
    plane : PlaneFit or None
    wt : WTScale or None
    roi_grid : (M, 2)
        The ROI's sample grid in the reference frame (where the depth is reported).
    counts : dict
        Matches after each block.
    """

    ok: bool
    reason: str
    xy: F64
    d: F64
    e: F64
    sigma_d: F64
    in_roi: np.ndarray
    majority_px: float
    plane: PlaneFit | None
    wt: WTScale | None
    roi_grid: F64
    counts: dict[str, int]


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


def fit_plane(xy: F64, d: F64, sigma: F64) -> PlaneFit:
    """Robust (soft-L1) weighted plane of d over (x, y); σ from the scatter and Jacobian."""
    x0, y0 = float(np.mean(xy[:, 0])), float(np.mean(xy[:, 1]))
    A = np.column_stack([np.ones(len(d)), xy[:, 0] - x0, xy[:, 1] - y0])
    w = 1.0 / np.clip(sigma, 1e-3, None)
    Aw, bw = A * w[:, None], d * w
    p0 = np.linalg.lstsq(Aw, bw, rcond=None)[0]
    res = least_squares(lambda p: Aw @ p - bw, p0, loss="soft_l1", f_scale=2.0)
    r = d - A @ res.x
    rw = r * w
    inl = np.abs(rw) <= 4.0 * max(1.0, 1.4826 * float(np.median(np.abs(rw))))
    dof = max(int(inl.sum()) - 3, 1)
    chi2 = float(np.sum(rw[inl] ** 2)) / dof
    # σ: Cramér–Rao weights, inflated by the observed scatter when it exceeds them.
    cov = np.linalg.pinv(Aw[inl].T @ Aw[inl]) * max(chi2, 1.0)
    scatter = float(1.4826 * np.median(np.abs(r[inl] - np.median(r[inl])))) if inl.any() else 0.0
    return PlaneFit(np.asarray(res.x), cov, x0, y0, scatter, int(inl.sum()))


def coarse_disparity(
    left: Any, right: Any, box: tuple[int, int, int, int], d_min: int, d_max: int, rows: int = 3
) -> tuple[float, float, float, float]:
    """Whole-window ZNCC disparity of a rectified box (cv2.matchTemplate): (d, peak ZNCC,
    second peak (another local maximum > 2 px away), e) with e the whole-pixel row offset.

    The coarse step before sub-pixel matching: one large window (the expanded ROI) is far less
    ambiguous than 15-px windows on repetitive texture (a chessboard's period is within the
    disparity range), so the fine search can then be narrowed to a few pixels around it. The
    second peak is the best other local maximum more than 2 px away (an ambiguity measure).
    """
    x, y, w, h = box
    tpl = np.ascontiguousarray(left[y : y + h, x : x + w], dtype=np.float32)
    H, W = right.shape[:2]
    xs0, xs1 = max(0, x - d_max), min(W, x + w - d_min)
    ys0, ys1 = max(0, y - rows), min(H, y + h + rows)
    strip = np.ascontiguousarray(right[ys0:ys1, xs0:xs1], dtype=np.float32)
    if strip.shape[0] < h or strip.shape[1] < w or float(tpl.std()) < 1e-3:
        return float("nan"), float("nan"), float("nan"), float("nan")
    score = cv2.matchTemplate(strip, tpl, cv2.TM_CCOEFF_NORMED)
    col = score.max(axis=0)  # best row per shift
    j = int(np.argmax(col))
    row = int(np.argmax(score[:, j])) + ys0  # the tele row of the box's top at the peak
    peak = float(col[j])
    sub = 0.0
    if 0 < j < len(col) - 1:  # parabola through the peak: coarse only, ±0.5 px is enough
        den = col[j - 1] - 2 * col[j] + col[j + 1]
        sub = float(0.5 * (col[j - 1] - col[j + 1]) / den) if den < 0 else 0.0
    # The second peak is the best *other local maximum* (a broad main lobe is not ambiguity).
    inner = col[1:-1]
    is_max = (inner >= col[:-2]) & (inner >= col[2:])
    idx = np.flatnonzero(is_max) + 1
    idx = idx[np.abs(idx - j) > 2]
    second = float(col[idx].max()) if idx.size else float("-inf")
    d = x - (xs0 + j + sub)
    return float(d), peak, second, float(y - row)


def equalise_blur(
    left: Any,
    right: Any,
    box: tuple[int, int, int, int],
    d0: float,
    sigmas: tuple[float, ...] = (0.0, 0.4, 0.7, 1.0, 1.4, 1.8, 2.4, 3.0),
) -> tuple[Any, Any, float, float]:
    """Blur the sharper image of the pair so both have the same blur: (left, right, σ_l, σ_r).

    Defocus differs between the cameras away from the focus distance (f/1.8 wide vs f/2.8
    tele), and a blur mismatch makes every window misfit. The Gaussian σ (added to one image)
    that maximises the box's ZNCC at the coarse disparity ``d0`` is chosen; a symmetric blur
    does not move the correlation peak, so d is unbiased.
    """
    x, y, w, h = box
    xi = round(d0)
    _H, W = right.shape[:2]
    x0 = max(x, xi)
    x1 = min(x + w, W + xi)
    if x1 - x0 < 16:
        return left, right, 0.0, 0.0
    a = np.asarray(left, np.float32)
    b = np.asarray(right, np.float32)

    def zncc(p: Any, q: Any) -> float:
        p, q = p - p.mean(), q - q.mean()
        return float((p * q).sum() / np.sqrt((p * p).sum() * (q * q).sum() + 1e-12))

    # Candidates are scored on the compared regions plus a blur border only (not the window).
    m = int(np.ceil(3 * max(sigmas))) + 1
    ya, yb = max(y - m, 0), min(y + h + m, a.shape[0])
    ca = a[ya:yb, max(x0 - m, 0) : min(x1 + m, a.shape[1])]
    cb = b[ya:yb, max(x0 - xi - m, 0) : min(x1 - xi + m, b.shape[1])]
    ia = (slice(y - ya, y - ya + h), slice(x0 - max(x0 - m, 0), x1 - max(x0 - m, 0)))
    ib = (
        slice(y - ya, y - ya + h),
        slice(x0 - xi - max(x0 - xi - m, 0), x1 - xi - max(x0 - xi - m, 0)),
    )
    best = (zncc(ca[ia], cb[ib]), 0.0, 0.0)
    for s in sigmas[1:]:
        la = cv2.GaussianBlur(ca, (0, 0), s)
        rb = cv2.GaussianBlur(cb, (0, 0), s)
        best = max(best, (zncc(la[ia], cb[ib]), s, 0.0), (zncc(ca[ia], rb[ib]), 0.0, s))
    if best[2] > 0:
        # The tele is the sharper one: leave the pair as it is. (Blurring the matcher's right
        # image collapses its sub-pixel stage — measured: 841 → 104 survivors on a chart at
        # 2 m — while the wide/tele misfit of an unblurred pair only widens σ_d.)
        best = (best[0], 0.0, 0.0)
    _, s_l, s_r = best
    if s_l > 0:
        a = cv2.GaussianBlur(a, (0, 0), s_l)
    if s_r > 0:
        b = cv2.GaussianBlur(b, (0, 0), s_r)
    return a, b, s_l, s_r


def _expanded(roi: tuple[int, int, int, int], factor: float, size: tuple[int, int]) -> Any:
    x, y, w, h = roi
    cx, cy = x + w / 2, y + h / 2
    w2, h2 = w * factor, h * factor
    x0, y0 = max(0, round(cx - w2 / 2)), max(0, round(cy - h2 / 2))
    x1, y1 = min(size[0], round(cx + w2 / 2)), min(size[1], round(cy + h2 / 2))
    return (x0, y0, x1 - x0, y1 - y0)


def tele_view_box(ref: Rectification, margin_px: int = 40) -> tuple[int, int, int, int]:
    """The raw-wide box the tele sees (the reference window unrectified), shrunk by a margin."""
    w, h = ref.wide_rect.size
    edge = np.concatenate([
        np.column_stack([np.linspace(0, w - 1, 32), np.zeros(32)]),
        np.column_stack([np.linspace(0, w - 1, 32), np.full(32, h - 1.0)]),
        np.column_stack([np.zeros(32), np.linspace(0, h - 1, 32)]),
        np.column_stack([np.full(32, w - 1.0), np.linspace(0, h - 1, 32)]),
    ])  # fmt: skip
    raw = ref.unrectify_wide(edge)
    raw = raw[np.isfinite(raw).all(axis=1)]
    lo = np.maximum(raw.min(axis=0) + margin_px, 0)
    hi = np.minimum(raw.max(axis=0) - margin_px, np.array(ref.rig.wide.size) - 1)
    return int(lo[0]), int(lo[1]), int(max(hi[0] - lo[0], 0)), int(max(hi[1] - lo[1], 0))


def roi_grid(roi: tuple[int, int, int, int], n: int = 9) -> F64:
    """An n × n grid of raw wide pixels over the ROI (x, y, w, h), (n², 2)."""
    x, y, w, h = roi
    gx, gy = np.meshgrid(np.linspace(x, x + w - 1, n), np.linspace(y, y + h - 1, n))
    return np.column_stack([gx.ravel(), gy.ravel()])


def _fail(reason: str, grid: F64, counts: dict[str, int], wt: WTScale | None = None) -> Any:
    z = np.zeros(0)
    return RoiMeasurement(
        False, reason, np.zeros((0, 2)), z, z, z, np.zeros(0, bool), float("nan"), None, wt,
        grid, counts,
    )  # fmt: skip


def measure_roi(
    rig: Rig,
    image_wide: Any,
    image_tele: Any,
    roi: tuple[int, int, int, int],
    config: RoiConfig | None = None,
    reference: Rectification | None = None,
) -> RoiMeasurement:
    """Disparity of the surface in a raw-wide ROI (Fig. 4-2's measuring blocks).

    Parameters
    ----------
    rig : Rig
        The calibration (possibly already focus-corrected).
    image_wide, image_tele : ndarray
        Raw images (grey or colour).
    roi : (x, y, w, h)
        Raw wide pixels.
    config : RoiConfig
    reference : Rectification, optional
        The reference frame (default :func:`reference_rectification` of ``rig``).

    Returns
    -------
    RoiMeasurement
        ``ok`` False with a reason when the ROI gives no measurement (no texture, no surface,
        too few matches) — never an exception for data-caused failures.
    """
    cfg = config or RoiConfig()
    if cfg.expand < 1.0:
        raise InputError(f"ROI expansion must be >= 1, got {cfg.expand}")
    ref = reference or reference_rectification(rig, cfg.mode)
    w_img, h_img = rig.wide.size
    x, y, w, h = (int(v) for v in roi)
    if w <= 0 or h <= 0 or x < 0 or y < 0 or x + w > w_img or y + h > h_img:
        raise InputError(f"ROI {list(roi)} is not inside the {w_img}×{h_img} wide image")
    roi = (x, y, w, h)
    grid_raw = roi_grid(roi)
    d_max = int(np.ceil(ref.f_px * abs(ref.baseline_m) / cfg.z_min_m)) + 2
    big = _expanded(roi, cfg.expand, rig.wide.size)
    wide_box = _expanded(roi, max(cfg.coarse_expand, cfg.expand), rig.wide.size)
    win = Rectification.from_rig(rig, cfg.mode, RectifyOptions(roi=wide_box, margin_px=d_max + 12))
    shift = np.array([ref.wide_rect.cx - win.wide_rect.cx, ref.wide_rect.cy - win.wide_rect.cy])
    grid = win.points_wide(grid_raw) + shift
    counts: dict[str, int] = {}
    lw, rt = win.remap(image_wide, image_tele)
    box_small = win.points_wide(roi_grid(roi, 3))
    boxes = []
    for b in (big, wide_box):
        pts = win.points_wide(roi_grid(b, 3))
        if not (np.isfinite(box_small).all() and np.isfinite(pts).all()):
            return _fail("the ROI does not map into the rectified view", grid, counts)
        lo, hi = np.floor(pts.min(0)).astype(int), np.ceil(pts.max(0)).astype(int)
        rw, rh = win.wide_rect.size
        lo, hi = np.maximum(lo, 0), np.minimum(hi, [rw - 1, rh - 1])
        boxes.append((int(lo[0]), int(lo[1]), int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1)))
    box, cbox = boxes
    # The coarse step correlates a box `coarse_expand` times the ROI: a repetitive texture
    # (a chessboard's period is inside the disparity range) needs the context around it.
    d0, peak, second, e0 = coarse_disparity(lw, rt, cbox, -2, d_max, rows=cfg.coarse_rows)
    counts["coarse_zncc_x1000"] = round(1000 * peak) if np.isfinite(peak) else 0
    if not np.isfinite(d0) or peak < cfg.coarse_min_zncc:
        return _fail(
            f"the ROI does not correlate with the tele (ZNCC {peak:.2f} < "
            f"{cfg.coarse_min_zncc}): no texture, occluded, or outside the tele's view",
            grid, counts,
        )  # fmt: skip
    if second >= cfg.max_ambiguity * peak:
        return _fail(
            f"ambiguous disparity: two correlation peaks ({peak:.3f}, {second:.3f}) — a "
            "repetitive texture without context; enlarge the ROI or aim at a distinct object",
            grid, counts,
        )  # fmt: skip
    if cfg.equalise_blur:
        lw, rt, s_l, s_r = equalise_blur(lw, rt, box, d0)
        counts["blur_added_x100"] = round(100 * (s_l - s_r))
    lo_d = int(np.floor(d0)) - cfg.fine_range_px
    hi_d = int(np.ceil(d0)) + cfg.fine_range_px
    counts["coarse_e_px"] = int(e0)
    mcfg = cfg.match
    if abs(e0) + 2 > mcfg.row_tolerance:  # a calibration off across the baseline (refocus)
        mcfg = replace(mcfg, row_tolerance=int(abs(e0)) + 2)
    res = match_rectified(lw, rt, max_disparity=hi_d, min_disparity=lo_d, roi=box, config=mcfg)
    counts["matches"] = len(res.d)
    if len(res.d) == 0:
        return _fail(f"no features matched in the ROI: {res.reason}", grid, counts)
    slo, shi = box_small.min(0), box_small.max(0)
    in_roi = np.all((res.xy >= slo) & (res.xy <= shi), axis=1)
    counts["in_roi"] = int(in_roi.sum())
    if counts["in_roi"] < 3:
        return _fail(
            f"only {counts['in_roi']} features matched inside the ROI: no texture?", grid, counts
        )
    kw = {"bin_px": cfg.majority_bin_px, "tol_px": cfg.majority_tol_px,
          "tol_rel": cfg.majority_tol_rel}  # fmt: skip
    m1, _ = majority(res.d[in_roi], **kw)
    tol = max(cfg.majority_tol_px, cfg.majority_tol_rel * abs(m1))
    keep = np.abs(res.d - m1) <= 3 * tol  # expanded ROI: matches on the majority surface
    m2, sel = majority(res.d[keep], **kw)
    idx = np.flatnonzero(keep)[sel]
    counts["majority"] = len(idx)
    if len(idx) < cfg.min_matches:
        return _fail(
            f"{len(idx)} matches on the majority surface (< {cfg.min_matches})", grid, counts
        )
    xy = res.xy[idx] + shift
    d, e, sd = res.d[idx], res.e[idx], res.sigma_d[idx]
    wt = None
    if cfg.wt_scale:
        c_tele = ref.points_tele(np.array([[rig.tele.cx, rig.tele.cy]]))[0]
        fit = fit_wt_scale(xy, xy - np.column_stack([d, e]), c_tele, sigma_px=res.sigma_e[idx])
        assert isinstance(fit, WTScale)
        wt = fit
        if fit.ok:
            d, e = fit.disparity(xy, xy - np.column_stack([d, e]))
    plane = fit_plane(xy, d, sd)
    resid = d - plane.predict(xy)[0]
    good = np.abs(resid) <= max(4 * plane.scatter_px, 0.2)
    counts["plane"] = int(good.sum())
    return RoiMeasurement(
        True, "", xy[good], d[good], e[good], sd[good], in_roi[idx][good], m2, plane, wt, grid,
        counts,
    )  # fmt: skip


__all__ = [
    "PlaneFit",
    "RoiConfig",
    "RoiMeasurement",
    "fit_plane",
    "majority",
    "measure_roi",
    "reference_rectification",
    "roi_grid",
    "tele_view_box",
]
