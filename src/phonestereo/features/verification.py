"""Verification-chart detection (thesis §1.2.2): circle pairs → labelled chessboard corners.

Stages (each in its own module):

1. **Circles** (:mod:`~phonestereo.features.circles`): the circle pairs, searched from the
   coarsest pyramid level down (finer levels only if the coarser ones give no chart).
2. **Lattice** (:mod:`~phonestereo.features.lattice`): Harris corners on the pyramid level where
   squares are ≥ ~12 px, moved onto their X-junctions (cv2.cornerSubPix), grown into a lattice
   from the square of an anchor circle, each node checked to be an X-junction of the expected
   colour parity.
3. **Labels** (:mod:`~phonestereo.features.labels`): the chart (row, col) of every node from the
   circles the lattice contains, checked against the whole chart layout; nodes off a smooth
   (homography + cubic) chart-to-image mapping are dropped.
4. **Sub-pixel**: :func:`~phonestereo.features.saddle.refine_saddle` on the full image, window
   0.32 of the local square size (2–8 px), pre-blur σ = min(1.5, radius / 3); 0.25 and
   radius / 4 next to a circle. Each refined corner must pass the crossing check again, now
   strictly (point symmetry: ≤ ~0.05 square off the junction), and lie within 0.15 px of the
   quadratic through its 5 × 5 neighbours (occluder edges, glare).

Because the labels come from the chart's own circles, a partly visible chart (the tele's view)
still gives correctly labelled corners, and wide ↔ tele matching is by id. Assumption: the
camera is rolled by less than ±45° relative to the chart (or relative to ``rotation_hint_deg``);
when the visible circles fix the orientation by themselves, the hint is not needed. A data
problem (no circles, too few corners, contradictions) is a result with ``found=False`` and a
reason, never a mislabelled corner set.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.charts.verification import VerificationChart
from phonestereo.errors import InputError
from phonestereo.features import labels as lb
from phonestereo.features._image import (
    F32,
    F64,
    as_gray_float,
    base_to_level,
    noise_sigma,
    pyramid,
)
from phonestereo.features.chart_detection import ChartDetection, failed_detection
from phonestereo.features.circles import Circles, find_circles
from phonestereo.features.lattice import (
    Lattice,
    crossing_check,
    grow,
    harris_candidates,
    seed_from_pair,
    square_size,
    subpix,
)
from phonestereo.features.noise_level import estimate_noise_level
from phonestereo.features.saddle import refine_saddle

__all__ = ["MIN_CORNERS", "ChartDetection", "detect_verification_chart"]

MIN_CORNERS = 12
_R_MAX = 8.0  # largest saddle-fit window radius, px
_LOCAL_PX = 0.15  # largest offset of a corner from its 5 × 5 neighbourhood's quadratic, px
_MAX_ANCHORS = 4  # circle pairs tried as lattice seeds per pyramid level
_MAX_LEVEL = 4


def _circle_levels(pyr: list[F32], sigma: float, stages: dict[str, Any]) -> Iterator[Circles]:
    """Circle pairs per pyramid level, coarsest first (only levels that have a pair)."""
    for level in range(len(pyr) - 1, -1, -1):
        c = find_circles(pyr[level], level, max(sigma / 2**level, 1e-3))
        stages.setdefault("circle_candidates", {})[level] = len(c.centers)
        if len(c.pairs):
            yield c


def _refine(
    img: F32, pts: F64, size_px: F64, near_circle: NDArray[np.bool_]
) -> tuple[F64, F64, NDArray[np.bool_], F64]:
    """refine_saddle with a window of 0.32 of the local square size (2–``_R_MAX`` px, 0.5 px
    steps) and pre-blur radius / 3 (≤ 1.5 px); next to a circle 0.25 and radius / 4, which
    keeps the blurred circle out of the fit (bias ≤ 0.03 px instead of ≤ 0.1 px on 12 px
    squares). The image is blurred once per σ, not once per call. Returns points, strength,
    ok and each corner's predicted σ (px per coordinate; a processed image's misfit is read per
    window size, since its white-noise equivalent depends on the window: 233 → 84 DN² from
    radius 4 to 7.5 on a phone-ISP render)."""
    frac = np.where(near_circle, 0.25, 0.32)
    radius = np.clip(np.round(frac * size_px * 2) / 2, 2.0, _R_MAX)
    blur = np.round(np.minimum(1.5, radius / np.where(near_circle, 4.0, 3.0)), 2)
    out, strength, sigma = pts.copy(), np.zeros(len(pts)), np.full(len(pts), np.nan)
    ok = np.zeros(len(pts), bool)
    noise = estimate_noise_level(img)  # of the unblurred image: each blur correlates it
    lo, hi = np.percentile(img[::4, ::4], [1, 99])
    min_strength = 2e-3 * max(float(hi - lo), 1e-12)  # refine_saddle's default, computed once
    for b in np.unique(blur):
        f = cv2.GaussianBlur(img, (0, 0), float(b))
        for r in np.unique(radius[blur == b]):
            m = (radius == r) & (blur == b)
            res = refine_saddle(
                f,
                pts[m],
                radius_px=float(r),
                blur_sigma_px=0.0,
                min_strength=min_strength,
                noise=noise,
                prefilter_sigma_px=float(b),
            )
            out[m], strength[m], ok[m], sigma[m] = (
                res.points,
                res.saddle_strength,
                res.ok,
                res.sigma_px,
            )
    return out, strength, ok, sigma


def _near_circle(chart: VerificationChart, ids: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Corners (row, col) that are a corner of a square holding a circle."""
    sq = np.concatenate([p.square_ids for p in chart.circle_pairs])  # (8, 2) row, col
    d = ids[:, None, :] - sq[None, :, :]  # corner (r, c) touches squares (r|r+1, c|c+1)
    return np.any(
        ((d[..., 0] == 0) | (d[..., 0] == -1)) & ((d[..., 1] == 0) | (d[..., 1] == -1)), axis=1
    )


