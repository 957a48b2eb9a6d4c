"""The coarse step's window pair resampled where the coarse step reads it (issue #18).

With two passes (:func:`~phonestereo.flows.roi_window.coarse_window`) the coarse step reads the
cubic window only in the first usable coarse box (the left) and its search strip and tiles
(the right; :func:`~phonestereo.flows.tele_roi_scale.coarse_reads`); the next boxes are read
only when the first cannot be used. :class:`LazyPair` resamples the first box's parts at
once (the right's first rows on the helper thread, about as many pixels as this thread
resamples) and any other part when asked for it: ~40 % fewer cubic pixels at 12 MP than the
boxes' bounding box and the whole right window. ``cv2.remap`` treats every output pixel on
its own, so every pixel is the whole-window remap's; the rest stays zero (unread).
"""

from __future__ import annotations

from concurrent.futures import Future
from typing import Any

import numpy as np

from phonestereo.features._threads import background
from phonestereo.flows.tele_roi_scale import coarse_reads
from phonestereo.rectification.maps import Source

__all__ = ["LazyPair"]

Box = tuple[int, int, int, int]
#: Px beyond a box's search strip read on the right: the W-T scale's tiles search ±8 px about
#: the first peak (≤ 9 px beyond the strip), with room to spare.
RIGHT_REACH = 16


class LazyPair:
    """The window pair (``left``, ``right``: full-size arrays, zero where not yet resampled),
    filled in place as the coarse step asks for parts of it."""

    def __init__(
        self, sources: tuple[Source, Source | Future[Source]], interpolation: str,
        span: tuple[int, int], rows: int, tele_like: Any = None,
    ) -> None:
        """``sources[1]`` may be the helper thread's pending tele :class:`Source` (the left's
        part is then resampled here while it is prepared); ``span``: the searched disparities
        (d_min, d_max), px; ``tele_like``: an array of the tele's dtype and channels (default:
        the tele source's image)."""
        self.sources, self.interpolation = sources, interpolation
        self.span, self.rows = span, rows
        self.H, self.W = sources[0].map_x.shape
        self.left = self._empty(sources[0].image)
        self.right = self._empty(self._source(1).image if tele_like is None else tele_like)
        self._done = (np.zeros((self.H, self.W), bool), np.zeros((self.H, self.W), bool))
        #: The parts resampled so far, per image (a part inside one of them needs no scan).
        self._parts: tuple[list[Any], list[Any]] = ([], [])

    def _empty(self, like: Any) -> Any:
        like = np.asarray(like)
        return np.zeros((self.H, self.W, *like.shape[2:]), like.dtype)

    def _source(self, i: int) -> Source:
        s = self.sources[i]
        return s.result() if isinstance(s, Future) else s

    def _missing(self, i: int, part: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
        """The bounding box (x0, y0, x1, y1) of the pixels of ``part`` not yet resampled in
        image i (empty: x1 ≤ x0)."""
        x0, y0, x1, y1 = part
        if any(a <= x0 and b <= y0 and x1 <= c and y1 <= d for a, b, c, d in self._parts[i]):
            return (x0, y0, x0, y0)
        todo = ~self._done[i][y0:y1, x0:x1]
        rows, cols = np.flatnonzero(todo.any(axis=1)), np.flatnonzero(todo.any(axis=0))
        if not len(rows):
            return (x0, y0, x0, y0)
        return (x0 + int(cols[0]), y0 + int(rows[0]), x0 + int(cols[-1]) + 1,
                y0 + int(rows[-1]) + 1)

    def _fill(self, i: int, part: tuple[int, int, int, int]) -> None:
        x0, y0, x1, y1 = part
        if x1 <= x0 or y1 <= y0:
            return
        (self.left, self.right)[i][y0:y1, x0:x1] = self._source(i).remap(self.interpolation, part)
        self._done[i][y0:y1, x0:x1] = True
        self._parts[i].append(part)

    def cover_box(self, box: Box) -> None:
        """Resample what the coarse step reads for the left box (x, y, w, h): the box in the
        left, its strip and tiles in the right (the right's first rows on the helper, queued
        behind a pending tele source; the left here first)."""
        x, y, w, h = box
        lp = self._missing(0, (x, y, x + w, y + h))
        rp = self._missing(1, coarse_reads(box, *self.span, self.rows, (self.W, self.H),
                                           RIGHT_REACH))
        rx0, ry0, rx1, ry1 = rp
        n_left = max(lp[2] - lp[0], 0) * max(lp[3] - lp[1], 0)
        n_right = max(rx1 - rx0, 0) * max(ry1 - ry0, 0)
        if not n_right:
            self._fill(0, lp)
            return
        k = min(ry0 + round((n_right + n_left) / 2 / (rx1 - rx0)), ry1)
        top = background(self._fill, 1, (rx0, ry0, rx1, k))
        self._fill(0, lp)
        self._fill(1, (rx0, k, rx1, ry1))
        top.result()

    def cover_right(self, part: tuple[int, int, int, int]) -> None:
        """Resample the right window over ``part`` (x0, y0, x1, y1)."""
        self._fill(1, self._missing(1, part))
