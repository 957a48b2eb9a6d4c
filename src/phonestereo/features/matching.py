"""Sparse sub-pixel matching of a rectified wide/tele pair, with σ per match (thesis §1.2.1).

Stages (each counted in :attr:`MatchResult.counts`):

1. **keypoints** — DoG extrema with Hessian edge rejection (or SIFT) inside the ROI
   (:mod:`~phonestereo.features.keypoints`);
2. **search** — NCC of the window along the row band ± ``row_tolerance``, the peak's score,
   uniqueness, convexity and left–right consistency (:mod:`~phonestereo.features.search`);
3. **sub-pixel** — the sharper image is blurred to the other's blur when the NCC matches show a
   difference that would misfit the windows beyond the noise (:mod:`~phonestereo.features.blur`;
   a symmetric Gaussian does not move the peak); both images are filtered by [1, 2, 1] / 4 when
   both still carry a demosaicer's CFA phase, which would pull d toward even disparities
   (:mod:`~phonestereo.features.cfa`); then 2-D Lucas–Kanade (d, e, gain, offset,
   disparity gradient) on a cubic B-spline: no pixel locking
   (:mod:`~phonestereo.features.subpixel`); it must converge near the NCC peak, fit to within
   the noise and not be ill-conditioned. A pair whose misfit floor (below) says it is
   compression-limited (``MatchConfig.wide_floor``: JPEG q85 and worse, phone JPEGs) is fitted
   again with a wider window on both images prefiltered by a small Gaussian: the quantisation
   error is then the residual, and it averages down with the window's area;
4. **σ** — the Cramér–Rao covariance from the window's gradients and the image noise, raised to
   the window's residual misfit where it fits worse than noise (:mod:`~phonestereo.features.crlb`);
   windows fitting much worse than the pair's typical window (its misfit floor, measured on its
   own converged windows: compression, sharpening and denoising raise it,
   :mod:`~phonestereo.features.misfit`), or with σ_d above a bound, are dropped;
5. **global** — non-disparity error field, disparity histogram and neighbour support
   (:mod:`~phonestereo.features.match_filters`).

Conventions (docs/conventions.md): left = wide, right = tele, rectified with disparity along x;
``d = x_left − x_right``, ``e = y_left − y_right``; (x, y) are left pixels, (0, 0) the centre of
the top-left pixel.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError
from phonestereo.features import match_filters as gf
from phonestereo.features._threads import background
from phonestereo.features.blur import equalise_pair, relative_blur
from phonestereo.features.cfa import cfa_phase_contrast, suppress_cfa
from phonestereo.features.crlb import match_sigma, noise_sigma
from phonestereo.features.keypoints import detect_dog, detect_sift, dog_noise_gain
from phonestereo.features.match_config import MatchConfig, MatchResult
from phonestereo.features.match_fit import (
    NoiseModel,
    Windows,
    first_fit,
    fit_windows,
    scaled,
    wide_prefilter,
)
from phonestereo.features.match_input import as_image, check_pair, crop_box, parse_roi
from phonestereo.features.misfit import (
    correlation_factor,
    residual_correlation,
)
from phonestereo.features.search import SearchResult, ncc_search
from phonestereo.features.search_budget import REFILL_BUDGET, REFILL_LIMIT, refill_search
from phonestereo.features.subpixel import PREFILTER_MARGIN, bspline_coefficients

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
Mask = NDArray[np.bool_]

__all__ = ["MatchConfig", "MatchResult", "match_rectified"]


def _empty(
    counts: dict[str, int], noise: tuple[float, float], roi: Any, t0: float, why: str
) -> MatchResult:
    z = np.zeros(0)
    return MatchResult(
        np.zeros((0, 2)), z, z, z, z, z, z, counts, noise, tuple(roi), time.perf_counter() - t0, why
    )


def match_rectified(
    left: Any,
    right: Any,
    *,
    max_disparity: int,
    min_disparity: int = 0,
    roi: Any = None,
    config: MatchConfig | None = None,
) -> MatchResult:
    """Sparse sub-pixel matches of a rectified pair with Cramér–Rao σ per match.

    Parameters
    ----------
    left, right : array_like, shape (H, W) or (H, W, 3)
        Rectified wide (left) and tele (right) images, same size, disparity along +x
        (a scene point at x in the left image is at x − d in the right, d ≥ 0 in front).
    max_disparity, min_disparity : int
        Disparity search range, px (inclusive).
    roi : (x, y, w, h), optional
        Left-image region whose keypoints are matched (the search may leave it); default all.
    config : MatchConfig, optional

    Returns
    -------
    MatchResult
        Matches, their σ, the survivors of every stage and the time; ``reason`` says why
        there are none when the data give none.

    Raises
    ------
    InputError / ShapeError
        Unreadable, empty, non-finite or mismatched images, a bad disparity range, or an ROI
        not inside the image.

    Examples
    --------
    A random texture and a copy shifted 12.25 px to the left (exact Fourier shift):

    >>> rng = np.random.default_rng(1)
    >>> f = np.fft.fft2(rng.standard_normal((120, 160)))
    >>> fy, fx = np.fft.fftfreq(120)[:, None], np.fft.fftfreq(160)[None, :]
    >>> lp = np.exp(-2 * np.pi**2 * 1.5**2 * (fx**2 + fy**2))          # blur σ = 1.5 px
    >>> left = 128 + 600 * np.real(np.fft.ifft2(f * lp))
    >>> right = 128 + 600 * np.real(np.fft.ifft2(f * lp * np.exp(2j * np.pi * fx * 12.25)))
    >>> res = match_rectified(left, right, max_disparity=24, config=MatchConfig(noise_sigma=0.5))
    >>> len(res) > 50, round(float(np.median(res.d)), 2), round(float(np.median(res.e)), 2)
    (True, 12.25, 0.0)
    """
    t0 = time.perf_counter()
    cfg = config if config is not None else MatchConfig()
    lf, rt = as_image(left, "left"), as_image(right, "right")
    check_pair(lf, rt, cfg.radius + cfg.row_tolerance + 4)
    dmin, dmax = int(min_disparity), int(max_disparity)
    if dmin != min_disparity or dmax != max_disparity or dmax <= dmin:
        raise InputError(
            f"disparity range must be integers with max_disparity > min_disparity, got "
            f"[{min_disparity}, {max_disparity}]"
        )
    h, w = lf.shape
    roi_t = parse_roi(roi, (w, h))
    rx, ry, rw, rh = roi_t
    r, ty = int(cfg.radius), int(cfg.row_tolerance)
    guard = r + ty + 3  # keypoint windows, search rows and the sub-pixel slack stay in the image
    ox, oy, cx1, cy1 = crop_box(roi_t, (w, h), dmin, dmax, guard + PREFILTER_MARGIN)
    lc = np.ascontiguousarray(lf[oy:cy1, ox:cx1], dtype=np.float32)
    rc = np.ascontiguousarray(rt[oy:cy1, ox:cx1], dtype=np.float32)
    # the right image's noise and spline prefilter on the other core while the left's
    # keypoints are found (the prefilter is dropped if blur equalisation changes the image)
    right_prep = background(_right_preparation, rc, cfg.noise_sigma is None)
    given = cfg.noise_sigma
    noise_l = float(given) if given is not None else noise_sigma(lc)
    box = (
        max(rx, guard) - ox,
        max(ry, guard) - oy,
        min(rx + rw, w - guard) - ox,
        min(ry + rh, h - guard) - oy,
    )
    xy, resp = _keypoints(lc, box, noise_l, cfg)
    noise = (noise_l, noise_l if given is not None else right_prep.result()[0])
    counts = {"keypoints": len(xy)}
    if not len(xy):
        why = "no keypoints: the ROI has no texture above the noise"
        if box[2] <= box[0] or box[3] <= box[1]:
            why = f"no keypoints: the ROI is within {guard} px of the border (window + band)"
        return _empty(counts, noise, roi_t, t0, why)
    def search(sel: NDArray[np.int64]) -> SearchResult:
        return ncc_search(
            lc,
            rc,
            xy[sel],
            radius=r,
            min_d=dmin,
            max_d=dmax,
            row_tolerance=ty,
            lr_tolerance=cfg.lr_tolerance,
            lr_min_score=cfg.min_score if cfg.lr_check else np.inf,
            lr_uniqueness=cfg.uniqueness,
        )

    if cfg.detector == "dog":  # windows that fail the search free their place for the next
        searched, s, passed = refill_search(
            search,
            lambda res: _search_tests(res, cfg, {}),
            len(xy),
            first=cfg.max_keypoints,
            budget=round(REFILL_BUDGET * cfg.max_keypoints),
            limit=round(REFILL_LIMIT * cfg.max_keypoints),
        )
        counts["keypoints"] = len(searched)  # the first max_keypoints and the refills
        refilled = max(len(searched) - cfg.max_keypoints, 0)
        xy, resp = xy[searched], resp[searched]
        _search_tests(s, cfg, counts)
        order = np.argsort(-resp, kind="stable")  # strongest first, as without refilling
        idx = order[passed[order]]
        counts["left_right"] = len(idx)
    else:
        s, refilled = search(np.arange(len(xy))), 0
        idx = np.flatnonzero(_search_tests(s, cfg, counts))
    if not len(idx):
        return _empty(counts, noise, roi_t, t0, "no keypoint passed the NCC search tests")
    added, shift_noise, noise_in = (0.0, 0.0), noise, noise
    if cfg.equalise_blur:  # after the search: its windows tell the pair's relative blur
        est = relative_blur(lc, rc, xy[idx], s.d0[idx], s.e0[idx], noise)
        eq = equalise_pair(lc, rc, est, noise, min_misfit=cfg.min_blur_misfit)
        lc, rc, added, noise, shift_noise = eq.left, eq.right, eq.added, eq.noise, eq.shift_noise
    cfa = cfg.cfa_filter and all(cfa_phase_contrast(im) >= cfg.min_cfa for im in (lc, rc))
    if cfa:  # both on their sensor grids: the CFA carriers would pull d to even values
        lc, rc, pf, sf = suppress_cfa(lc, rc, noise)
        noise, noise_in = (noise[0] * pf, noise[1] * pf), (noise_in[0] * pf, noise_in[1] * pf)
        shift_noise = (shift_noise[0] * sf[0], shift_noise[1] * sf[1])
    coef = right_prep.result()[1] if added[1] == 0 and not cfa else bspline_coefficients(rc)
    models = NoiseModel(noise, noise_in, shift_noise)
    corr = cfg.correlated_misfit
    fit, wide = first_fit(Windows(lc, coef, xy[idx], s.d0[idx], s.e0[idx], r, cfg.sigma_w),
                          models, cfg, corr)
    if wide:  # compression-limited: a larger window, the quantiser's high frequencies damped
        l_wide, gain, coef_wide, (rl, rr) = wide_prefilter(lc, rc, noise, cfg.wide_prefilter_px)
        r = int(cfg.wide_radius)
        hh, ww = lc.shape
        p = xy[idx]
        idx = idx[(p[:, 0] >= r) & (p[:, 1] >= r) & (p[:, 0] < ww - r) & (p[:, 1] < hh - r)]
        # the shift sees the prefiltered noise as white noise of variance ρ·σ² (ρ from the
        # images' own gradient spectra, features/cfa.py), more than the per-pixel Σk² says
        shift_wide = (shift_noise[0] * rl**0.5, shift_noise[1] * rr**0.5)
        models = NoiseModel(scaled(noise, gain), scaled(noise_in, gain), shift_wide)
        # the quantiser's residual is correlated over its blocks and the prefilter: σ_d from
        # its pooled autocorrelation, not as if the 23 × 23 pixels were independent (not after
        # a blur equalisation, whose even misfit the autocorrelation would read as noise)
        corr = corr or (cfg.wide_correlated and added == (0.0, 0.0))
        wide_windows = Windows(
            l_wide, coef_wide, xy[idx], s.d0[idx], s.e0[idx], r,
            cfg.wide_sigma_w,
        )
        fit = fit_windows(wide_windows, models, cfg, corr)
    ref, ok, floor, nbound = fit.ref, fit.ok.copy(), fit.floor, fit.nbound
    noise, shift_noise, noise_var = fit.noise, fit.shift_noise, fit.noise_var
    counts["subpixel"] = int(ok.sum())
    with np.errstate(invalid="ignore"):
        ok &= ref.residual_var <= nbound * ref.template_std**2
        ok &= ref.residual_var <= cfg.max_residual_ratio**2 * floor * noise_var
        counts["residual"] = int(ok.sum())
    fd = fe = None
    if corr and ref.residual is not None and ref.influence is not None:
        rho = residual_correlation(ref.residual[ok], 2 * r + 1)
        fd = correlation_factor(ref.influence[:, 0], rho)
        fe = correlation_factor(ref.influence[:, 1], rho)
    sd, se, _ = match_sigma(
        ref.cov_unit,
        ref.residual_var,
        ref.gain,
        *shift_noise,
        use_residual=cfg.residual_sigma,
        factor_d=fd,
        factor_e=fe,
    )
    with np.errstate(invalid="ignore"):
        ok &= sd <= cfg.max_sigma_d
    counts["sigma"] = int(ok.sum())
    sel = np.flatnonzero(ok)
    pts = xy[idx[sel]].astype(np.float64)
    g = _global_filters(pts, ref.d[sel], ref.e[sel], cfg, counts)
    sel, pts = sel[g], pts[g]
    why = "" if len(sel) else "no match survived the sub-pixel fit and the global filters"
    return MatchResult(
        xy=pts + np.array([ox, oy], np.float64),
        d=ref.d[sel],
        e=ref.e[sel],
        sigma_d=sd[sel],
        sigma_e=se[sel],
        score=s.score[idx[sel]],
        zncc=ref.zncc[sel],
        counts=counts,
        noise_sigma=noise,
        roi=roi_t,
        seconds=time.perf_counter() - t0,
        reason=why,
        blur_added=added,
        cfa_filtered=bool(cfa),
        radius=r,
        refilled=refilled,
    )


def _right_preparation(right: F32, with_noise: bool) -> tuple[float, F32]:
    """The right image's noise σ (NaN unless ``with_noise``) and its B-spline coefficients."""
    noise = noise_sigma(right) if with_noise else float("nan")
    return noise, bspline_coefficients(right)


