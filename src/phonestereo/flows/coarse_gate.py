"""The coarse step's choice and gate (ROI disparity, thesis §4.1.3; issue #18).

The whole-box correlation (:func:`~phonestereo.flows.coarse.coarse_search`) of the first usable
coarse box gives the disparity the fine search starts from — or the reason the ROI cannot be
measured: no correlation, a peak at the end of the searched range, or two peaks the box does
not tell apart. "Never a confident wrong number": on a periodic texture (the verification
chessboard) a shift by one period correlates nearly as well as the true disparity, and the
fine matching then finds a tight, wrong plane around whichever peak the coarse step chose.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from phonestereo.flows.coarse import (
    CoarsePeak,
    PeakContrast,
    TileMaps,
    coarse_search,
    peak_contrast,
    rescale_tele,
    tile_wt_scale,
)
from phonestereo.flows.roi_config import RoiConfig
from phonestereo.flows.tele_roi_lazy import LazyPair
from phonestereo.flows.tele_roi_scale import coarse_reads, preimage, scaled_part

Box = tuple[int, int, int, int]


def coarse_verdict(
    lw: Any, rt: Any, cbox: tuple[int, int, int, int], cp: CoarsePeak, cfg: RoiConfig,
    maps: TileMaps | None = None,
) -> tuple[str, PeakContrast | None]:
    """Why the coarse peak of one box cannot be used ("" when it can), and the tile contrast
    of its two peaks when it was computed (``maps``: the tiles' maps of a wider search about
    the first peak, :func:`~phonestereo.flows.coarse.peak_contrast`'s ``reuse``)."""
    if not np.isfinite(cp.d) or cp.peak < cfg.coarse_min_zncc:
        return (
            f"the ROI does not correlate with the tele (ZNCC {cp.peak:.2f} < "
            f"{cfg.coarse_min_zncc}): no texture, occluded, or outside the tele's view"
        ), None
    if cp.at_end and cp.d > 0:
        return (
            f"the correlation is highest at the end of the searched disparities "
            f"({cp.d:.0f} px): the object is nearer than {cfg.z_min_m} m, or a repetitive "
            "texture; move back or aim at a distinct object"
        ), None
    if cp.at_end:
        return (
            f"the correlation is highest at the far end of the searched disparities "
            f"({cp.d:.0f} px, beyond infinity): the calibration's disparity is off by more "
            f"than {-cfg.far_disparity_px} px — recalibrate (or learn from faces), or a "
            "repetitive texture; aim at a distinct object"
        ), None
    if cp.second >= cfg.max_ambiguity * cp.peak:
        return (
            f"ambiguous disparity: two correlation peaks ({cp.peak:.3f}, {cp.second:.3f}) — a "
            "repetitive texture without context; enlarge the ROI or aim at a distinct object"
        ), None
    if not np.isfinite(cp.d2):
        return "", None
    # A periodic texture's alias peak is near the true one over the whole box by chance: the
    # first must beat it tile by tile (coarse.peak_contrast), not only in the sum — and so every
    # other alias within alias_ratio of it, any of which may be the truth.
    rivals = [(cp.d2, cp.e2, cp.second)]
    rivals += [o for o in cp.others if o[2] >= cfg.alias_ratio * cp.peak]
    first: PeakContrast | None = None
    for d2, e2, z2 in rivals:
        pc = peak_contrast(lw, rt, cbox, (cp.d, cp.e), (d2, e2), reuse=maps)
        first = first or pc
        if not pc.t >= cfg.min_peak_t:
            return (
                f"ambiguous disparity: the correlation peaks at {cp.d:.1f} px and {d2:.0f} px "
                f"(ZNCC {cp.peak:.3f}, {z2:.3f}) and the first wins only by chance over the "
                f"box's tiles (t = {pc.t:.1f} < {cfg.min_peak_t}) — a repetitive texture; "
                "enlarge the ROI over a distinct feature or aim at a distinct object"
            ), pc
    return "", first


@dataclass(frozen=True)
class CoarseChoice:
    """The coarse step's choice (:func:`coarse_peak`)."""

    #: (x, y, w, h). The coarse box used.
    box: Box
    peak: CoarsePeak
    #: The tile test of its two peaks, when there were two.
    contrast: PeakContrast | None
    #: Why the ROI cannot be measured ("" when it can).
    reason: str
    #: ndarray. The tele window the fine search must use: the input, or the input with the W-T scale
    #: the tiles showed corrected (``scale``).
    right: Any
    #: That pre-correction (1.0: none).
    scale: float = 1.0
    #: Median tile ZNCC at the first box's peak, when it was computed (NaN otherwise).
    tile_zncc: float = float("nan")

    def counts(self) -> dict[str, int]:
        """The choice's figures for a measurement's ``counts`` (ZNCCs ×1000, the tile test's t
        ×10, the pre-correction ×10⁴ when there was one)."""
        peak, pc, out = self.peak.peak, self.contrast, {}
        out["coarse_zncc_x1000"] = round(1000 * peak) if np.isfinite(peak) else 0
        if pc is not None and np.isfinite(pc.t):
            out["coarse_peak_t_x10"] = round(10 * max(min(pc.t, 999.0), -999.0))
        if np.isfinite(self.tile_zncc):
            out["coarse_tile_zncc_x1000"] = round(1000 * self.tile_zncc)
        if self.scale != 1.0:
            out["coarse_scale_x1e4"] = round(1e4 * self.scale)
        return out


def _first_usable(
    lw: Any, rt: Any, boxes: list[Box], d_max: int, cfg: RoiConfig,
    first: CoarsePeak | None = None,
    maps: TileMaps | None = None,
    before: Callable[[Box], None] | None = None,
) -> tuple[Box, CoarsePeak, PeakContrast | None, str]:
    """The first box whose coarse peak can be used (``first``: the first box's peak on this
    very pair, already searched; ``maps``: its tiles' maps about that peak; ``before``: called
    with each box before it is searched).

    When none can, the verdict returned is that of the first box that correlated (peak ≥
    ``coarse_min_zncc``) and failed a later test, if any, else the last box's: a larger box
    that reaches beyond what the tele sees does not correlate whatever the ROI holds, and its
    "does not correlate" would hide why the ROI itself cannot be measured (random-5008's ×5.9
    tele sees 335 px of the wide; the box inside its view read the chessboard's true peak 0.92
    and an alias 0.86, "ambiguous", while the 418- and 791-px boxes after it read 0.32 and 0.15
    and gave the capture's reason: "no texture, occluded, or outside the tele's view")."""
    told: tuple[Box, CoarsePeak, PeakContrast | None, str] | None = None
    for i, cbox in enumerate(boxes):
        if i == 0 and first is not None:
            cp = first
        else:
            if before is not None:
                before(cbox)
            cp = coarse_search(lw, rt, cbox, cfg.far_disparity_px, d_max, rows=cfg.coarse_rows)
        why, pc = coarse_verdict(lw, rt, cbox, cp, cfg, maps if i == 0 else None)
        if not why:
            return cbox, cp, pc, why
        if told is None and np.isfinite(cp.d) and cp.peak >= cfg.coarse_min_zncc:
            told = (cbox, cp, pc, why)
    return told if told is not None else (cbox, cp, pc, why)


def coarse_peak(
    lw: Any,
    rt: Any,
    boxes: list[Box],
    d_max: int,
    cfg: RoiConfig,
    center: tuple[float, float] | None = None,
    partial: bool = False,
    cover: LazyPair | None = None,
    on_prescale: Callable[[float], None] | None = None,
) -> CoarseChoice:
    """The first of ``boxes`` (context first, the ROI's own box last) whose coarse peak can be
    used — or the last box's with the reason it cannot.

    With ``center`` (the tele's rectified principal point in the window; None when the flow
    does not correct the W-T scale), the W-T scale the first box's tiles show
    (:func:`~phonestereo.flows.coarse.tile_wt_scale`) is corrected on the tele window first
    when the tiles correlate (median ≥ ``coarse_min_zncc``) and the scale moves the box's
    edges by more than ``coarse_max_scale_drift_px`` against its centre. An uncorrected scale
    decorrelates a large box although every part of it matches, and then the whole-box
    comparison of two peaks means nothing: random-1013's ×4.2 periscope (scale 3.7 %) had
    its box at 2.4 m correlate 0.55 (tiles 0.80) and the chessboard's alias one period away
    win over the true disparity; corrected, the true peak wins 0.96 to 0.83, and at 3.6-4 m
    the box correlates 0.95 instead of 0.22-0.30. If the corrected pair gives no usable peak
    the uncorrected one is tried too. Below that drift the uncorrected pair is tried first and,
    when no box of it can be used, the corrected one after it (a smaller scale still
    decorrelates a fine texture; a capture measured without it is measured as before).

    ``partial``: the corrected tele is computed only where the coarse step reads it (each
    box's strip as it is tried, :mod:`~phonestereo.flows.tele_roi_scale`, the same pixels),
    the rest of the returned ``right`` keeping the uncorrected ones — for a caller that
    resamples the fine part again (:func:`~phonestereo.flows.roi_window.fine_window`).
    ``cover``: ``lw`` and ``rt`` are its arrays, resampled where the first box is read; each
    other box's parts (and the tele the pre-scale reads) are resampled before it is tried.
    ``on_prescale``: called with the scale once the tele is to be pre-scaled, before the
    corrected pair is searched (``measure_roi`` starts the fine tele's resampling there:
    :class:`~phonestereo.flows.roi_window.FineAhead`).
    """
    assert boxes, "no coarse box"
    b0 = boxes[0]
    size = (rt.shape[1], rt.shape[0])
    if cover is not None:
        cover.cover_box(b0)
    tz, s = float("nan"), float("nan")
    p0: CoarsePeak | None = None
    maps: list[TileMaps] = []  # the tiles' ±8 px maps about p0: the tile test's first peak
    if center is not None:
        p0 = coarse_search(lw, rt, b0, cfg.far_disparity_px, d_max, rows=cfg.coarse_rows)
        if np.isfinite(p0.d):
            s, _, tz = tile_wt_scale(lw, rt, b0, p0.d, p0.e, center[1], keep=maps)
    drift = abs(s - 1.0) * 0.5 * max(b0[2], b0[3]) if np.isfinite(s) else 0.0
    scalable = center is not None and tz >= cfg.coarse_min_zncc and np.isfinite(s) and s != 1.0
    prescale = scalable and drift > cfg.coarse_max_scale_drift_px

    def scaled() -> tuple[CoarseChoice | None, str, float]:
        """The boxes on the tele window with the tiles' W-T scale corrected: the choice, or
        None, why not and the peak ZNCC of the box that said so."""
        assert center is not None
        if on_prescale is not None:
            on_prescale(s)
        fill = None
        if partial:
            rt_s = rt.copy()

            def fill(b: Box) -> None:
                x0, y0, x1, y1 = part = coarse_reads(b, cfg.far_disparity_px, d_max,
                                                     cfg.coarse_rows, size)
                if cover is not None:
                    cover.cover_box(b)
                    cover.cover_right(preimage(part, s, center, size))
                rt_s[y0:y1, x0:x1] = scaled_part(rt, s, center, part)
        else:
            rt_s = rescale_tele(rt, s, center)
        cbox, cp, pc, why = _first_usable(lw, rt_s, boxes, d_max, cfg, before=fill)
        if not why:
            return CoarseChoice(cbox, cp, pc, "", rt_s, s, tz), "", cp.peak
        return None, (f"{why} (with the W-T scale {s:.3f} that the ROI's tiles show "
                      "corrected)"), cp.peak

    why_s, peak_s = "", float("nan")
    if prescale:
        choice, why_s, peak_s = scaled()
        if choice is not None:
            return choice
    cbox, cp, pc, why = _first_usable(lw, rt, boxes, d_max, cfg, p0, maps[0] if maps else None,
                                      before=None if cover is None else cover.cover_box)
    if not why and prescale and cp.peak < peak_s and peak_s >= cfg.coarse_min_zncc:
        # The scale-corrected pair correlated better and could not choose (an alias as good
        # as the truth): the uncorrected pair's choice, made where the scale decorrelates the
        # box, is chance. random-3073's ×3.1 periscope (W-T scale 2.1 %) at 2.8 m: corrected,
        # the truth 0.970 against an alias 0.962 (ambiguous); uncorrected, an alias 82 px off
        # won 0.570 to 0.519 (tile t 3.5) and the chart read 0.47 m, 1598σ.
        return CoarseChoice(cbox, cp, pc, why_s, rt, tile_zncc=tz)
    if not why:
        return CoarseChoice(cbox, cp, pc, "", rt, tile_zncc=tz)
    if scalable and not prescale:
        # Below the drift that pre-scales first, a W-T scale still decorrelates a fine
        # periodic texture: random-5012's ×5.9 periscope (tele focused per stack, 20 mm,
        # calibrated at 0.6 m) shows 2.4–2.7 % at 2–4 m, 2.4 px at a 180-px box's edges, and
        # its chessboard's whole-box ZNCC fell from 0.93 at 0.9 m to 0.58 at 4 m (tiles 0.91),
        # the true peak no longer beating an alias. Tried only once the uncorrected pair has
        # failed, so a capture measured without it is measured as before.
        choice, why_s, _ = scaled()
        if choice is not None:
            return choice
        why_s = ""  # the uncorrected pair's reason stands
    if why_s:
        why = why_s
    elif np.isfinite(tz) and tz < cfg.coarse_min_zncc and "does not correlate" in why:
        why += (f"; nor do its parts (median tile ZNCC {tz:.2f}): the tele sees it too "
                "blurred or not at all — focus on the object or move closer")
    return CoarseChoice(cbox, cp, pc, why, rt, tile_zncc=tz)


__all__ = ["CoarseChoice", "coarse_peak", "coarse_verdict"]
