"""The face chart: real portraits, each scaled to an IPD of 63 mm (thesis §2.2, §3.6).

The learning phase measures faces; a chart whose faces all have the same interpupillary
distance (IPD, pupil to pupil) isolates the disparity correction from the spread of real IPDs
(§2.2: "all the faces in the image have fixed IPD of 6.3 cm ... spread as uniformly as possible").

Layout: a grid of equal square cells on a mid-grey background; in each cell one portrait,
scaled so that its pupils are ``ipd_m`` apart, its eye midpoint centred horizontally and at
``eye_height`` of the cell height, and clipped to the cell minus a ``gap_m`` border (the
portrait's *box*). Portraits are not rotated: a slightly rolled head stays rolled, which
changes nothing in uv (the pupils are still ``ipd_m`` apart on the plane).

The shipped portraits (``charts/data/faces``, CC0, see its ``LICENSES.md``) are 600 × 600 px;
their pupil centres come from MediaPipe FaceMesh iris landmarks (``tools/locate_pupils.py``,
``pupils.json``, pixel convention of docs/conventions.md). Eye 0 is the one on the image left.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass, field
from importlib import resources
from typing import Any

import numpy as np
from PIL import Image

from phonestereo.charts.base import (
    Array,
    Keypoints,
    blockwise,
    check_uv,
    inside_mask,
    print_to_reflectance,
    require_reflectance,
)
from phonestereo.errors import InputError

#: Population mean interpupillary distance (Dodgson 2004), the thesis's chart value.
IPD_M = 0.063


@dataclass(frozen=True, eq=False)
class Portrait:
    """One shipped portrait and its located eyes (pixels, docs/conventions.md)."""

    #: File name in ``charts/data/faces``.
    name: str
    #: (width, height) in pixels.
    size: tuple[int, int]
    #: ndarray, shape (2, 2). Iris centres (x, y), eye 0 on the image left.
    pupils_px: Array
    #: ndarray, shape (2, 2). Centroids of the eye-contour landmarks (x, y), same eye order.
    eye_contours_px: Array

    @property
    def ipd_px(self) -> float:
        """Pupil-to-pupil distance in pixels."""
        return float(np.linalg.norm(self.pupils_px[1] - self.pupils_px[0]))


def _data_dir() -> Any:
    return resources.files("phonestereo.charts") / "data" / "faces"


@functools.cache
def portraits() -> dict[str, Portrait]:
    """The shipped portraits and their pupil table, by file name (sorted).

    >>> table = portraits()
    >>> len(table), all(80 < p.ipd_px < 140 for p in table.values())
    (8, True)
    """
    table = json.loads((_data_dir() / "pupils.json").read_text())
    out = {}
    for name, entry in sorted(table["faces"].items()):
        pupils = np.array(entry["pupils_px"], dtype=np.float64)
        contours = np.array(entry["eye_contour_centroids_px"], dtype=np.float64)
        pupils.setflags(write=False)
        contours.setflags(write=False)
        out[name] = Portrait(name, (int(entry["size"][0]), int(entry["size"][1])), pupils, contours)
    return out


@functools.lru_cache(maxsize=16)
def portrait_reflectance(name: str) -> Array:
    """Linear reflectance (H, W) of a shipped portrait printed in grey.

    Grey = linear-light luminance (Rec. 709 weights on sRGB-decoded RGB), printed between
    ink (0.05) and paper (0.95) as :func:`~phonestereo.charts.base.print_to_reflectance`.
    """
    with (_data_dir() / name).open("rb") as fh:
        rgb = np.asarray(Image.open(fh).convert("RGB"), dtype=np.float64) / 255.0
    lin = print_to_reflectance(rgb)  # per channel, then luminance in linear light
    refl = lin @ np.array([0.2126, 0.7152, 0.0722])
    refl.setflags(write=False)
    return refl


@dataclass(frozen=True, eq=False)
class FaceChart:
    """A grid of real portraits, every one scaled to the same IPD (thesis §2.2).

    Examples
    --------
    >>> chart = FaceChart()                                  # 4 × 2 faces, 1.3 × 0.65 m
    >>> chart.size_m
    (1.3, 0.65)
    >>> p = chart.keypoints()["pupils"].uv.reshape(-1, 2, 2)
    >>> np.round(1000 * np.linalg.norm(p[:, 1] - p[:, 0], axis=1), 6).tolist() == [63.0] * 8
    True
    """

    #: Cells (cols, rows); faces fill them row by row.
    grid: tuple[int, int] = (4, 2)
    #: Side of a square cell, metres.
    cell_m: float = 0.325
    #: Pupil-to-pupil distance of every face on the chart, metres (thesis: 63 mm).
    ipd_m: float = IPD_M
    #: Grey border kept free inside each cell, metres (faces never touch).
    gap_m: float = 0.01
    #: Height of the eye midpoint as a fraction of the cell, from its top.
    eye_height: float = 0.42
    #: Reflectance of the mid-grey background (0.2 ≈ an 18 % grey card on paper).
    background: float = 0.2
    #: tuple of str. Portrait file names in cell order; empty: all shipped portraits, repeated if
    #: needed.
    faces: tuple[str, ...] = ()
    name: str = "faces"
    _scale: Array = field(init=False, repr=False)
    _origin: Array = field(init=False, repr=False)
    _boxes: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        cols, rows = (int(n) for n in self.grid)
        if (cols, rows) != tuple(self.grid) or cols < 1 or rows < 1:
            raise InputError(f"grid must be two integers (cols, rows) >= 1, got {self.grid}")
        for attr in ("cell_m", "ipd_m"):
            val = float(getattr(self, attr))
            if not (np.isfinite(val) and val > 0):
                raise InputError(f"{attr} must be a positive length in metres, got {val}")
            object.__setattr__(self, attr, val)
        if not 0 <= self.gap_m < self.cell_m / 2:
            raise InputError(f"gap_m must be in [0, cell_m / 2), got {self.gap_m}")
        if not 0 < self.eye_height < 1:
            raise InputError(f"eye_height must be a fraction in (0, 1), got {self.eye_height}")
        object.__setattr__(self, "grid", (cols, rows))
        object.__setattr__(self, "background", require_reflectance(self.background, "background"))
        table = portraits()
        names = tuple(self.faces) or tuple(table)
        unknown = [n for n in names if n not in table]
        if unknown:
            raise InputError(f"unknown portrait(s) {unknown}; choose from {sorted(table)}")
        names = tuple(names[k % len(names)] for k in range(cols * rows))
        object.__setattr__(self, "faces", names)
        col, row = np.arange(cols * rows) % cols, np.arange(cols * rows) // cols
        scale = np.array([self.ipd_m / table[n].ipd_px for n in names])
        mid_px = np.array([table[n].pupils_px.mean(axis=0) for n in names])
        sizes = np.array([table[n].size for n in names], dtype=np.float64)
        target = np.column_stack([(col + 0.5) * self.cell_m, (row + self.eye_height) * self.cell_m])
        origin = target - scale[:, None] * mid_px  # uv of the centre of pixel (0, 0)
        lo = origin - 0.5 * scale[:, None]  # portrait extent: pixel edges
        hi = origin + (sizes - 0.5) * scale[:, None]
        cell_lo = np.column_stack([col, row]) * self.cell_m + self.gap_m / 2
        cell_hi = np.column_stack([col + 1, row + 1]) * self.cell_m - self.gap_m / 2
        boxes = np.column_stack([np.maximum(lo, cell_lo), np.minimum(hi, cell_hi)])
        pupils = np.stack([origin[f] + scale[f] * table[n].pupils_px for f, n in enumerate(names)])
        if np.any(pupils < boxes[:, None, :2]) or np.any(pupils >= boxes[:, None, 2:]):
            raise InputError(
                f"cell_m = {self.cell_m} m is too small for faces with an IPD of {self.ipd_m} m "
                "(a pupil falls outside its cell); use a larger cell_m or smaller ipd_m"
            )
        for arr, attr in ((scale, "_scale"), (origin, "_origin"), (boxes, "_boxes")):
            arr.setflags(write=False)
            object.__setattr__(self, attr, arr)

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) of the printed chart, metres."""
        return round(self.grid[0] * self.cell_m, 12), round(self.grid[1] * self.cell_m, 12)

    @property
    def boxes_m(self) -> Array:
        """Per-face visible portrait box (F, 4): (u0, v0, u1, v1), metres."""
        return self._boxes.copy()

    @property
    def scale_m_per_px(self) -> Array:
        """Printed size of one portrait pixel, per face (F,), metres."""
        return self._scale.copy()

    def portrait_to_uv(self, face: int, q: Any) -> Array:
        """Map portrait pixels ``q`` (..., 2) of face ``face`` to chart uv (..., 2), metres."""
        return self._origin[face] + self._scale[face] * np.asarray(q, dtype=np.float64)

    def pupils_uv(self) -> Array:
        """Pupil centres (F, 2, 2): face, eye (0 = left on the chart), (u, v) metres."""
        table = portraits()
        return np.stack(
            [self.portrait_to_uv(f, table[n].pupils_px) for f, n in enumerate(self.faces)]
        )

    def keypoints(self) -> dict[str, Keypoints]:
        """``"pupils"`` and ``"eye_contours"`` (centroids): ids (face, eye), uv metres."""
        table = portraits()
        nf = len(self.faces)
        ids = np.stack(np.meshgrid(np.arange(nf), np.arange(2), indexing="ij"), -1).reshape(-1, 2)
        contours = np.stack(
            [self.portrait_to_uv(f, table[n].eye_contours_px) for f, n in enumerate(self.faces)]
        )
        return {
            "pupils": Keypoints(ids, self.pupils_uv().reshape(-1, 2)),
            "eye_contours": Keypoints(ids, contours.reshape(-1, 2)),
        }

    def intensity(self, uv: Any) -> Array:
        """Reflectance at chart points ``uv`` (..., 2) metres; NaN off the chart.

        Portrait pixels are sampled bilinearly (exact float64 weights); the background is
        ``background``.

        >>> chart = FaceChart()
        >>> float(chart.intensity([0.001, 0.001]))                 # corner: mid-grey
        0.2
        """
        u, v, lead = check_uv(uv)
        return blockwise(self._intensity, u, v).reshape(lead)

    def _intensity(self, u: Array, v: Array) -> Array:
        cols, rows = self.grid
        out = np.full(u.shape, self.background)
        inside = inside_mask(u, v, self.size_m)
        out[~inside] = np.nan
        idx = np.flatnonzero(inside)
        cu, cv = u.take(idx), v.take(idx)  # 1-D takes: faster than fancy indexing, same values
        col = np.minimum((cu * (1.0 / self.cell_m)).astype(np.intp), cols - 1)
        row = np.minimum((cv * (1.0 / self.cell_m)).astype(np.intp), rows - 1)
        face = row * cols + col
        b, o = self._boxes.T, self._origin.T
        hit = (cu >= b[0].take(face)) & (cu < b[2].take(face))
        hit &= (cv >= b[1].take(face)) & (cv < b[3].take(face))
        idx, face = idx[hit], face[hit]
        inv = 1.0 / self._scale.take(face)
        x = (u.take(idx) - o[0].take(face)) * inv
        y = (v.take(idx) - o[1].take(face)) * inv
        out[idx] = _bilinear(_raster_stack(self.faces), face, x, y)
        return out