def _keypoints(
    image: NDArray[np.float32], box: tuple[int, ...], noise: float, cfg: MatchConfig
) -> tuple[NDArray[np.int64], F64]:
    """Integer keypoints (N, 2) inside ``box`` = (x0, y0, x1, y1) of the working crop and their
    responses. DoG: up to :data:`~.search_budget.REFILL_LIMIT` × ``max_keypoints`` candidates in
    the detector's priority order, whose first ``max_keypoints`` are those it picks for that cap
    (the search refills from the rest, :mod:`~.search_budget`)."""
    x0, y0, x1, y1 = box
    if cfg.detector == "sift":
        kp = detect_sift(image, mask_box=(x0, y0, x1, y1), max_keypoints=cfg.max_keypoints)
    else:
        kp = detect_dog(
            image,
            mask_box=(x0, y0, x1, y1),
            sigma=cfg.dog_sigma,
            k=cfg.dog_k,
            threshold=max(cfg.contrast * dog_noise_gain(cfg.dog_sigma, cfg.dog_k) * noise, 0.2),
            edge_ratio=cfg.edge_ratio,
            max_keypoints=round(REFILL_LIMIT * cfg.max_keypoints),
            priority=True,
        )
    return kp.xy.astype(np.int64), kp.response


def _search_tests(s: SearchResult, cfg: MatchConfig, counts: dict[str, int]) -> Mask:
    """NCC peak tests of §1.2.1: score, uniqueness, convexity, left–right (counted)."""
    keep = s.searched & ~s.at_edge
    counts["searched"] = int(keep.sum())
    with np.errstate(invalid="ignore"):
        keep &= s.score >= cfg.min_score
        counts["score"] = int(keep.sum())
        keep &= s.second < cfg.uniqueness * s.score
        counts["unique"] = int(keep.sum())
        keep &= s.curvature_x >= cfg.min_curvature
        if cfg.row_tolerance > 0:
            keep &= s.curvature_y >= cfg.min_curvature
    counts["convex"] = int(keep.sum())
    if cfg.lr_check:
        keep &= s.lr_ok
    counts["left_right"] = int(keep.sum())
    return keep


def _global_filters(pts: F64, d: F64, e: F64, cfg: MatchConfig, counts: dict[str, int]) -> Mask:
    """Row-error field, disparity histogram and neighbour support, in that order (counted)."""
    g = gf.row_error_filter(pts, e, floor_px=cfg.e_floor_px, k_mad=cfg.e_k_mad)
    counts["row_error"] = int(g.sum())
    if g.any():
        sub = np.flatnonzero(g)
        hist = gf.histogram_filter(d[sub], bin_px=cfg.hist_bin_px, min_count=cfg.hist_min_count)
        g[sub[~hist]] = False
    counts["histogram"] = int(g.sum())
    if cfg.min_support > 0 and g.any():
        sub = np.flatnonzero(g)
        sup = gf.support_filter(
            pts[sub],
            d[sub],
            k=cfg.support_k,
            tol_px=cfg.support_tol_px,
            min_support=cfg.min_support,
        )
        g[sub[~sup]] = False
    counts["support"] = counts["matches"] = int(g.sum())
    return g
