"""ROI disparity: the application phase's measuring blocks (thesis §4.1.3, Fig. 4-2).

"Features in the ROI, matched into the tele → majority disparity → ROI expansion → majority
again → W-T scale in the ROI": the pair is rectified (canonical, §3.3) only in a window around
the expanded ROI (no full-frame remap), sparse sub-pixel matches are found there
(:func:`~phonestereo.features.matching.match_rectified`), the majority disparity of the ROI's
own matches selects the surface the user pointed at, the expanded ROI's matches on that
surface are kept, and a robust plane d = a + b·x + c·y (exact for a planar surface in a perfect
rectification: 1/Z is affine in the image; with enough matches plus the quadratic terms that a
factory calibration's distortion error leaves, :func:`fit_plane`) gives the disparity over the
ROI with its σ. Every coordinate returned is in the *reference* rectified frame
(:func:`reference_rectification`: canonical, shared field of view), the fix store's frame.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any

import numpy as np

from phonestereo.errors import InputError
from phonestereo.features._threads import background
from phonestereo.fixes.distortion import RadialResidualFix
from phonestereo.fixes.radial_residual import correct_matches
from phonestereo.fixes.wt_scale import WTScale, fit_wt_scale
from phonestereo.flows.band_gate import band_reason, band_split, on_row
from phonestereo.flows.blur_equalise import equalise_blur
from phonestereo.flows.coarse_gate import coarse_peak
from phonestereo.flows.roi_config import RoiConfig
from phonestereo.flows.roi_plane import PlaneFit, fit_plane, majority, match_majority
from phonestereo.flows.roi_window import (
    FineAhead,
    coarse_lazy,
    coarse_window,
    fine_part,
    fine_window,
)
from phonestereo.flows.view_box import inscribed_box, outline, tele_outline
from phonestereo.geometry import Rig
from phonestereo.geometry.checks import Array, frozen
from phonestereo.heap import keep_large_arrays_on_the_heap
from phonestereo.rectification import Rectification, RectifyOptions, check_pair

F64 = Array


#: How far from 0 the coarse step's rows are moved at most when its peak lies on their border
#: (:func:`measure_roi`), px: three times the default ±8 rows. The issue's module ranges (heating
#: drift up to 7 px per camera, factory noise up to 3×) reached 11–12 px (random-3056).
MAX_ROW_OFFSET_PX = 24


def reference_rectification(rig: Rig, mode: str = "canonical") -> Rectification:
    """The reference rectified frame of a calibration: ``mode``, shared field of view."""
    return Rectification.from_rig(rig, mode)


def tele_center_px(ref: Rectification, rig: Rig) -> Array:
    """``rig``'s tele principal point in ``ref``'s rectified frame (2,), px: the centre of the
    W-T scale (:class:`~phonestereo.fixes.wt_scale.WTScale`)."""
    return frozen(ref.points_tele(np.array([[rig.tele.cx, rig.tele.cy]]))[0])


@dataclass(frozen=True)
class RoiMeasurement:
    """What the ROI blocks measured."""

    ok: bool
    #: Why not ok (no texture, no surface, ...).
    reason: str
    #: (N, 2). Kept matches, reference rectified wide pixels.
    xy: F64
    #: ``d``, ``e``, ``sigma_d``: (N,). Their disparity (W-T corrected when enabled), non-disparity
    #: error, 1σ, px.
    d: F64
    #: See ``d`` above.
    e: F64
    #: See ``d`` above.
    sigma_d: F64
    #: (N,) bool. Match inside the original ROI.
    in_roi: np.ndarray
    #: The final majority disparity.
    majority_px: float
    plane: PlaneFit | None
    wt: WTScale | None
    #: (M, 2). The ROI's sample grid in the reference frame (where the depth is reported).
    roi_grid: F64
    #: dict. Matches after each block.
    counts: dict[str, int]


def _expanded(roi: tuple[int, int, int, int], factor: float, size: tuple[int, int]) -> Any:
    x, y, w, h = roi
    cx, cy = x + w / 2, y + h / 2
    w2, h2 = w * factor, h * factor
    x0, y0 = max(0, round(cx - w2 / 2)), max(0, round(cy - h2 / 2))
    x1, y1 = min(size[0], round(cx + w2 / 2)), min(size[1], round(cy + h2 / 2))
    return (x0, y0, x1 - x0, y1 - y0)


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
    )


@dataclass(frozen=True)
class _Window:
    """The rectified window of a raw-wide ROI and the boxes placed in it (image-independent)."""

    #: The window's rectification (it caches its maps: built once per window, not per capture).
    win: Rectification
    #: (2,). Window → reference rectified pixels.
    shift: F64
    #: The largest disparity searched, px.
    d_max: int
    #: (81, 2). The ROI's sample grid in the reference frame.
    grid: F64
    #: (9, 2). The ROI's 3 × 3 grid in the window.
    box_small: F64
    #: The expanded ROI's bounding box in the window (x, y, w, h).
    box: tuple[int, int, int, int]
    #: The coarse step's boxes, in the order tried.
    cboxes: tuple[tuple[int, int, int, int], ...]
    #: (2,). The tele's principal point in the reference frame.
    c_tele: F64
    #: Why the ROI cannot be measured ("" when it can).
    reason: str = ""


def _bounding_box(pts: F64, size: tuple[int, int]) -> tuple[int, int, int, int]:
    """The integer box (x, y, w, h) around points (N, 2), inside an image of ``size``."""
    lo, hi = np.floor(pts.min(0)).astype(int), np.ceil(pts.max(0)).astype(int)
    lo, hi = np.maximum(lo, 0), np.minimum(hi, [size[0] - 1, size[1] - 1])
    return int(lo[0]), int(lo[1]), int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1)


@lru_cache(maxsize=2)
def _window(
    rig: Rig, mode: str, ref: Rectification, roi: tuple[int, int, int, int], cfg: RoiConfig,
    row_offset_px: int = 0,
) -> _Window:
    """The window of ``roi`` (:class:`_Window`), its tele's rows moved by ``row_offset_px``
    (:attr:`~phonestereo.rectification.options.RectifyOptions.tele_row_shift_px`). Cached: the
    learning flow measures the W-T scale over the same box (the tele's view) of every face
    capture of a calibration, and the window's maps (~10 ms at 2000 × 1500) are then built
    once. Two entries: each holds its window's maps and keeps ``ref`` alive (keyed by
    identity)."""
    grid_raw = roi_grid(roi)
    d_max = int(np.ceil(ref.f_px * abs(ref.baseline_m) / cfg.z_min_m)) + 2
    big = _expanded(roi, cfg.expand, rig.wide.size)
    wide_box = _expanded(roi, max(cfg.coarse_expand, cfg.expand), rig.wide.size)
    margin = max(d_max, -cfg.far_disparity_px) + 12
    opts = RectifyOptions(roi=wide_box, margin_px=margin, grid_step_px=cfg.map_step_px,
                          tele_row_shift_px=float(row_offset_px))
    win = Rectification.from_rig(rig, mode, opts)
    # the tele's maps on the helper thread while this one places the boxes (measure_roi's
    # tele source is queued behind them there; the wide's maps are built on this thread)
    background(win.prepare, "tele")
    shift = np.array([ref.wide_rect.cx - win.wide_rect.cx, ref.wide_rect.cy - win.wide_rect.cy])
    # every raw point in one call (each point is undistorted on its own: the same values)
    raw = (grid_raw, roi_grid(roi, 3), roi_grid(big, 3), roi_grid(wide_box, 3), outline(wide_box))
    grid_w, box_small, pts, wide_pts, wide_outline = np.split(
        win.points_wide(np.concatenate(raw)), np.cumsum([len(r) for r in raw])[:-1]
    )
    grid = frozen(grid_w + shift)
    c_tele = tele_center_px(ref, rig)
    box_small = frozen(box_small)
    if not (np.isfinite(box_small).all() and np.isfinite(pts).all()):
        why = "the ROI does not map into the rectified view"
        return _Window(win, shift, d_max, grid, box_small, (0, 0, 0, 0), (), c_tele, why)
    box = _bounding_box(pts, win.wide_rect.size)
    # The coarse box: inside what the tele sees (a rotated or narrow tele leaves black corners
    # in the bounding box), else — or when that one is ambiguous — the bounding box.
    bbox = _bounding_box(wide_pts, win.wide_rect.size)
    span = (float(cfg.far_disparity_px), float(d_max))
    inner = inscribed_box(wide_outline, tele_outline(win), span, win.wide_rect.size)
    cboxes = [b for b in (inner, bbox) if b is not None]
    if inner == bbox:
        cboxes = [bbox]
    # The coarse step correlates a box `coarse_expand` times the ROI: a repetitive texture
    # (a chessboard's period is inside the disparity range) needs the context around it.
    if box not in cboxes:
        # A long tele (×5: a fifth of the wide's field) may not see the context box at all:
        # the ROI's own box is the last try.
        cboxes.append(box)
    return _Window(win, frozen(shift), d_max, grid, box_small, box, tuple(cboxes), c_tele)


def measure_roi(
    rig: Rig,
    image_wide: Any,
    image_tele: Any,
    roi: tuple[int, int, int, int],
    config: RoiConfig | None = None,
    reference: Rectification | None = None,
    *,
    mode: str | None = None,
    wt_scale: bool = True,
    radial: RadialResidualFix | None = None,
    row_offset_px: float = 0.0,
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
        The reference frame (default :func:`reference_rectification` of ``rig`` in ``mode``).
    mode : str, optional
        Rectification mode (canonical, §3.3; the others for ablation). Default: the
        reference's mode, else ``"canonical"``.
    wt_scale : bool
        Fit and apply the W-T scale in the ROI (§3.5.1).
    radial : RadialResidualFix, optional
        A learned residual radial distortion (§3.2, :mod:`~phonestereo.fixes.radial_residual`)
        taken out of the matches' d and e before the W-T scale is fitted.
    row_offset_px : float
        The row error e the calibration is known to have here (a learned one), px: the coarse
        step's ±``coarse_rows`` are searched about it (whole pixels). When the coarse peak lies
        on the border of those rows the rows are searched again about it, up to
        :data:`MAX_ROW_OFFSET_PX` from 0 (a factory rectification warm-up moves by more than
        ``coarse_rows``: random-3056's rows were off by 11–12 px and no capture was measured).
        The matches' e are reported in the reference frame (the offset added back).

    Returns
    -------
    RoiMeasurement
        ``ok`` False with a reason when the ROI gives no measurement (no texture, no surface,
        too few matches) — never an exception for data-caused failures.
    """
    keep_large_arrays_on_the_heap()  # page faults were ~10 % of this call's CPU (phonestereo.heap)
    cfg = config or RoiConfig()
    if cfg.expand < 1.0:
        raise InputError(f"ROI expansion must be >= 1, got {cfg.expand}")
    mode = mode or (reference.mode if reference is not None else "canonical")
    if reference is not None and reference.mode != mode:
        raise InputError(f"measure_roi: mode {mode!r} but the reference is {reference.mode!r}")
    ref = reference or reference_rectification(rig, mode)
    w_img, h_img = rig.wide.size
    x, y, w, h = (int(v) for v in roi)
    if w <= 0 or h <= 0 or x < 0 or y < 0 or x + w > w_img or y + h > h_img:
        raise InputError(f"ROI {list(roi)} is not inside the {w_img}×{h_img} wide image")
    roi = (x, y, w, h)
    rows = round(float(row_offset_px)) if np.isfinite(row_offset_px) else 0
    tried = {rows}
    m = _measure(rig, image_wide, image_tele, roi, cfg, ref, mode, wt_scale, radial, rows)
    while True:
        e0 = m.counts.get("coarse_e_px", rows) - rows  # the coarse peak's row in its window
        nxt = rows + e0
        if abs(e0) < cfg.coarse_rows or abs(nxt) > MAX_ROW_OFFSET_PX or nxt in tried:
            return m
        tried.add(nxt)
        again = _measure(rig, image_wide, image_tele, roi, cfg, ref, mode, wt_scale, radial, nxt)
        if m.ok and not again.ok:  # the border peak was measured: the wider rows found no better
            return m
        m, rows = again, nxt


