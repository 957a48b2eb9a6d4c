"""The coarse blocks before sub-pixel matching in an ROI (thesis §4.1.3, Fig. 4-2).

A whole-box correlation (cv2.matchTemplate) gives the coarse disparity and its ambiguity; blur
equalisation (:mod:`~phonestereo.flows.blur_equalise`) then evens out the two cameras'
defocus before the windows are fitted.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from phonestereo.features._threads import run_split
from phonestereo.geometry.checks import Array

F64 = Array


@dataclass(frozen=True)
class CoarsePeak:
    """The whole-box correlation's answer (:func:`coarse_search`)."""

    #: ``d``, ``e``: Disparity of the highest peak (sub-pixel, parabola) and its whole-pixel row
    #: offset (NaN when the box cannot be correlated).
    d: float
    #: Its ZNCC.
    peak: float
    #: See ``d`` above.
    e: float
    #: The best *other* candidate: a local maximum more than 2 px away, or a lobe cut by an end of
    #: the searched range (−inf when none).
    second: float = float("-inf")
    #: ``d2``, ``e2``: Where that candidate is (whole pixels; NaN when none).
    d2: float = float("nan")
    #: See ``d2`` above.
    e2: float = float("nan")
    #: The highest peak lies at an end of the searched range: the correlation may still rise beyond
    #: it, so its disparity is not located.
    at_end: bool = False
    #: ((d, e, ZNCC), ...). The candidates after the second, highest first (at most 8): a periodic
    #: texture's aliases, of which the truth may be any (random-3014: 127 px first, 101 second,
    #: the truth 18 px fourth).
    others: tuple[tuple[float, float, float], ...] = ()


_NO_PEAK = CoarsePeak(float("nan"), float("nan"), float("nan"))


def _correlation_dtype(left: Any, right: Any) -> np.dtype[Any]:
    """The windows' type for cv2.matchTemplate: 8-bit pairs stay 8-bit, so OpenCV correlates
    in float32 (≤ 1e-4 off the float64 correlation of float32 input; ~1.5× faster for a 12 MP
    box); anything else float32."""
    return np.dtype(np.uint8 if left.dtype == right.dtype == np.uint8 else np.float32)


def pixel_std(img: Any) -> float:
    """The standard deviation of an image's pixels (cv2.meanStdDev: ~10× less overhead than
    NumPy's on a small tile)."""
    return float(cv2.meanStdDev(img)[1][0, 0])


def coarse_search(
    left: Any, right: Any, box: tuple[int, int, int, int], d_min: int, d_max: int, rows: int = 3
) -> CoarsePeak:
    """Whole-window ZNCC disparity of a rectified box (cv2.matchTemplate) with its competitor.

    The coarse step before sub-pixel matching: one large window (the expanded ROI) is far less
    ambiguous than 15-px windows on repetitive texture (a chessboard's period is within the
    disparity range), so the fine search can then be narrowed to a few pixels around it. Each
    shift takes its best row within ±``rows``. The competitor is the best other local maximum
    more than 2 px away (a broad main lobe is not ambiguity) — or an end of the range whose
    lobe the range cuts (an alias lobe whose top lies just outside is still a competitor).
    """
    x, y, w, h = box
    dtype = _correlation_dtype(left, right)
    tpl = np.ascontiguousarray(left[y : y + h, x : x + w], dtype=dtype)
    H, W = right.shape[:2]
    xs0, xs1 = max(0, x - d_max), min(W, x + w - d_min)
    ys0, ys1 = max(0, y - rows), min(H, y + h + rows)
    strip = np.ascontiguousarray(right[ys0:ys1, xs0:xs1], dtype=dtype)
    if strip.shape[0] < h or strip.shape[1] < w or pixel_std(tpl) < 1e-3:
        return _NO_PEAK
    score = cv2.matchTemplate(strip, tpl, cv2.TM_CCOEFF_NORMED)
    col = score.max(axis=0)  # best row per shift
    j = int(np.argmax(col))

    def d_e(k: int, sub: float = 0.0) -> tuple[float, float]:
        row = int(np.argmax(score[:, k])) + ys0  # the tele row of the box's top at shift k
        return float(x - (xs0 + k + sub)), float(y - row)

    peak = float(col[j])
    sub = 0.0
    if 0 < j < len(col) - 1:  # parabola through the peak: coarse only, ±0.5 px is enough
        den = col[j - 1] - 2 * col[j] + col[j + 1]
        sub = float(0.5 * (col[j - 1] - col[j + 1]) / den) if den < 0 else 0.0
    d, e = d_e(j, sub)
    # Candidates: interior local maxima and the range's ends when their lobe is cut there.
    pad = np.concatenate([[-np.inf], col, [-np.inf]])
    is_max = (pad[1:-1] >= pad[:-2]) & (pad[1:-1] >= pad[2:])
    idx = np.flatnonzero(is_max)
    idx = idx[np.abs(idx - j) > 2]
    at_end = len(col) > 1 and j in (0, len(col) - 1)
    if not idx.size:
        return CoarsePeak(d, peak, e, at_end=at_end)
    order = idx[np.argsort(-col[idx], kind="stable")]
    k = int(order[0])
    d2, e2 = d_e(k)
    others = tuple((*d_e(int(i)), float(col[i])) for i in order[1:9])
    return CoarsePeak(d, peak, e, float(col[k]), d2, e2, at_end, others)


