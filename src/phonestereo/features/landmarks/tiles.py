"""Where the MediaPipe backend looks: search tiles, box suppression, crops, quarter turns.

Pure pixel geometry of :mod:`~phonestereo.features.landmarks.mediapipe_backend` (which
re-exports :func:`tile_grid`, :func:`nms` and :func:`unrotate`): no model is touched here.
Pixels follow docs/conventions.md ((0, 0) at the centre of the top-left pixel).
"""

from __future__ import annotations

import numpy as np

from phonestereo.errors import InputError
from phonestereo.features.landmarks.base import F64, U8

Box = tuple[float, float, float, float, float]  # x0, y0, x1, y1 (pixels), score


def tile_grid(
    width: int,
    height: int,
    min_tile_px: int,
    two_level: tuple[float, float] | None = None,
) -> list[tuple[int, int, int]]:
    """Square search tiles (x0, y0, side) of an image: sides max(W, H) / 2^k ≥ min_tile_px.

    Neighbouring tiles of one level overlap by about half a side, so every face smaller than
    half a tile lies whole inside some tile. Tiles larger than the image are clipped to it.

    With ``two_level = (fine, overlap)`` (fractions of max(W, H)) there are two levels
    instead: the whole image, and tiles of side ``fine`` overlapping their neighbours by at
    least ``overlap``. The detector finds faces from ~6 % of a tile's side, so the whole image
    covers faces from 0.06, and the fine tiles those from 0.06·fine up to ``overlap`` (each
    lies whole in some tile): (0.35, 0.08) covers 0.02–0.08 and beyond with 13 tiles instead
    of the pyramid's 42.

    >>> len(tile_grid(2000, 1500, 256))            # sides 2000, 1000, 500: 1 + 6 + 35 tiles
    42
    >>> len(tile_grid(2000, 1500, 256, (0.35, 0.08)))   # 2000, and 700 every <= 540 px
    13
    >>> tile_grid(300, 200, 256)
    [(0, 0, 300)]
    """
    if width < 1 or height < 1 or min_tile_px < 1:
        raise InputError(f"bad tile grid request: {width} × {height}, min tile {min_tile_px}")
    out = []
    side = max(width, height)
    if two_level is not None:
        fine, overlap = two_level
        if not 0 < overlap < fine < 1:
            raise InputError(f"two_level must be (fine, overlap) with 0 < overlap < fine < 1, "
                             f"got {two_level}")
        small = max(round(fine * side), 1)
        step = small - round(overlap * side)
        out.append((0, 0, side))
        for y0 in _starts(height, small, step):
            for x0 in _starts(width, small, step):
                out.append((x0, y0, small))
        return out
    while True:
        for y0 in _starts(height, side):
            for x0 in _starts(width, side):
                out.append((x0, y0, side))
        side //= 2
        if side < min_tile_px:
            break
    return out


def _starts(length: int, side: int, step: float | None = None) -> list[int]:
    """Tile starts along one axis: first at 0, last at length − side, at most ``step``
    (default half a side) apart."""
    span = length - side
    if span <= 0:
        return [0]
    n = int(np.ceil(span / (side / 2 if step is None else step))) + 1
    return sorted({round(v) for v in np.linspace(0, span, n)})


def nms(boxes: list[Box], iou_max: float = 0.3) -> list[Box]:
    """Greedy non-maximum suppression (highest score first); a box that overlaps a kept box
    by more than ``iou_max`` IoU or lies mostly (> 60 %) inside it is dropped.

    >>> nms([(0, 0, 10, 10, 0.9), (1, 1, 11, 11, 0.8), (50, 50, 60, 60, 0.7)])
    [(0, 0, 10, 10, 0.9), (50, 50, 60, 60, 0.7)]
    """
    kept: list[Box] = []
    for b in sorted(boxes, key=lambda b: -b[4]):
        area = (b[2] - b[0]) * (b[3] - b[1])
        dup = False
        for k in kept:
            iw = min(b[2], k[2]) - max(b[0], k[0])
            ih = min(b[3], k[3]) - max(b[1], k[1])
            inter = max(iw, 0.0) * max(ih, 0.0)
            union = area + (k[2] - k[0]) * (k[3] - k[1]) - inter
            if inter > iou_max * union or inter > 0.6 * area:
                dup = True
                break
        if not dup:
            kept.append(b)
    return kept


def unrotate(points: F64, k: int, size: tuple[int, int]) -> F64:
    """Pixels (N, 2|3) of ``np.rot90(image, k)`` → pixels of ``image`` (W, H = ``size``).

    One counter-clockwise quarter turn maps image pixel (x, y) to (y, W − 1 − x); this undoes
    ``k`` of them (extra columns such as z are kept: an in-plane turn leaves the yaw alone).

    >>> img = np.arange(12).reshape(3, 4)                       # W = 4, H = 3
    >>> x, y = unrotate(np.array([[2.0, 1.0]]), 1, (4, 3))[0]   # pixel (2, 1) of rot90(img)
    >>> (x, y), int(np.rot90(img)[1, 2]) == int(img[int(y), int(x)])
    ((2.0, 2.0), True)
    """
    out = np.array(points, dtype=np.float64)
    w, h = size
    for j in range(k % 4, 0, -1):
        w_prev = w if (j - 1) % 2 == 0 else h
        x, y = out[:, 0].copy(), out[:, 1].copy()
        out[:, 0], out[:, 1] = w_prev - 1 - y, x
    return out


def crop_square(rgb: U8, X0: int, Y0: int, side: int) -> U8:
    """The square ``side`` × ``side`` crop starting at pixel (X0, Y0), black past the border
    (as many channels as ``rgb``: (H, W) gray or (H, W, 3))."""
    h, w = rgb.shape[:2]
    out = np.zeros((side, side, *rgb.shape[2:]), dtype=np.uint8)
    xa, ya, xb, yb = max(X0, 0), max(Y0, 0), min(X0 + side, w), min(Y0 + side, h)
    if xb > xa and yb > ya:
        out[ya - Y0 : yb - Y0, xa - X0 : xb - X0] = rgb[ya:yb, xa:xb]
    return out
