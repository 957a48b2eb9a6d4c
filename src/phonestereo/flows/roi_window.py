"""The ROI window's two resamplings (:func:`~phonestereo.flows.roi_disparity.measure_roi`).

The coarse step (whole-pixel peaks and tile comparisons over the 3× ROI context) reads the
window resampled by OpenCV's cubic; the fine matcher's part of it — its crop for the coarse
disparity ± ``fine_range_px`` plus a guard — is resampled again with the rectification's
default (Lanczos-4, :data:`~phonestereo.rectification.maps.DEFAULT_INTERPOLATION`), so every
pixel the matcher and the blur equalisation read is the one a whole-window Lanczos-4 remap
gives (issue #18: the window remap was ~35 % of ``measure_roi`` at 12 MP). The left's part
about the box, which no coarse disparity changes (:func:`fine_core`), is resampled on the helper
thread while the coarse step's whole-box correlation keeps this one busy.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any

import numpy as np

from phonestereo.features._threads import background, run_split
from phonestereo.features.subpixel import PREFILTER_MARGIN
from phonestereo.flows.roi_config import RoiConfig
from phonestereo.flows.tele_roi_lazy import LazyPair
from phonestereo.flows.tele_roi_scale import preimage, scale_matrix, warp_part
from phonestereo.rectification.maps import DEFAULT_INTERPOLATION, Source

__all__ = [
    "COARSE_INTERPOLATION",
    "MAX_FINE_SHARE",
    "Ahead",
    "FineAhead",
    "coarse_lazy",
    "coarse_window",
    "fine_core",
    "fine_part",
    "fine_window",
    "remap_pair",
    "two_passes",
]


#: The coarse step's window resampling: it locates whole-pixel peaks and compares tiles.
#: OpenCV's cubic is ~3× faster than Lanczos-4 and moves the coarse ZNCCs and the tile test's t
#: by ≤ 0.003 and ≤ 1 % on the bench sets (bilinear, ~10× faster: +0.02 and −4 %).
COARSE_INTERPOLATION = "cubic"
#: Px beyond the matcher's crop resampled for it: the blur equalisation's Gaussian (σ ≤ 3,
#: OpenCV's kernel reaches 12 px) must see the fine pixels only.
_FINE_GUARD_PX = 16


def remap_pair(
    sources: tuple[Source, Source], interpolation: str, boxes: tuple[Any, Any] = (None, None)
) -> tuple[Any, Any]:
    """Both images of the window (or the parts ``boxes``), the tele's on the helper thread."""
    tele = background(sources[1].remap, interpolation, boxes[1])
    return sources[0].remap(interpolation, boxes[0]), tele.result()


#: Two passes only when the fine part's bound is at most this share of the window (the
#: application's 3× context: ~0.35); else one Lanczos-4 pass serves both steps (the learning
#: flow's face box, ``coarse_expand`` 1, is nearly the whole window).
MAX_FINE_SHARE = 0.6


def _fine_part(
    box: tuple[int, int, int, int], lo_d: int, hi_d: int, e0: float, cfg: RoiConfig,
    size: tuple[int, int],
) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) of the window the matcher's crop reaches for disparities
    lo_d … hi_d (crop_box of the box, its row band and spline margin, + _FINE_GUARD_PX)."""
    mcfg = cfg.match
    ty = max(int(mcfg.row_tolerance), int(abs(e0)) + 2)
    reach = int(mcfg.radius) + ty + 3 + PREFILTER_MARGIN + _FINE_GUARD_PX
    x, y, w, h = box
    W, H = size
    x0, x1 = max(min(x, x - hi_d) - reach, 0), min(max(x + w, x + w - lo_d) + reach, W)
    return x0, max(y - reach, 0), x1, min(y + h + reach, H)


def fine_part(
    box: tuple[int, int, int, int], d0: float, e0: float, cfg: RoiConfig, size: tuple[int, int]
) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) of the window :func:`fine_window` resamples again for the coarse
    disparity ``d0`` and row offset ``e0``: what the fine matcher reads, plus a guard."""
    lo_d = int(np.floor(d0)) - cfg.fine_range_px
    hi_d = int(np.ceil(d0)) + cfg.fine_range_px
    return _fine_part(box, lo_d, hi_d, e0, cfg, size)


@dataclass(frozen=True)
class Ahead:
    """A part of a window resampled ahead by the default interpolation (:func:`fine_core`)."""

    #: (x0, y0, x1, y1) of the window (of the tele before its W-T pre-scale).
    part: tuple[int, int, int, int]
    #: Its pixels, pending on the helper thread.
    pixels: Future[Any]
    #: The W-T pre-scale the part was chosen for (1.0: none).
    scale: float = 1.0