@functools.lru_cache(maxsize=8)
def _raster_stack(names: tuple[str, ...]) -> Array:
    """Reflectance rasters of ``names`` stacked (F, H, W); all shipped portraits share a size."""
    rasters = [portrait_reflectance(n) for n in names]
    if len({r.shape for r in rasters}) != 1:
        raise InputError(
            f"face-chart portraits must share one size, got {[r.shape for r in rasters]}"
        )
    stack = np.stack(rasters)
    stack.setflags(write=False)
    return stack


def _bilinear(stack: Array, k: Any, x: Array, y: Array) -> Array:
    """Bilinear sample of image ``k`` of ``stack`` (F, H, W) at pixels (x, y) (docs/conventions.md).

    Edge pixels extend half a pixel (the portrait's extent); exact float64 weights.
    """
    _, h, w = stack.shape
    xc = np.clip(x, 0.0, w - 1.0)
    yc = np.clip(y, 0.0, h - 1.0)
    x0 = np.minimum(xc.astype(np.intp), w - 2)  # xc >= 0: truncation is floor
    y0 = np.minimum(yc.astype(np.intp), h - 2)
    fx = xc - x0
    fy = yc - y0
    flat = stack.ravel()
    i = (np.asarray(k, dtype=np.intp) * h + y0) * w + x0
    p00, p01, p10, p11 = (flat.take(i + di) for di in (0, 1, w, w + 1))
    top = p00 + (p01 - p00) * fx
    bottom = p10 + (p11 - p10) * fx
    return top + (bottom - top) * fy
