"""The coarse blocks before sub-pixel matching in an ROI (thesis §4.1.3, Fig. 4-2).

A whole-box correlation (cv2.matchTemplate) gives the coarse disparity and its ambiguity, and
blur equalisation evens out the two cameras' defocus before the windows are fitted.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np


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
        # The tele is the sharper one: leave the pair as it is here. The matcher equalises
        # that case itself (features/blur.py), with the blurred image's noise computed from
        # the kernel; blurring the right image here, with the noise then re-estimated from
        # the blurred image (read low), collapsed its sub-pixel stage (841 → 104 survivors
        # on a chart at 2 m).
        best = (best[0], 0.0, 0.0)
    _, s_l, s_r = best
    if s_l > 0:
        a = cv2.GaussianBlur(a, (0, 0), s_l)
    if s_r > 0:
        b = cv2.GaussianBlur(b, (0, 0), s_r)
    return a, b, s_l, s_r


__all__ = ["coarse_disparity", "equalise_blur"]
