"""The coarse step's choice and gate (ROI disparity, thesis §4.1.3; issue #18).

The whole-box correlation (:func:`~phonestereo.flows.coarse.coarse_search`) of the first usable
coarse box gives the disparity the fine search starts from — or the reason the ROI cannot be
measured: no correlation, a peak at the end of the searched range, or two peaks the box does
not tell apart. "Never a confident wrong number": on a periodic texture (the verification
chessboard) a shift by one period correlates nearly as well as the true disparity, and the
fine matching then finds a tight, wrong plane around whichever peak the coarse step chose.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from phonestereo.flows.coarse import CoarsePeak, PeakContrast, coarse_search, peak_contrast
from phonestereo.flows.roi_config import RoiConfig

Box = tuple[int, int, int, int]


def coarse_verdict(
    lw: Any, rt: Any, cbox: tuple[int, int, int, int], cp: CoarsePeak, cfg: RoiConfig
) -> tuple[str, PeakContrast | None]:
    """Why the coarse peak of one box cannot be used ("" when it can), and the tile contrast
    of its two peaks when it was computed."""
    if not np.isfinite(cp.d) or cp.peak < cfg.coarse_min_zncc:
        return (
            f"the ROI does not correlate with the tele (ZNCC {cp.peak:.2f} < "
            f"{cfg.coarse_min_zncc}): no texture, occluded, or outside the tele's view"
        ), None
    if cp.at_end:
        return (
            f"the correlation is highest at the end of the searched disparities "
            f"({cp.d:.0f} px): the object is nearer than {cfg.z_min_m} m, or a repetitive "
            "texture; aim at a distinct object"
        ), None
    if cp.second >= cfg.max_ambiguity * cp.peak:
        return (
            f"ambiguous disparity: two correlation peaks ({cp.peak:.3f}, {cp.second:.3f}) — a "
            "repetitive texture without context; enlarge the ROI or aim at a distinct object"
        ), None
    if not np.isfinite(cp.d2):
        return "", None
    # A periodic texture's alias peak is near the true one over the whole box by chance: the
    # first must beat it tile by tile (coarse.peak_contrast), not only in the sum.
    pc = peak_contrast(lw, rt, cbox, (cp.d, cp.e), (cp.d2, cp.e2))
    if not pc.t >= cfg.min_peak_t:
        return (
            f"ambiguous disparity: the correlation peaks at {cp.d:.1f} px and {cp.d2:.0f} px "
            f"(ZNCC {cp.peak:.3f}, {cp.second:.3f}) and the first wins only by chance over the "
            f"box's tiles (t = {pc.t:.1f} < {cfg.min_peak_t}) — a repetitive texture; enlarge "
            "the ROI over a distinct feature or aim at a distinct object"
        ), pc
    return "", pc


def coarse_peak(
    lw: Any, rt: Any, boxes: list[Box], d_max: int, cfg: RoiConfig
) -> tuple[Box, CoarsePeak, PeakContrast | None, str]:
    """The first of ``boxes`` (context first, the ROI's own box last) whose coarse peak can be
    used: (box, peak, tile contrast, "") — or the last box's with the reason it cannot."""
    assert boxes, "no coarse box"
    for cbox in boxes:
        cp = coarse_search(lw, rt, cbox, -2, d_max, rows=cfg.coarse_rows)
        why, pc = coarse_verdict(lw, rt, cbox, cp, cfg)
        if not why:
            break
    return cbox, cp, pc, why


__all__ = ["coarse_peak", "coarse_verdict"]