def coarse_disparity(
    left: Any, right: Any, box: tuple[int, int, int, int], d_min: int, d_max: int, rows: int = 3
) -> tuple[float, float, float, float]:
    """:func:`coarse_search` as (d, peak ZNCC, second peak, e)."""
    p = coarse_search(left, right, box, d_min, d_max, rows)
    return p.d, p.peak, p.second, p.e


@dataclass(frozen=True)
class PeakContrast:
    """Whether the first coarse peak beats the second tile by tile (:func:`peak_contrast`)."""

    #: Paired t statistic of the tiles' ZNCC differences (first − second): their mean over its
    #: standard error (sd / √n), Student-t with n − 1 degrees of freedom when the peaks are equally
    #: good. NaN with too few tiles.
    t: float
    #: Tiles compared.
    n: int
    #: ``zncc_first``, ``zncc_second``: Median tile ZNCC at each peak (each tile at its best shift
    #: within ±``search_px``).
    zncc_first: float
    #: See ``zncc_first`` above.
    zncc_second: float
    #: Drift of the tiles' best disparity across x at the first peak, px per px (a W-T scale error
    #: of the uncorrected pair: 0.03 = the tele's scale is 3 % off).
    slope: float


@dataclass(frozen=True, eq=False)
class TileMaps:
    """The tiles' ZNCC maps of one :func:`_tile_scores` call, kept so that a narrower search
    about the same shift reads their centres instead of correlating the tiles again
    (:func:`peak_contrast` at the peak that :func:`tile_wt_scale` searched ±8 px about)."""

    left: Any
    right: Any
    box: tuple[int, int, int, int]
    d: float
    e: float
    n: int
    search_px: int
    #: Per tile: its (2·search_px + 1)² ZNCC map, None where it was not correlated.
    maps: list[Any]

    def serves(self, left: Any, right: Any, box: Any, d: float, e: float, n: int, r: int) -> bool:
        """Whether these maps hold the search ±r about (d, e) of the same pair and tiles."""
        return (left is self.left and right is self.right and tuple(box) == self.box
                and (d, e, n) == (self.d, self.e, self.n) and r <= self.search_px)