def fine_core(
    source: Source, box: tuple[int, int, int, int], cfg: RoiConfig, size: tuple[int, int],
    scale: float = 1.0, center: tuple[float, float] | None = None,
) -> Ahead:
    """The part that every :func:`fine_part` of ``box`` contains, whatever the coarse
    disparity and row offset (the box and the matcher's reach about it for d = 0 and the
    least row band; with ``scale`` and ``center``, what the tele's pre-scale of it reads),
    resampled by the default interpolation on the helper thread.

    ``measure_roi`` starts the left's before the coarse step and the tele's when the coarse
    step pre-scales it: its whole-box correlations (``cv2.matchTemplate``, one thread) leave
    the helper idle. :func:`fine_window` then resamples only the bands the coarse disparity
    adds (~5 % of the part at 12 MP). The pixels are the whole part's: ``cv2.remap`` treats
    every output pixel on its own."""
    core = _fine_part(box, 0, 0, 0.0, cfg, size)
    if scale != 1.0 and center is not None:
        core = preimage(core, scale, center, size)
    return Ahead(core, background(_one_core, source, core), scale)


#: Output pixels per ``cv2.remap`` call of :func:`_one_core`: OpenCV splits a call among its
#: own threads from 1.5 × 2¹⁶ pixels; below that it runs on the calling thread alone.
_SERIAL_PX = 1 << 16


