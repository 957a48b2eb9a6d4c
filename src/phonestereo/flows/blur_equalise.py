"""Blur equalisation in an ROI (thesis §4.1.3, Fig. 4-2): after the coarse step, the sharper
image of the pair is blurred to the other's blur before the sub-pixel windows are fitted.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np

from phonestereo.features._threads import background, run_split
from phonestereo.flows.coarse import pixel_std, template_peak


def _residual_shift(tpl: Any, search: Any) -> tuple[float, float]:
    """Sub-pixel offset (dx, dy) of ``tpl`` in ``search`` relative to the centred position
    (``search`` is ``tpl`` plus r px on every side), |dx|, |dy| ≤ r."""
    r = (search.shape[0] - tpl.shape[0]) // 2
    _, fx, fy = template_peak(search, tpl)
    return fx - r, fy - r


#: Tile size, px: a W-T scale mismatch of 2 % moves a tile's ends by < 0.4 px against each other.
_TILE = 40
#: At most this many tiles: a larger box (a 12 MP ROI's: ~190) takes every k-th tile in x
#: and y, spread over the box (k = 2 there: 48 tiles of 40 × 40 px, ~77 000 pixels pooled per
#: candidate; the same blur chosen on the 12 MP bench set). At 48 the learning flow's face
#: boxes (60-96 tiles at 2000 × 1500) chose another blur on 1 of 15 captures; at 96 none.
_MAX_TILES = 96
#: Each tile's alignment search, ± px (the coarse disparity and row offset are whole pixels, the
#: scale mismatch adds up to ~3 px at a wide box's ends).
_ALIGN = 3


def _tile_starts(x0: int, x1: int, y0: int, y1: int) -> tuple[Any, Any]:
    """Tile origins along x and y of the region [x0, x1) × [y0, y1): every ``_TILE`` px, thinned
    by one factor k on both axes (evenly spread, both ends kept) when there are more than
    ``_MAX_TILES`` in all."""
    xs, ys = np.arange(x0, x1 - _TILE + 1, _TILE), np.arange(y0, y1 - _TILE + 1, _TILE)
    k = int(np.ceil(np.sqrt(len(xs) * len(ys) / _MAX_TILES)))
    if k > 1:
        xs, ys = (
            v[np.unique(np.round(np.linspace(0, len(v) - 1, -(-len(v) // k))).astype(int))]
            for v in (xs, ys)
        )
    return xs.tolist(), ys.tolist()


def _aligned_tiles(
    a: Any, b: Any, rect: tuple[int, int, int, int], shift: tuple[int, int], m: int
) -> list[tuple[Any, Any]]:
    """Tile pairs of the compared region, each right tile aligned to its left tile to sub-pixel.

    ``rect`` (x0, y0, x1, y1) is the left region, ``shift`` (xi, yi) the whole-pixel offset of
    the right one (right = left − shift). Each textured tile, with an ``m``-px border for the
    blur candidates, is aligned on its own (:func:`_residual_shift`, ±``_ALIGN`` px, then a
    Lanczos-4 sub-pixel shift as the rectification resamples): the tele's focus-dependent scale
    (1-2 % on a periscope) moves a whole box's ends by pixels, and a misaligned pair correlates
    better the more it is blurred.
    """
    x0, y0, x1, y1 = rect
    xi, yi = shift
    r, n = _ALIGN, _TILE + 2 * m
    pad = m + r
    xs, ys = _tile_starts(x0, x1, y0, y1)
    starts = [(tx, ty) for ty in ys for tx in xs]
    out: list[tuple[Any, Any] | None] = [None] * len(starts)

    def align(idx: Sequence[int]) -> None:  # tiles in order; OpenCV releases the GIL
        for i in idx:
            tx, ty = starts[i]
            ly, lx, ry, rx = ty - m, tx - m, ty - yi - pad, tx - xi - pad
            if min(ly, lx, ry, rx) < 0 or ly + n > a.shape[0] or lx + n > a.shape[1] or (
                    ry + n + 2 * r > b.shape[0] or rx + n + 2 * r > b.shape[1]):
                continue
            # float32 per tile (the same values as slicing a float32 copy of the image)
            ta = np.ascontiguousarray(a[ly : ly + n, lx : lx + n], dtype=np.float32)
            if pixel_std(ta[m:-m, m:-m]) < 1.0:  # flat: says nothing about blur
                continue
            tb = np.ascontiguousarray(b[ry : ry + n + 2 * r, rx : rx + n + 2 * r], np.float32)
            dx, dy = _residual_shift(ta[m:-m, m:-m], tb[m:-m, m:-m])
            # out(u, v) = tb(u + r + dx, v + r + dy): the tile's own offset taken out
            out[i] = (ta, _shifted(tb, r + dx, r + dy, n))

    run_split(align, range(len(starts)), min_items=8)
    return [p for p in out if p is not None]


def _lanczos4_taps(x: float) -> Any:
    """OpenCV's Lanczos-4 taps (imgwarp.cpp ``interpolateLanczos4``) at the fraction x of a
    pixel, float32 (8,): the sinc window in double, each tap rounded, normalised in float32."""
    if x < np.finfo(np.float32).eps:
        return np.eye(8, dtype=np.float32)[3]
    s45 = np.sqrt(0.5)
    cs = ((1, 0), (-s45, -s45), (0, 1), (s45, -s45), (-1, 0), (s45, s45), (0, -1), (-s45, s45))
    y0 = -(x + 3) * np.pi * 0.25
    s0, c0 = np.sin(y0), np.cos(y0)
    taps = np.zeros(8, np.float32)
    total = np.float32(0)
    for i, (a, b) in enumerate(cs):
        y = -(x + 3 - i) * np.pi * 0.25
        taps[i] = np.float32((a * s0 + b * c0) / (y * y))
        total = np.float32(total + taps[i])
    return taps * (np.float32(1) / total)


#: The 32 fractions (1/32 px) of OpenCV's interpolation tables, each row its 8 taps.
_LANCZOS4 = np.array([_lanczos4_taps(float(np.float32(k / 32))) for k in range(32)], np.float32)


def _shifted(tile: Any, sx: float, sy: float, n: int) -> Any:
    """out(u, v) = tile(u + sx, v + sy) for u, v < n by Lanczos-4, mirror border: what
    ``cv2.warpAffine`` with [[1, 0, sx], [0, 1, sy]] (WARP_INVERSE_MAP, INTER_LANCZOS4,
    BORDER_REFLECT) gives — the same 1/32-px fixed-point shift and taps — as one separable
    8 × 8 filter (cv2.sepFilter2D): ~3× faster on a 60-px tile, within 1e-6 relative (float32
    sums in another order)."""
    # warpAffine's coordinates: 10 fractional bits, rounded to its 5 (INTER_BITS)
    qx = (int(np.rint(float(np.float32(sx)) * 1024)) + 16) >> 5
    qy = (int(np.rint(float(np.float32(sy)) * 1024)) + 16) >> 5
    p = 8  # the mirror border for the taps' reach (3 before, 4 after) beyond the shift
    x0, y0 = p + (qx >> 5), p + (qy >> 5)
    h, w = tile.shape[:2]
    if min(x0, y0) < 3 or x0 + n + 4 > w + 2 * p or y0 + n + 4 > h + 2 * p:
        # farther than the tiles' ±(_ALIGN + ½) px alignment reaches: OpenCV itself
        m = np.array([[1, 0, sx], [0, 1, sy]], np.float32)
        return cv2.warpAffine(tile, m, (n, n), flags=cv2.INTER_LANCZOS4 | cv2.WARP_INVERSE_MAP,
                              borderMode=cv2.BORDER_REFLECT)
    padded = cv2.copyMakeBorder(tile, p, p, p, p, cv2.BORDER_REFLECT)
    out = cv2.sepFilter2D(padded, cv2.CV_32F, _LANCZOS4[qx & 31], _LANCZOS4[qy & 31],
                          anchor=(3, 3), borderType=cv2.BORDER_REFLECT)
    return out[y0 : y0 + n, x0 : x0 + n]


def equalise_blur(
    left: Any,
    right: Any,
    box: tuple[int, int, int, int],
    d0: float,
    e0: float = 0.0,
    sigmas: tuple[float, ...] = (0.0, 0.4, 0.7, 1.0, 1.4, 1.8, 2.4, 3.0),
    part: tuple[int, int, int, int] | None = None,
) -> tuple[Any, Any, float, float]:
    """Blur the sharper image of the pair so both have the same blur: (left, right, σ_l, σ_r).

    Defocus differs between the cameras away from the focus distance (f/1.8 wide vs f/2.8
    tele), and a blur mismatch makes every window misfit. The Gaussian σ (added to one image)
    that maximises the box's ZNCC is chosen; a symmetric blur does not move the correlation
    peak, so d is unbiased.

    The ZNCC is pooled over tiles of the box, each tile pair *aligned* first
    (:func:`_aligned_tiles`: the coarse disparity ``d0`` and row offset ``e0``, then each tile's
    own sub-pixel offset). A misaligned pair correlates better the more both are blurred: with
    the whole box compared at ``d0`` alone, a calibration 4 px off across the baseline and a
    tele 1.8 % smaller than calibrated (a periscope's heating, factory error and focus
    breathing) chose σ = 2.4-3 px on a wide image as sharp as the tele, and that blur let the
    windows slide along the chart's edges: ±0.7 px per-match errors against σ_d 0.07 px
    (random-1000, verification chart at 1.2-2.8 m).

    ``part`` (x0, y0, x1, y1): the only pixels the caller reads; the chosen blur is applied
    there (with the same values as on the whole image) and the rest is left unblurred.

    An image that is not blurred is returned as given (the matcher converts the part it reads
    to float32 itself); a blurred one as float32. Only the tiles are converted to float32 for
    the comparison (at 12 MP the whole window's two float32 copies cost more than the tiles).
    """
    x, y, w, h = box
    xi, yi = round(d0), round(e0)
    H, W = right.shape[:2]
    x0, x1 = max(x, xi), min(x + w, W + xi)
    y0, y1 = max(y, yi), min(y + h, H + yi)
    if x1 - x0 < 16 or y1 - y0 < 16:
        return left, right, 0.0, 0.0
    a, b = np.asarray(left), np.asarray(right)
    m = int(np.ceil(3 * max(sigmas))) + 1  # blur border: candidates see real pixels only
    pairs = _aligned_tiles(a, b, (x0, y0, x1, y1), (xi, yi), m)
    if not pairs:
        return left, right, 0.0, 0.0

    # The tiles side by side in one strip per image (each keeps its own m-px border), so that
    # each candidate is one cv2.GaussianBlur per image instead of one per tile.
    n = pairs[0][0].shape[0]
    strip_a = np.hstack([ta for ta, _ in pairs])
    strip_b = np.hstack([tb for _, tb in pairs])

    def inner(strip: Any) -> Any:
        t = strip.reshape(n, len(pairs), n)[m:-m, :, m:-m]  # (rows, tile, cols)
        return t - t.mean(axis=(0, 2), keepdims=True)

    def centred(strip: Any, sigma: float) -> tuple[Any, float]:
        """The strip's tiles blurred by ``sigma`` (none: 0), means removed, and Σp²."""
        p = inner(cv2.GaussianBlur(strip, (0, 0), sigma) if sigma > 0 else strip)
        return p, float(np.einsum("ijk,ijk->", p, p))

    # every candidate blurs one image: the other's unblurred tiles are computed once
    sharp = (centred(strip_a, 0.0), centred(strip_b, 0.0))

    def pooled(sl: float, sr: float) -> float:
        # ZNCC pooled over the tiles (each tile's mean removed): Σpq / √(Σp²·Σq²).
        pa, sp = centred(strip_a, sl) if sl > 0 else sharp[0]
        pb, sq = centred(strip_b, sr) if sr > 0 else sharp[1]
        num = float(np.einsum("ijk,ijk->", pa, pb))
        return num / np.sqrt(sp * sq + 1e-12)

    # The candidates (left blurred, right blurred) compared in the order of the loop they
    # replace (ties go to the earlier one). Along each side's ascending σ ladder the pooled
    # ZNCC rises to one peak and then falls (on all 245 calls of the bench sets, demo sets 0-7
    # and random sets 1000, 1003, 1007, 1011, 1013), so each ladder stops at its first fall
    # and the rest, lower still, is not blurred (the large kernels, most of the cost): the
    # left ladder here, the right on the helper.
    cands = [(0.0, 0.0)] + [c for s in sigmas[1:] for c in ((s, 0.0), (0.0, s))]
    s00 = pooled(0.0, 0.0)

    def ladder(side: int) -> list[float]:
        out, prev = [], s00
        for s in sigmas[1:]:
            v = pooled(s, 0.0) if side == 0 else pooled(0.0, s)
            out.append(v)
            if v < prev:
                break
            prev = v
        return out + [-np.inf] * (len(sigmas) - 1 - len(out))

    right = background(ladder, 1)
    left_scores = ladder(0)
    scores = [s00] + [v for pair in zip(left_scores, right.result(), strict=True) for v in pair]
    best = (scores[0], 0.0, 0.0)
    for i in range(1, len(cands), 2):
        best = max(best, (scores[i], *cands[i]), (scores[i + 1], *cands[i + 1]))
    if best[2] > 0:
        # The tele is the sharper one: leave the pair as it is here. The matcher equalises
        # that case itself (features/blur.py), with the blurred image's noise computed from
        # the kernel; blurring the right image here, with the noise then re-estimated from
        # the blurred image (read low), collapsed its sub-pixel stage (841 → 104 survivors
        # on a chart at 2 m).
        best = (best[0], 0.0, 0.0)
    _, s_l, s_r = best
    if s_l > 0:
        a = _blurred(a, s_l, part)
    if s_r > 0:
        b = _blurred(b, s_r, part)
    return a, b, s_l, s_r


def _blurred(img: Any, sigma: float, part: tuple[int, int, int, int] | None) -> Any:
    """``img`` as float32 blurred by ``sigma`` (cv2.GaussianBlur), or only inside ``part``:
    that box and the kernel's reach around it are blurred (OpenCV's float kernel reaches
    round(8σ + 1) // 2 ≤ 4σ + 1 px), so the pixels in ``part`` are the whole image's."""
    if part is None:
        return cv2.GaussianBlur(np.asarray(img, np.float32), (0, 0), sigma)
    x0, y0, x1, y1 = part
    r = int(np.ceil(4 * sigma)) + 1
    h, w = img.shape[:2]
    bx, by = max(x0 - r, 0), max(y0 - r, 0)
    src = np.asarray(img[by : min(y1 + r, h), bx : min(x1 + r, w)], np.float32)
    blurred = cv2.GaussianBlur(src, (0, 0), sigma)
    out = img.astype(np.float32)  # a new array: the caller's image is not written
    out[y0:y1, x0:x1] = blurred[y0 - by : y1 - by, x0 - bx : x1 - bx]
    return out


__all__ = ["equalise_blur"]