def _lattice_for(
    pyr: list[F32], circles: Circles, pair: int, sigma: float, cache: dict[int, F64]
) -> Lattice:
    a, b = circles.pairs[pair]
    c1, c2 = circles.centers[a], circles.centers[b]
    cov = 0.5 * (circles.cov[a] + circles.cov[b])
    e1, e2, _ = seed_from_pair(c1, c2, cov)
    size0 = float(square_size(e1, e2))
    level = int(np.clip(np.floor(np.log2(max(size0, 1.0) / 12.0)), 0, len(pyr) - 1))
    k = 2.0**level
    l1, l2 = base_to_level(np.stack([c1, c2]), level)
    e1, e2, seed = seed_from_pair(l1, l2, cov / k**2)
    img = pyr[level]
    if level not in cache:
        cache[level] = harris_candidates(img, 3 if size0 / k < 14 else 5)
    parity = 1 if circles.dark[a] else 0  # the anchor square (0, 0) is white for a dark circle
    return grow(img, cache[level], seed, e1, e2, parity, max(sigma / k, 1e-3), level)


def detect_verification_chart(
    image: Any,
    chart: VerificationChart | None = None,
    *,
    roi: tuple[int, int, int, int] | None = None,
    rotation_hint_deg: float = 0.0,
) -> ChartDetection:
    """Find the verification chart's corners, labelled with their chart (row, col).

    Parameters
    ----------
    image : array_like, shape (H, W) or (H, W, 3)
        Grayscale (or BGR) image, any numeric type.
    chart : VerificationChart, optional
        The chart layout (default: 40 × 28 squares of 25 mm).
    roi : (x, y, w, h), optional
        Search only this pixel rectangle; points are still in full-image pixels.
    rotation_hint_deg : float
        Expected in-image angle of the chart's +u (column) axis, degrees from +x towards +y
        (90 for a camera rolled by −90°); the true angle must be within ±45° of it unless the
        visible circles fix the orientation.

    Returns
    -------
    ChartDetection
        ``found=False`` with a reason when no chart can be trusted (not an exception).

    Examples
    --------
    >>> from phonestereo.charts.export import raster
    >>> img = raster(VerificationChart(), 400.0)       # 10 px squares, seen head-on
    >>> det = detect_verification_chart(img)
    >>> det.found, len(det.ids), det.pairs_found
    (True, 1053, ('h_dark', 'v_light', 'v_dark', 'h_light'))
    """
    t0 = time.perf_counter()
    chart = VerificationChart() if chart is None else chart
    if not isinstance(chart, VerificationChart):
        raise InputError(f"chart must be a VerificationChart, got {type(chart).__name__}")
    full = as_gray_float(image)
    x0 = y0 = 0
    if roi is not None:
        x0, y0, w, h = (int(v) for v in roi)
        if w < 16 or h < 16 or x0 < 0 or y0 < 0 or x0 + w > full.shape[1] or y0 + h > full.shape[0]:
            raise InputError(f"roi {roi} must be (x, y, w, h) inside the {full.shape[::-1]} image")
        full = full[y0 : y0 + h, x0 : x0 + w]
    stages: dict[str, Any] = {}
    sec: dict[str, float] = {}
    sigma = max(noise_sigma(full), 1e-3 * float(np.ptp(full[::8, ::8])))
    pyr = pyramid(full, _MAX_LEVEL)
    stages["noise_sigma"] = round(sigma, 4)
    sec["prepare"] = time.perf_counter() - t0
    t = time.perf_counter()
    cache: dict[int, F64] = {}
    reason = "no circle pair of the verification chart found"
    for circles in _circle_levels(pyr, sigma, stages):
        stages["circle_pairs"] = len(circles.pairs)
        sec["circles"] = time.perf_counter() - t
        reason = "no chessboard lattice around the circle pairs"
        for p in range(min(len(circles.pairs), _MAX_ANCHORS)):
            lat = _lattice_for(pyr, circles, p, sigma, cache)
            stages["harris_candidates"] = lat.candidates
            stages["lattice_nodes"] = len(lat.ij)
            if len(lat.ij) < MIN_CORNERS:
                continue
            sq = lb.classify_squares(pyr[lat.level], lat.ij, lat.points)
            n_obs = int(np.count_nonzero(sq.code != lb.UNKNOWN))
            stages["squares"] = {"coded": n_obs, "circles": int(np.count_nonzero(sq.code == 1))}
            hyps = lb.hypotheses(chart, sq, lat.ij, lat.parity)
            ai = _anchor_index(lat)
            hyp, reason = lb.choose(hyps, n_obs, lat.e1[ai], lat.e2[ai], rotation_hint_deg)
            if hyp is None:
                continue
            sec["lattice"] = time.perf_counter() - t - sec["circles"]
            return _finish(pyr, chart, lat, sq, hyp, (x0, y0), stages, sec, t0)
    sec["total"] = time.perf_counter() - t0
    return failed_detection(reason, stages, sec)