def _one_core(source: Source, part: tuple[int, int, int, int]) -> Any:
    """``source.remap`` of ``part`` by the default interpolation in row bands small enough that
    OpenCV does not hand them to its own threads: the helper then takes one core, not the one
    the coarse step's correlation runs on (the same pixels)."""
    x0, y0, x1, y1 = part
    rows = max(_SERIAL_PX // max(x1 - x0, 1), 1)
    bands = [source.remap(DEFAULT_INTERPOLATION, (x0, y, x1, min(y + rows, y1)))
             for y in range(y0, y1, rows)] or [source.remap(DEFAULT_INTERPOLATION, part)]
    return np.concatenate(bands) if len(bands) > 1 else bands[0]


class FineAhead:
    """The fine parts of ``box`` resampled ahead (:func:`fine_core`) on the helper thread:
    the left's at once, the tele's when :meth:`prescaled` is called with the pre-scale."""

    def __init__(
        self, sources: tuple[Source, Source], box: tuple[int, int, int, int], cfg: RoiConfig,
        center: tuple[float, float] | None,
    ) -> None:
        H, W = sources[0].map_x.shape
        self.sources, self.box, self.cfg, self.center, self.size = sources, box, cfg, center, (W, H)
        self.left: Ahead | None = fine_core(sources[0], box, cfg, self.size)
        self.tele: Ahead | None = None

    def prescaled(self, scale: float) -> None:
        """Start the tele's core for the W-T pre-scale ``scale`` (about ``center``)."""
        self.tele = fine_core(self.sources[1], self.box, self.cfg, self.size, scale, self.center)


def _around(
    part: tuple[int, int, int, int], core: tuple[int, int, int, int]
) -> list[tuple[int, int, int, int]]:
    """The bands (x0, y0, x1, y1) that cover ``part`` less ``core`` (which lies inside it):
    above and below it at the part's width, left and right of it at its height."""
    x0, y0, x1, y1 = part
    cx0, cy0, cx1, cy1 = core
    bands = [(x0, y0, x1, cy0), (x0, cy1, x1, y1), (x0, cy0, cx0, cy1), (cx1, cy0, x1, cy1)]
    return [b for b in bands if b[2] > b[0] and b[3] > b[1]]


def _resampled(
    source: Source, part: tuple[int, int, int, int], ahead: Ahead | None, scale: float
) -> Any:
    """``source.remap`` of ``part`` by the default interpolation, taking the pixels of
    ``ahead`` when it lies inside the part and was chosen for the same pre-scale."""
    x0, y0, x1, y1 = part
    if ahead is None or ahead.scale != scale:
        return source.remap(DEFAULT_INTERPOLATION, part)
    cx0, cy0, cx1, cy1 = ahead.part
    if not (x0 <= cx0 and y0 <= cy0 and cx1 <= x1 and cy1 <= y1):
        return source.remap(DEFAULT_INTERPOLATION, part)
    core = ahead.pixels.result()
    out = np.empty((y1 - y0, x1 - x0, *core.shape[2:]), core.dtype)
    out[cy0 - y0 : cy1 - y0, cx0 - x0 : cx1 - x0] = core
    for bx0, by0, bx1, by1 in _around(part, ahead.part):
        out[by0 - y0 : by1 - y0, bx0 - x0 : bx1 - x0] = source.remap(
            DEFAULT_INTERPOLATION, (bx0, by0, bx1, by1))
    return out


def two_passes(box: tuple[int, int, int, int], d_max: int, cfg: RoiConfig,
               size: tuple[int, int]) -> bool:
    """Whether the coarse step reads a cubic window and the fine part is resampled again
    (:func:`fine_window`): when the fine part (bounded by the whole searched range
    ``far_disparity_px`` … d_max and the coarse rows) is a small share of the window of
    ``size`` (W, H)."""
    W, H = size
    x0, y0, x1, y1 = _fine_part(box, cfg.far_disparity_px - cfg.fine_range_px,
                                d_max + cfg.fine_range_px,
                                cfg.coarse_rows, cfg, (W, H))
    return (x1 - x0) * (y1 - y0) <= MAX_FINE_SHARE * W * H


def coarse_window(
    sources: tuple[Source, Source], box: tuple[int, int, int, int], d_max: int, cfg: RoiConfig,
) -> tuple[Any, Any, bool]:
    """The whole window pair the coarse step reads, and whether the fine part must be
    resampled again (:func:`two_passes`): cubic then, else Lanczos-4."""
    H, W = sources[0].map_x.shape
    if not two_passes(box, d_max, cfg, (W, H)):
        return (*remap_pair(sources, DEFAULT_INTERPOLATION), False)
    return (*remap_pair(sources, COARSE_INTERPOLATION), True)


def coarse_lazy(
    sources: tuple[Source, Source | Future[Source]], box: tuple[int, int, int, int], d_max: int,
    cfg: RoiConfig, first_box: tuple[int, int, int, int], tele_like: Any = None,
) -> LazyPair | None:
    """With two passes, the cubic pair resampled where the coarse step reads the coarse box
    ``first_box`` (x, y, w, h) only (:class:`~phonestereo.flows.tele_roi_lazy.LazyPair`,
    which resamples the next boxes' parts when asked; the tele source may still be pending
    on the helper thread, ``tele_like`` its dtype); None with one pass (:func:`coarse_window`)."""
    H, W = sources[0].map_x.shape
    if not two_passes(box, d_max, cfg, (W, H)):
        return None
    pair = LazyPair(sources, COARSE_INTERPOLATION, (cfg.far_disparity_px, d_max),
                    cfg.coarse_rows, tele_like)
    pair.cover_box(first_box)
    return pair


def fine_window(
    sources: tuple[Source, Source], lw: Any, rt: Any, box: tuple[int, int, int, int],
    d0: float, e0: float, scale: float, center: tuple[float, float] | None, cfg: RoiConfig,
    ahead: FineAhead | None = None,
) -> tuple[Any, Any]:
    """The window pair with the fine matcher's part resampled by the default interpolation
    (and the W-T pre-scale the coarse step chose applied to the tele as it did; ``ahead``:
    the left's and the tele's :func:`fine_core`, whose pixels are taken, not resampled again).

    The part is the matcher's crop (:func:`~phonestereo.features.match_input.crop_box` of the
    box for the fine disparities d0 ± ``fine_range_px`` and the row band that
    ``roi_plane.match_majority`` uses) plus ``_FINE_GUARD_PX``: every pixel the matcher and the
    blur equalisation read is then the one a whole-window Lanczos-4 remap gives.
    """
    H, W = lw.shape[:2]
    x0, y0, x1, y1 = part_w = part_t = fine_part(box, d0, e0, cfg, (W, H))
    if scale != 1.0 and center is not None:  # rescale_tele reads rt at c + (q − c)/s (cubic)
        part_t = preimage(part_w, scale, center, (W, H))

    # the tele's part on the helper (its core is ready there: queued before it)
    left, tele = (None, None) if ahead is None else (ahead.left, ahead.tele)
    pending = background(_resampled, sources[1], part_t, tele, scale)
    lw = lw.copy()
    lw[y0:y1, x0:x1] = _resampled(sources[0], part_w, left, 1.0)
    out = rt.copy()
    if scale == 1.0 or center is None:
        out[y0:y1, x0:x1] = pending.result()
        return lw, out
    # pre-scale the fine tele into part_w: rescale_tele(part_t pasted into rt, box=part_w)'s
    # pixels (its taps stay inside part_t), from part_t alone, in two row bands (one per thread)
    fine_t = pending.result()
    m = scale_matrix(scale, center, (x0, y0))
    h = y1 - y0

    def warp(bands: Sequence[tuple[int, int]]) -> None:
        for a, b in bands:
            out[y0 + a : y0 + b, x0:x1] = warp_part(fine_t, m, (0, a, x1 - x0, b), part_t[:2])

    run_split(warp, [(0, h // 2), (h // 2, h)], min_items=2)
    return lw, out