def _measure(
    rig: Rig, image_wide: Any, image_tele: Any, roi: tuple[int, int, int, int], cfg: RoiConfig,
    ref: Rectification, mode: str, wt_scale: bool, radial: RadialResidualFix | None, rows: int,
) -> RoiMeasurement:
    """:func:`measure_roi` of a checked ROI with the tele's rows moved by ``rows`` px."""
    g = _window(rig, mode, ref, roi, cfg, rows)
    win, shift, d_max, box, cboxes, c_tele = g.win, g.shift, g.d_max, g.box, g.cboxes, g.c_tele
    grid = g.grid.copy()
    counts: dict[str, int] = {}
    # the tele's maps and antialias blur on the helper thread while this one prepares the
    # wide (the images are checked first: a wrong size raises)
    image_wide, image_tele = check_pair(image_wide, image_tele, rig.wide, rig.tele)
    if g.reason:
        return _fail(g.reason, grid, counts)
    pending = background(win.source, "tele", image_tele)
    source_wide = win.source("wide", image_wide)
    # the tele's principal point in the window's tele (its rows moved by `rows`)
    center = (float(c_tele[0] - shift[0]), float(c_tele[1] - shift[1] + rows)) if wt_scale else None
    # the left's coarse part here while the helper still blurs the tele (coarse_lazy)
    lazy = coarse_lazy((source_wide, pending), box, d_max, cfg, cboxes[0], image_tele)
    sources = (source_wide, pending.result())
    if lazy is None:
        lw, rt, two_pass = coarse_window(sources, box, d_max, cfg)
    else:  # the coarse step reads the first box; the next ones are resampled if tried
        lw, rt, two_pass = lazy.left, lazy.right, True
    # the fine parts on the helper while the coarse step correlates here (roi_window.fine_core)
    ahead = FineAhead(sources, box, cfg, center) if two_pass else None
    ch = coarse_peak(lw, rt, list(cboxes), d_max, cfg, center, partial=two_pass, cover=lazy,
                     on_prescale=None if ahead is None else ahead.prescaled)
    if ch.box == box and len(cboxes) > 1:
        counts["coarse_context_dropped"] = 1
    d0, e0, rt = ch.peak.d, ch.peak.e, ch.right
    counts.update(ch.counts())
    if np.isfinite(e0):  # in the reference frame
        counts["coarse_e_px"] = int(e0) + rows
    if rows:
        counts["row_offset_px"] = rows
    if ch.reason:
        return _fail(ch.reason, grid, counts)
    if two_pass:
        lw, rt = fine_window(sources, lw, rt, box, d0, e0, ch.scale, center, cfg, ahead)
    slo, shi = g.box_small.min(0), g.box_small.max(0)
    variants = [(lw, rt, 0.0)]
    if cfg.equalise_blur:
        # the blur only where the matcher reads (the fine part)
        part = fine_part(box, d0, e0, cfg, (lw.shape[1], lw.shape[0]))
        bl, br, s_l, s_r = equalise_blur(lw, rt, box, d0, e0, part=part)
        if s_l > 0 or s_r > 0:
            variants.insert(0, (bl, br, s_l - s_r))
    found: tuple[Any, np.ndarray, np.ndarray, float, dict[str, int]] | None = None
    for a, b, blur in variants:
        # Blur equalisation first; the unblurred pair when it leaves few matches (it can
        # help or hurt the window fits; the one with more matches on the surface is kept).
        res, in_roi, idx, m2, sub = match_majority(a, b, box, d0, e0, slo, shi, cfg)
        sub["blur_added_x100"] = round(100 * blur)
        if found is None or len(idx) > len(found[2]):
            found = (res, in_roi, idx, m2, sub)
        if len(idx) >= cfg.enough_matches:
            break
    assert found is not None
    res, in_roi, idx, m2, sub = found
    counts.update(sub)
    if counts.get("matches", 0) == 0:
        return _fail(f"no features matched in the ROI: {res.reason}", grid, counts)
    if counts["in_roi"] < 3:
        return _fail(
            f"only {counts['in_roi']} features matched inside the ROI: no texture?", grid, counts
        )
    if len(idx) < cfg.min_matches:
        return _fail(
            f"{len(idx)} matches on the majority surface (< {cfg.min_matches})", grid, counts
        )
    xy_all, d_all, e_all = res.xy + shift, res.d, res.e + rows
    if radial is not None:
        d_all, e_all = correct_matches(radial, xy_all, d_all, e_all)
    xy = xy_all[idx]
    d, e, sd = d_all[idx], e_all[idx], res.sigma_d[idx]
    wt = None
    if wt_scale:
        # Tele points in the (possibly pre-scaled, coarse_gate) window: the fit finds what
        # remains, and the scale reported is the product.
        fit = fit_wt_scale(xy, xy - np.column_stack([d, e]), c_tele, sigma_px=res.sigma_e[idx])
        if fit.ok:
            d, e = fit.disparity(xy, xy - np.column_stack([d, e]))
            row = on_row(e, fit.rms_e_px)  # a row alias of a repetitive chart is no match
            counts["off_row"] = int((~row).sum())
            xy, d, e, sd, idx = xy[row], d[row], e[row], sd[row], idx[row]
        wt = replace(fit, scale=fit.scale * ch.scale, sigma_scale=fit.sigma_scale * ch.scale)
    if len(d) < cfg.min_matches:  # the others were row aliases (on_row)
        return _fail(f"{len(d)} matches on their rows (< {cfg.min_matches}), the rest row "
                     "aliases of a repetitive texture: aim at less regular texture", grid, counts)
    plane = fit_plane(xy, d, sd)
    if wt is not None and wt.ok:  # one band about the plane, once the W-T scale's spread is out
        split = band_split(xy_all, d_all, e_all, m2, fit, plane.predict, cfg)
        counts.update(split)
        why = band_reason(split, cfg)
        if why:
            return _fail(why, grid, counts)
    resid = d - plane.predict(xy)[0]
    good = np.abs(resid) <= max(4 * plane.scatter_px, 0.2)
    counts["plane"] = int(good.sum())
    return RoiMeasurement(
        True, "", xy[good], d[good], e[good], sd[good], in_roi[idx][good], m2, plane, wt, grid,
        counts,
    )


__all__ = [
    "PlaneFit",
    "RoiConfig",
    "RoiMeasurement",
    "fit_plane",
    "majority",
    "measure_roi",
    "reference_rectification",
    "roi_grid",
    "tele_center_px",
]