def _tile_scores(
    left: Any, right: Any, box: tuple[int, int, int, int], d: float, e: float, n: int,
    search_px: int, keep: list[TileMaps] | None = None, reuse: TileMaps | None = None,
) -> tuple[F64, F64, F64, F64, F64]:
    """Per tile of an n × n split of ``box``: best ZNCC within ±search_px of shift (d, e), its
    disparity and row offset (sub-pixel, parabola) and the tile's centre (x, y); NaN where the
    tile cannot be compared. (n² small windows: a loop over tiles, not pixels.)

    ``keep``: a list the tiles' maps are appended to (:class:`TileMaps`); ``reuse``: maps of a
    wider search about the same shift, whose centres stand for the tiles they hold (the same
    scores within ~1e-6: OpenCV's correlation rounds differently with the window's size)."""
    x, y, w, h = box
    tw, th = w // n, h // n
    r = search_px
    H, W = right.shape[:2]
    out = np.full((5, n * n), np.nan)
    dtype = _correlation_dtype(left, right)
    kept: list[Any] = [None] * (n * n)
    if reuse is not None and not reuse.serves(left, right, box, d, e, n, r):
        reuse = None

    def tiles(idx: Sequence[int]) -> None:  # half of them on the helper thread (OpenCV)
        for i in idx:
            tx, ty = x + (i % n) * tw, y + (i // n) * th
            sx, sy = round(tx - d) - r, round(ty - e) - r
            if reuse is not None and reuse.maps[i] is not None:
                k = reuse.search_px - r
                s = reuse.maps[i][k : k + 2 * r + 1, k : k + 2 * r + 1]
            else:
                tpl = np.ascontiguousarray(left[ty : ty + th, tx : tx + tw], dtype=dtype)
                if (sx < 0 or sy < 0 or sx + tw + 2 * r > W or sy + th + 2 * r > H
                        or pixel_std(tpl) < 1e-3):
                    continue
                win = np.ascontiguousarray(
                    right[sy : sy + th + 2 * r, sx : sx + tw + 2 * r], dtype
                )
                s = kept[i] = cv2.matchTemplate(win, tpl, cv2.TM_CCOEFF_NORMED)
            z, fx, fy = map_peak(s)
            out[:, i] = (z, tx - (sx + fx), ty - (sy + fy), tx + tw / 2, ty + th / 2)

    run_split(tiles, range(n * n), min_items=4)
    if keep is not None:
        keep.append(TileMaps(left, right, (x, y, w, h), d, e, n, r, kept))
    return out[0], out[1], out[2], out[3], out[4]


def template_peak(window: Any, template: Any) -> tuple[float, float, float]:
    """Best match of ``template`` inside ``window`` (cv2.matchTemplate, ZNCC): (score, x, y),
    the template's top-left in the window refined by a parabola per axis."""
    return map_peak(cv2.matchTemplate(window, template, cv2.TM_CCOEFF_NORMED))


def map_peak(s: Any) -> tuple[float, float, float]:
    """The highest value of a ZNCC map (rows, cols) and its position (x, y) there, refined by
    a parabola per axis (:func:`template_peak`)."""
    ky, kx = (int(v) for v in np.unravel_index(int(np.argmax(s)), s.shape))
    fx = kx + parabola_vertex(s[ky, max(kx - 1, 0) : kx + 2], kx)
    fy = ky + parabola_vertex(s[max(ky - 1, 0) : ky + 2, kx], ky)
    return float(s[ky, kx]), fx, fy


def parabola_vertex(v: Any, k: int) -> float:
    """Sub-pixel offset of a parabola's vertex through three samples (0 at an edge)."""
    if k == 0 or len(v) < 3:
        return 0.0
    den = float(v[0] - 2 * v[1] + v[2])
    if not den < 0:
        return 0.0
    # min/max, not np.clip (~3 µs per call on a scalar): the same value
    return float(min(max(0.5 * (v[0] - v[2]) / den, -0.5), 0.5))


def tile_wt_scale(
    left: Any,
    right: Any,
    box: tuple[int, int, int, int],
    d: float,
    e: float,
    center_y: float,
    tiles: int = 4,
    search_px: int = 8,
    keep: list[TileMaps] | None = None,
) -> tuple[float, int, float]:
    """The W-T scale the tiles' row offsets show about the tele's rectified centre row:
    (scale, tiles used, median tile ZNCC); scale NaN with fewer than 6 tiles. ``keep``: a list
    the tiles' ZNCC maps are appended to (:class:`TileMaps`, for :func:`peak_contrast`).

    A tele whose scale differs from the calibration's by s − 1 sees a wide row y at
    c_y + (y − c_y)/s (:class:`~phonestereo.fixes.wt_scale.WTScale`), so the row offset of a
    tile grows as (1 − 1/s)·(y − c_y) — whatever the depth (a slanted surface changes the
    disparity, not the rows). A 3.7 % scale (random-1013's periscope) moves the rows of a
    512-px box by ±9 px, enough to decorrelate it as a whole.

    Examples
    --------
    >>> import cv2
    >>> rng = np.random.default_rng(0)
    >>> a = cv2.GaussianBlur(rng.uniform(0, 255, (500, 400)).astype(np.float32), (0, 0), 3)
    >>> m = np.float32([[1 / 1.03, 0, 0], [0, 1 / 1.03, 250 * (1 - 1 / 1.03)]])
    >>> b = cv2.warpAffine(a, m, (400, 500))  # the tele: scaled 3 % about row 250
    >>> s, n, z = tile_wt_scale(a, b, (40, 40, 320, 420), 0.0, 0.0, 250.0)
    >>> bool(abs(s - 1.03) < 0.005), n, bool(z > 0.9)
    (True, 16, True)
    """
    z, _, ee, _, yy = _tile_scores(left, right, box, d, e, tiles, search_px, keep)
    zm = float(np.nanmedian(z)) if np.isfinite(z).any() else float("nan")
    ok = np.isfinite(z) & (z > 0.3)  # tiles that found their counterpart
    if ok.sum() < 6 or np.ptp(yy[ok]) <= 0:
        return float("nan"), int(ok.sum()), zm
    b = float(np.polyfit(yy[ok] - center_y, ee[ok], 1)[0])
    return 1.0 / (1.0 - b), int(ok.sum()), zm


def rescale_tele(
    right: Any, scale: float, center: tuple[float, float],
    box: tuple[int, int, int, int] | None = None,
) -> Any:
    """The rectified tele window scaled by ``scale`` about ``center`` (x, y): the pixel at q
    moves to center + scale·(q − center), the W-T scale's correction of
    :class:`~phonestereo.fixes.wt_scale.WTScale` applied to the image. With ``box``
    (x0, y0, x1, y1) only that part of the output is computed (the rest is ``right``'s)."""
    k = 1.0 / scale
    cx, cy = center
    x0, y0 = (0, 0) if box is None else box[:2]
    # output pixel (x0 + u, y0 + v) reads right at c + k·(x0 + u − c)
    m = np.array([[k, 0, cx * (1 - k) + k * x0], [0, k, cy * (1 - k) + k * y0]], np.float32)
    h, w = right.shape[:2]
    flags = cv2.WARP_INVERSE_MAP | cv2.INTER_CUBIC
    if box is None:
        return cv2.warpAffine(right, m, (w, h), flags=flags, borderMode=cv2.BORDER_CONSTANT)
    out = right.copy()
    out[y0 : box[3], x0 : box[2]] = cv2.warpAffine(
        right, m, (box[2] - x0, box[3] - y0), flags=flags, borderMode=cv2.BORDER_CONSTANT
    )
    return out


def peak_contrast(
    left: Any,
    right: Any,
    box: tuple[int, int, int, int],
    first: tuple[float, float],
    second: tuple[float, float],
    tiles: int = 4,
    search_px: int = 3,
    reuse: TileMaps | None = None,
) -> PeakContrast:
    """Does the first coarse peak beat the second everywhere, or only by chance?

    A periodic texture (a chessboard) correlates as well at a shift by its period as at the
    true disparity; only its few non-periodic parts (the chart's circles, its border) tell
    them apart. The whole-box ZNCC of the two peaks then differs by a few hundredths, less
    than what an uncorrected W-T scale, blur or noise changes (random-1013's ×4.2 periscope:
    the wrong peak won 0.553 to 0.528 and the capture read 0.37 m for 2.40 m). The box is split
    into ``tiles`` × ``tiles`` tiles; each is correlated at both peaks (its best shift within
    ±``search_px``, which absorbs a scale drift across the box) and the paired differences are
    tested: their mean over its standard error (a paired t test over the tiles). A distinct
    texture wins in every tile (t in the tens); a periodic one only where its non-periodic
    parts are (the folded-x3 demo's chart border: t 3.8-5.5 with 4 × 4 tiles); an alias wins
    by noise (|t| ≲ 2: random-1013, t 1.5). Two surfaces of similar area in the box also give
    a small t (large differences of both signs): the box is then ambiguous too, and
    :func:`~phonestereo.flows.coarse_gate.coarse_peak` tries the next, smaller box.

    Parameters
    ----------
    left, right : ndarray
        The rectified pair.
    box : (x, y, w, h)
        The coarse box in ``left``.
    first, second : (d, e)
        The two peaks (disparity, row offset), px.
    tiles : int
        Tiles per side.
    search_px : int
        Each tile's search either side of each peak, px.
    reuse : TileMaps, optional
        The tiles' maps of a wider search about ``first`` on the same pair and box
        (:func:`tile_wt_scale`'s): their centres are read instead of correlating again.

    Returns
    -------
    PeakContrast

    Examples
    --------
    >>> import cv2
    >>> rng = np.random.default_rng(0)
    >>> a = cv2.GaussianBlur(rng.uniform(0, 255, (240, 320)).astype(np.float32), (0, 0), 2)
    >>> b = np.roll(a, -10, axis=1)  # the tele sees it shifted by d = 10
    >>> pc = peak_contrast(a, b, (60, 40, 200, 160), (10.0, 0.0), (40.0, 0.0))
    >>> pc.t > 10 and pc.zncc_first > 0.99 and pc.n == 16
    True
    """
    z1, d1, _, x1, _ = _tile_scores(left, right, box, *first, tiles, search_px, reuse=reuse)
    z2 = _tile_scores(left, right, box, *second, tiles, search_px)[0]
    ok = np.isfinite(z1) & np.isfinite(z2)
    n = int(ok.sum())
    if n < 6:
        return PeakContrast(float("nan"), n, float("nan"), float("nan"), float("nan"))
    diff = z1[ok] - z2[ok]
    mean, sd = float(np.mean(diff)), float(np.std(diff, ddof=1))
    se = sd / np.sqrt(n)
    t = mean / se if se > 0 else float(np.copysign(np.inf, mean)) if mean != 0 else 0.0
    slope = float("nan")
    if np.ptp(x1[ok]) > 0:
        slope = float(np.polyfit(x1[ok], d1[ok], 1)[0])
    return PeakContrast(t, n, float(np.median(z1[ok])), float(np.median(z2[ok])), slope)


__all__ = [
    "CoarsePeak",
    "PeakContrast",
    "TileMaps",
    "coarse_disparity",
    "coarse_search",
    "map_peak",
    "parabola_vertex",
    "peak_contrast",
    "pixel_std",
    "rescale_tele",
    "template_peak",
    "tile_wt_scale",
]
