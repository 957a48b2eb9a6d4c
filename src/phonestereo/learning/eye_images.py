"""The rectified pair of the landmark disparity, resampled only where it is read (issue 18).

:func:`~phonestereo.learning.landmark_disparity.landmark_disparity` reads the reference
rectified wide and tele only around the faces' eyes (the NCC windows, their search bands and
the Lucas–Kanade samples of the tele's B-spline) and, for the Cramér–Rao σ, the noise of both
images, which :func:`~phonestereo.features.crlb.noise_sigma` takes from a fixed subset of rows
(:func:`~phonestereo.features.crlb.noise_rows`). :func:`prepare` resamples just those parts
(a whole-image Lanczos-4 remap of both images was ~20 ms of the learning phase's CPU per face
capture at 2000 × 1500). The arrays keep the whole rectified size — pixels nothing reads are
0 — so every index, border test and value read is that of a whole remap: ``cv2.remap`` treats
each output pixel on its own, and the spline coefficients are filtered over each box plus the
prefilter's reach (:data:`~phonestereo.features.spline_gradients.TAPS`), where the FIR
gives the whole image's values (tests/learning/test_landmark_disparity.py).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from phonestereo.features._threads import background
from phonestereo.features.crlb import noise_rows, noise_sigma
from phonestereo.features.spline_gradients import TAPS
from phonestereo.features.subpixel import bspline_coefficients
from phonestereo.rectification import Rectification
from phonestereo.rectification.maps import Source

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]
Box = tuple[int, int, int, int]

__all__ = ["FaceReach", "RectifiedPair", "eye_step", "gray32", "prepare"]

#: The largest window radius any search around the eyes uses (the eye windows ≤ 12 px,
#: :func:`~phonestereo.learning.tele_search.search_start`'s ≤ 20 px), px.
MAX_RADIUS = 20
#: Lucas–Kanade's reach beyond its window: ``max_step`` (1.5 px) and the cubic spline's taps
#: (−1 … +2), rounded up, px.
_LK_REACH = 4
#: Extra pixels on every side (a part resampled for nothing costs little; one missed, a
#: result), px.
_GUARD = 8


def eye_step(ipd_px: float) -> int:
    """Spacing of the 5 × 5 grid of eye windows for pupils ``ipd_px`` apart, px."""
    return max(2, round(0.06 * ipd_px))


def gray32(image: Any) -> F32:
    """Grey float32 (an (H, W, 3) BGR image weighted as OpenCV's grey)."""
    a = np.asarray(image)
    if a.ndim == 3:
        a = a[..., :3].astype(np.float32) @ np.array([0.114, 0.587, 0.299], np.float32)
    return np.ascontiguousarray(a, dtype=np.float32)


@dataclass(frozen=True)
class RectifiedPair:
    """The rectified wide (left) and tele (right), grey float32 (H', W'), the tele's B-spline
    coefficients and both images' noise σ, DN."""

    left: F32
    right: F32
    right_coef: F32
    sigma_left: float
    sigma_right: float


@dataclass(frozen=True)
class FaceReach:
    """Where the searches of one face may read: its rectified pupils (2, 2), the disparities
    ``d_lo`` … ``d_hi`` and the non-disparity errors up to ``e_max`` they may reach, px."""

    pupils: F64
    d_lo: float
    d_hi: float
    e_max: float

    def boxes(self, size: tuple[int, int]) -> tuple[Box, Box, Box]:
        """(left, right, coefficient) boxes (x0, y0, x1, y1), ends exclusive, inside ``size``.

        The left box holds every window centre (the pupils ± two grid steps) with the largest
        radius, the gradient filter's reach and a guard; the coefficient box every tele sample
        at the reachable (d, e); the right box that plus the spline prefilter's reach. Empty
        boxes (x0 = x1) for pupils or a range that is not finite (nothing is searched there).

        Pupils 60 px apart, d from 8 to 20 px, |e| ≤ 2 px in a 640 × 480 rectified pair:

        >>> reach = FaceReach(np.array([[200.0, 150.0], [260.0, 150.0]]), 8.0, 20.0, 2.0)
        >>> reach.boxes((640, 480))
        ((151, 101, 310, 200), (128, 96, 305, 205), (139, 107, 294, 194))
        """
        p = np.asarray(self.pupils, dtype=np.float64).reshape(2, 2)
        if not np.isfinite([*p.ravel(), self.d_lo, self.d_hi, self.e_max]).all():
            return (0, 0, 0, 0), (0, 0, 0, 0), (0, 0, 0, 0)
        step = 2 * eye_step(float(np.linalg.norm(p[1] - p[0]))) + 1
        lo, hi = np.floor(p.min(axis=0)) - step, np.ceil(p.max(axis=0)) + step
        a = MAX_RADIUS + TAPS + 2 + _GUARD
        left = (lo[0] - a, lo[1] - a, hi[0] + a + 1, hi[1] + a + 1)
        b = MAX_RADIUS + _LK_REACH + _GUARD
        ex = np.ceil(self.e_max)
        coef = (
            lo[0] - np.ceil(self.d_hi) - b, lo[1] - ex - b,
            hi[0] - np.floor(self.d_lo) + b + 1, hi[1] + ex + b + 1,
        )
        t = TAPS + 1
        right = (coef[0] - t, coef[1] - t, coef[2] + t, coef[3] + t)
        return _clip(left, size), _clip(right, size), _clip(coef, size)


def _clip(box: Any, size: tuple[int, int]) -> Box:
    w, h = size
    x0, y0 = min(max(int(box[0]), 0), w), min(max(int(box[1]), 0), h)
    return x0, y0, max(min(int(box[2]), w), x0), max(min(int(box[3]), h), y0)


def _resample(src: Source, boxes: Sequence[Box], rows: NDArray[np.int64],
              shape: tuple[int, int]) -> F32:
    """The rectified image (grey float32) at ``rows`` (whole width) and inside ``boxes``."""
    out = np.zeros(shape, np.float32)
    if len(rows):
        out[rows] = gray32(src.remap_rows(rows))
    for x0, y0, x1, y1 in boxes:
        if x1 > x0 and y1 > y0:
            out[y0:y1, x0:x1] = gray32(src.remap(box=(x0, y0, x1, y1)))
    return out


def prepare(
    rect: Rectification, image_wide: Any, image_tele: Any, faces: Sequence[FaceReach] | None
) -> RectifiedPair:
    """Both images rectified by ``rect`` where ``faces`` and the noise σ read them
    (module docstring; None: the whole images), the tele's part on the helper thread.

    Raises
    ------
    InputError, ShapeError
        As :meth:`~phonestereo.rectification.Rectification.remap`.
    """
    src_w, src_t = rect.sources(image_wide, image_tele)
    size = rect.wide_rect.size
    shape = (size[1], size[0])
    if faces is None:
        whole = (0, 0, *size)
        rows, boxes = np.zeros(0, np.int64), [(whole, whole, whole)]
    else:
        nr = noise_rows(*shape)
        rows = np.unique(np.concatenate([nr - 1, nr, nr + 1])) if len(nr) else nr
        boxes = [f.boxes(size) for f in faces]

    def tele() -> tuple[F32, F32]:
        right = _resample(src_t, [b[1] for b in boxes], rows, shape)
        coef = np.zeros(shape, np.float32)
        for (rx0, ry0, rx1, ry1), (cx0, cy0, cx1, cy1) in ((b[1], b[2]) for b in boxes):
            if cx1 > cx0 and cy1 > cy0:
                part = bspline_coefficients(right[ry0:ry1, rx0:rx1])
                coef[cy0:cy1, cx0:cx1] = part[cy0 - ry0 : cy1 - ry0, cx0 - rx0 : cx1 - rx0]
        return right, coef

    pending = background(tele)
    left = _resample(src_w, [b[0] for b in boxes], rows, shape)
    right, coef = pending.result()
    return RectifiedPair(left, right, coef, noise_sigma(left), noise_sigma(right))