def _anchor_index(lat: Lattice) -> int:
    """Index of the lattice node nearest to (0, 0) (the anchor square's corner)."""
    return int(np.argmin(np.abs(lat.ij).sum(axis=1)))


def _row_angle_deg(ids: NDArray[np.int64], pts: F64) -> float:
    """Angle of the summed vectors between row neighbours (col → col + 1), degrees.

    >>> _row_angle_deg(np.array([[0, 0], [0, 1], [1, 0]]), np.array([[0., 0.], [1., 1.], [0., 2.]]))
    45.0
    """
    key = ids[:, 0] * 100_000 + ids[:, 1]
    order = np.argsort(key)
    j = np.clip(np.searchsorted(key[order], key + 1), 0, len(key) - 1)
    has = key[order][j] == key + 1
    if not has.any():
        return float("nan")
    d = (pts[order[j[has]]] - pts[has]).sum(axis=0)
    return round(float(np.degrees(np.arctan2(d[1], d[0]))), 9)


def _finish(
    pyr: list[F32],
    chart: VerificationChart,
    lat: Lattice,
    sq: lb.Squares,
    h: lb.Hypothesis,
    origin: tuple[int, int],
    stages: dict[str, Any],
    sec: dict[str, float],
    t0: float,
) -> ChartDetection:
    t = time.perf_counter()
    ids = lb.corner_ids(h, lat.ij)
    k = 2.0**lat.level
    size0 = k * square_size(lat.e1, lat.e2)
    res = lb.smooth_residuals(ids, lat.points)
    bad = res > 0.2 * size0 / k
    stages["dropped_by_fit"] = int(np.count_nonzero(bad))
    if np.count_nonzero(bad) > 0.1 * len(bad):
        return failed_detection(
            f"{int(np.count_nonzero(bad))} of {len(bad)} corners do not follow a smooth "
            "chart-to-image mapping; the lattice is not trustworthy",
            stages,
            sec,
        )
    pts0 = lat.points
    for level in range(lat.level - 1, -1, -1):  # down the pyramid, onto each level's junction
        pts0 = subpix(pyr[level], 2.0 * pts0 + 0.5, size0 / 2.0**level)[0]
    pts, strength, ok, sigma = _refine(pyr[0], pts0, size0, _near_circle(chart, ids))
    shift = np.hypot(*(pts - pts0).T)
    ok &= ~bad & (shift > 0) & (shift < 0.3 * size0)  # 0: refine_saddle rejected its step
    stages["dropped_by_saddle"] = int(np.count_nonzero(~ok & ~bad))
    tl_dark = (lat.ij.sum(axis=1) + lat.parity) % 2 == 0
    sigma0 = float(stages["noise_sigma"])
    good, _ = crossing_check(pyr[0], pts, k * lat.e1, k * lat.e2, tl_dark, sigma0)
    stages["dropped_by_check"] = int(np.count_nonzero(ok & ~good))
    ok &= good
    # a corner pulled off its neighbours' smooth grid (occluder edge, glare)
    loc = lb.local_residuals(ids[ok], pts[ok])
    off = np.zeros(len(ok), bool)
    off[np.flatnonzero(ok)] = loc > np.maximum(_LOCAL_PX, 0.01 * size0[ok])
    resid = np.full(len(ok), np.nan)
    resid[np.flatnonzero(ok)] = loc
    stages["dropped_by_local_fit"] = int(np.count_nonzero(off))
    ok &= ~off
    sec["refine"] = time.perf_counter() - t
    order = np.lexsort((ids[ok, 1], ids[ok, 0]))
    ids, pts, strength = ids[ok][order], pts[ok][order], strength[ok][order]
    sigma = sigma[ok][order]
    resid = resid[ok][order]
    pts = pts + np.array(origin, dtype=np.float64)
    circ = sq.code == lb.CIRCLE
    centre0 = k * sq.centre[circ] + (k - 1.0) / 2.0 + np.array(origin, dtype=np.float64)
    seen = {
        (int(r), int(c)): x
        for (r, c), x in zip(lb.square_ids(h, sq.ij[circ]), centre0, strict=True)
    }
    circles = {
        p.name: np.array([seen[(int(r), int(c))] for r, c in p.square_ids])
        for p in chart.circle_pairs
        if all((int(r), int(c)) in seen for r, c in p.square_ids)
    }
    pairs = tuple(circles)
    rot = _row_angle_deg(ids, pts)
    stages["corners"] = len(ids)
    stages["pyramid_level"] = lat.level
    sec["total"] = time.perf_counter() - t0
    dropped = sum(v for k, v in stages.items() if k.startswith("dropped_by"))
    if len(ids) < MIN_CORNERS:
        return failed_detection(f"only {len(ids)} corners survived refinement", stages, sec)
    note = (
        f"{dropped} corner(s) dropped (not clean saddles or off the smooth fit)" if dropped else ""
    )
    return ChartDetection(
        True, note, ids, pts, strength, pairs, rot, stages, sec, circles, resid, sigma
    )
