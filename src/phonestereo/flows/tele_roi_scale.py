"""The W-T pre-scale of the rectified tele window, computed on a part of it only (issue #18).

:func:`~phonestereo.flows.coarse.rescale_tele` warps the whole tele window (``cv2.warpAffine``,
cubic); the coarse step reads only the strip each coarse box searches (at 12 MP ~60 % of the
window; the whole-window warp was ~10 % of the application phase there). A warp of a part
with its own origin rounds OpenCV's fixed-point coordinates differently on a few pixels;
:func:`scaled_part` instead builds the fixed-point maps ``cv2.warpAffine`` builds for the whole
window (its ``WarpAffineInvoker``: 10-bit coordinates rounded to 5 fractional bits, 1/32 px)
for the part's pixels only and hands them to ``cv2.remap``, as ``warpAffine`` itself does: every
pixel is the whole-window warp's, bit for bit (tests/flows/test_tele_roi_scale.py).
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "coarse_reads", "fixed_point_maps", "preimage", "scale_matrix", "scaled_part", "warp_part",
]

#: ``cv2.warpAffine``'s coordinate bits (AB_BITS) and the interpolation tables' (INTER_BITS).
_AB_BITS, _INTER_BITS = 10, 5
#: Px beyond a coarse box's search strip that the tile tests read (each tile's ±3-px search
#: about a peak rounded to whole pixels: ≤ 4 px), with room to spare.
_TILE_REACH = 8

Box = tuple[int, int, int, int]


def scale_matrix(
    scale: float, center: tuple[float, float], origin: tuple[int, int] = (0, 0)
) -> NDArray[np.float32]:
    """The 2 × 3 inverse map (float32) of :func:`~phonestereo.flows.coarse.rescale_tele`:
    output pixel q reads the tele at c + (q − c)/scale; with ``origin`` (x0, y0), that of its
    ``box`` variant, whose output pixel (0, 0) is q = (x0, y0)."""
    k = 1.0 / scale
    cx, cy = center
    x0, y0 = origin
    return np.array([[k, 0, cx * (1 - k) + k * x0], [0, k, cy * (1 - k) + k * y0]], np.float32)


def fixed_point_maps(
    m: Any, box: Box, origin: tuple[int, int] = (0, 0)
) -> tuple[NDArray[np.int16], NDArray[np.uint16]]:
    """``cv2.warpAffine``'s remap tables (WARP_INVERSE_MAP) for the output pixels of ``box``.

    Parameters
    ----------
    m : array_like, shape (2, 3)
        The inverse map as given to ``warpAffine`` (float32 values); axis-aligned (no shear or
        rotation: m[0, 1] = m[1, 0] = 0), so x and y are rounded independently.
    box : (x0, y0, x1, y1)
        Output pixels, in the frame of the whole warp's output (ends exclusive).
    origin : (x, y)
        Where the source array handed to ``cv2.remap`` starts in the whole source image.

    Returns
    -------
    xy : ndarray, int16, shape (h, w, 2)
        Whole source pixels (x, y), as ``cv2.convertMaps`` gives for CV_16SC2.
    a : ndarray, uint16, shape (h, w)
        Their 1/32-px fractions, (y & 31)·32 + (x & 31).
    """
    mm = np.asarray(m, np.float32).astype(np.float64)
    if mm[0, 1] != 0 or mm[1, 0] != 0:
        raise ValueError("fixed_point_maps: only an axis-aligned map (a scale and a shift)")
    x0, y0, x1, y1 = box
    scale = 1 << _AB_BITS
    shift = _AB_BITS - _INTER_BITS
    half = scale // (1 << _INTER_BITS) // 2  # round_delta
    x = np.arange(x0, x1, dtype=np.float64)
    y = np.arange(y0, y1, dtype=np.float64)
    # X0 = round((m01·y + m02)·S) + δ with m01 = 0; adelta = round(m00·x·S) (imgwarp.cpp)
    X = (np.rint(mm[0, 2] * scale).astype(np.int64) + half
         + np.rint(mm[0, 0] * x * scale).astype(np.int64)) >> shift
    Y = (np.rint((mm[1, 1] * y + mm[1, 2]) * scale).astype(np.int64) + half) >> shift
    tab = (1 << _INTER_BITS) - 1
    # each (x, y) int16 pair as one little-endian uint32 (x the low half): one broadcast
    # write instead of two strided ones (the map is ~1 Mpx per coarse strip)
    lo = (((X >> _INTER_BITS) - origin[0]) & 0xFFFF).astype(np.uint32)
    hi = ((((Y >> _INTER_BITS) - origin[1]) & 0xFFFF).astype(np.uint32) << 16)
    xy = np.bitwise_or(hi[:, None], lo[None, :]).view("<i2").reshape(len(Y), len(X), 2)
    a = np.add(((Y & tab) * (tab + 1)).astype(np.uint16)[:, None],
               (X & tab).astype(np.uint16)[None, :])
    return xy, a


def warp_part(source: Any, m: Any, box: Box, origin: tuple[int, int] = (0, 0)) -> Any:
    """The pixels in ``box`` (x0, y0, x1, y1) of ``cv2.warpAffine`` (cubic, inverse map ``m``,
    constant border) of an image of which ``source`` is the part starting at ``origin``
    (:func:`fixed_point_maps`), bit for bit."""
    xy, a = fixed_point_maps(m, box, origin)
    return cv2.remap(source, xy, a, cv2.INTER_CUBIC, borderMode=cv2.BORDER_CONSTANT)


def scaled_part(right: Any, scale: float, center: tuple[float, float], box: Box) -> Any:
    """The pixels in ``box`` (x0, y0, x1, y1) of ``rescale_tele(right, scale, center)``, bit
    for bit, without warping the rest of the window."""
    return warp_part(right, scale_matrix(scale, center), box)


def coarse_reads(
    box: Box, d_min: int, d_max: int, rows: int, size: tuple[int, int], reach: int = _TILE_REACH
) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) of the right window that the coarse step reads for the left box
    (x, y, w, h): the whole-box search strip (disparities d_min … d_max, ±``rows``) and the
    tile tests about its peaks (``reach`` px beyond the strip: the default covers the ±3-px
    tile test; the W-T scale's ±8-px tiles need 9), inside a window of ``size`` (W, H)."""
    x, y, w, h = box
    W, H = size
    r = reach
    return (max(x - d_max - r, 0), max(y - rows - r, 0),
            min(x + w - d_min + r, W), min(y + h + rows + r, H))


def preimage(
    part: tuple[int, int, int, int], scale: float, center: tuple[float, float],
    size: tuple[int, int],
) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) of the tele window that the pre-scale of ``part`` reads (its cubic
    taps and a pixel to spare), inside a window of ``size`` (W, H)."""
    x0, y0, x1, y1 = part
    c = np.array(center)
    q = c + (np.array([[x0, y0], [x1 - 1, y1 - 1]], float) - c) / scale
    lo, hi = np.floor(q.min(0)).astype(int) - 3, np.ceil(q.max(0)).astype(int) + 4
    return (max(int(lo[0]), 0), max(int(lo[1]), 0), min(int(hi[0]), size[0]),
            min(int(hi[1]), size[1]))
