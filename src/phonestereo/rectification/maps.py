"""Remap maps of a rectification and the image resampling itself (cv2.remap).

A map gives, for every rectified pixel, the raw pixel it samples. It is the exact rectified →
raw point map (:func:`~phonestereo.rectification.points.from_rectified`) evaluated on a coarse
grid (``grid_step_px``, default 8) and interpolated (bicubic spline, then bilinear ×2): the
exact map needs a Newton undistortion per pixel in ``tele-to-wide`` (≈ 7 s for 2000×1500) and
a polynomial per pixel elsewhere (≈ 0.7 s), while the interpolated one costs ~20 ms and stays
within 1e-3 px of the exact map on the thesis modules (bounded in
tests/rectification/test_rect_maps.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.interpolate import BSpline, RectBivariateSpline

from phonestereo.errors import InputError, ShapeError
from phonestereo.geometry import Camera
from phonestereo.geometry.checks import Array
from phonestereo.rectification.points import from_rectified

INVALID = -10.0  # map value of rectified pixels with no raw source (cv2 fills them with 0)
_INTERP = {"linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC, "lanczos4": cv2.INTER_LANCZOS4}
#: Default resampling of the rectification. Bilinear interpolation low-passes an image by an
#: amount that depends on the sub-pixel phase of each sample, so a pair whose two images are
#: resampled at different phases gets a disparity bias: resampling the right image of the real
#: Middlebury-Q Adirondack pair through a 0.1° roll moves the sparse matcher's median error to
#: 1.95× the aligned pair's with bilinear, 1.16× with OpenCV's cubic, 1.05× with Lanczos-4
#: (tests/rectification/test_rect_interpolation.py). OpenCV's cubic (Keys, a = −0.75) does not
#: reproduce a linear ramp: it shifts an image's low frequencies by up to 0.047 px with the
#: sub-pixel phase (a blob's centroid), Lanczos-4 by 0.015 px, bilinear by the 1/32-px map
#: quantisation only. In the flows (``demo --seed N``, phone ISP on, seeds 0–3) the full-flow
#: median / p90 go 0.57 / 0.79, 0.51 / 0.81, 0.46 / 0.87, 0.47 / 0.77 % (bilinear) → 0.35 / 0.66,
#: 0.50 / 0.81, 0.50 / 0.74, 0.58 / 0.85 % (Lanczos-4): a small gain on average, within the
#: seeds' spread; the real pair decides. Lanczos-4: the best on it and the smallest phase error.
DEFAULT_INTERPOLATION = "lanczos4"
_DTYPES = (np.uint8, np.uint16, np.float32)


def _grid(n: int, step: int) -> Array:
    """Nodes −step, 0, step, … up to the first one ≥ n − 1 + step (one node beyond each side)."""
    return (np.arange(int(np.ceil((n - 1) / step)) + 3, dtype=np.float64) - 1) * step


def _spline_grid(
    spline: RectBivariateSpline, y: Array, x: Array, design: dict[str, Any] | None = None
) -> NDArray[np.float32]:
    """``spline(y, x)`` on the grid y × x, float32 (len(y), len(x)): the same values as
    FITPACK's grid evaluation (within 1e-12 px) from the sparse B-spline design matrices,
    By · C · Bxᵀ (four non-zeros per row), ~4× faster for a map (issue #18: the window's maps
    are built per capture).

    ``design``: a dict the design matrices are kept in and taken from for splines with the
    same knots evaluated on the same y × x (map_x and map_y of one map: ~0.3 ms each at
    12 MP; the same matrices, so the same values)."""
    ty, tx, coef = spline.tck
    kx, ky = spline.degrees
    c = np.asarray(coef).reshape(len(ty) - kx - 1, len(tx) - ky - 1)
    d = design if design is not None else {}
    same = "ty" in d and np.array_equal(d["ty"], ty) and np.array_equal(d["tx"], tx)
    if not (same and d["k"] == (kx, ky)):
        d.update(ty=ty, tx=tx, k=(kx, ky),
                 by=BSpline.design_matrix(y, ty, kx, extrapolate=True),
                 bx=BSpline.design_matrix(x, tx, ky, extrapolate=True))
    return np.ascontiguousarray((d["bx"] @ (d["by"] @ c).T).T, dtype=np.float32)


def build_map(
    raw: Camera, rect: Camera, R_rect_raw: Array, step: int
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Remap maps (map_x, map_y) of one camera, float32 (H', W').

    Three levels: the exact point map on nodes every ``step`` pixels; a bicubic spline through
    them evaluated every 2 pixels; OpenCV's bilinear ×2 upsampling of that (float weights,
    error ≤ f''/2 px, negligible for a lens map).

    Parameters
    ----------
    raw, rect : Camera
        The raw camera and its rectified camera.
    R_rect_raw : ndarray, shape (3, 3)
        Raw camera frame → rectified frame.
    step : int
        Coarse-grid spacing in rectified pixels; 1 (or an image under 4 steps a side)
        evaluates the exact map at every pixel.
    """
    w, h = rect.size
    if step <= 1 or min(w, h) < 4 * step:
        grid = np.stack(np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float)), -1)
        m = from_rectified(raw, rect, R_rect_raw, grid)
        valid = np.isfinite(m).all(axis=-1)
        return (
            np.where(valid, m[..., 0], INVALID).astype(np.float32),
            np.where(valid, m[..., 1], INVALID).astype(np.float32),
        )
    gx, gy = _grid(w, step), _grid(h, step)
    m = from_rectified(raw, rect, R_rect_raw, np.stack(np.meshgrid(gx, gy), axis=-1))
    ok = np.isfinite(m).all(axis=-1)
    if not ok.any():
        full = np.full((h, w), INVALID, dtype=np.float32)
        return full, full.copy()
    if not ok.all():  # fill holes with the nearest valid node so the spline stays tame
        idx = ndimage.distance_transform_edt(~ok, return_distances=False, return_indices=True)
        m = m[idx[0], idx[1]]
    # Half-resolution nodes at 2i − 1.5 so that cv2.resize(×2) puts them on pixel centres.
    nx, ny = (w + 1) // 2 + 2, (h + 1) // 2 + 2
    fx, fy = 2.0 * np.arange(nx) - 1.5, 2.0 * np.arange(ny) - 1.5
    out: list[NDArray[np.float32]] = []
    design: dict[str, Any] = {}  # both splines' knots are the grid's: one pair of matrices
    for c in range(2):
        half = _spline_grid(RectBivariateSpline(gy, gx, m[..., c]), fy, fx, design)
        full = cv2.resize(half, (2 * nx, 2 * ny), interpolation=cv2.INTER_LINEAR)
        out.append(full[2 : 2 + h, 2 : 2 + w])
    # A pixel is valid when its grid cell and the cells around it had valid corners (the
    # spline reaches one node further than the cell).
    if ok.all():
        return out[0], out[1]
    node_ok = ndimage.binary_erosion(ok, np.ones((3, 3), bool), border_value=1)
    cell_ok = node_ok[:-1, :-1] & node_ok[1:, :-1] & node_ok[:-1, 1:] & node_ok[1:, 1:]
    iy = np.minimum((np.arange(h) + step) // step, cell_ok.shape[0] - 1)
    ix = np.minimum((np.arange(w) + step) // step, cell_ok.shape[1] - 1)
    valid = cell_ok[np.ix_(iy, ix)]
    out[0][~valid] = INVALID
    out[1][~valid] = INVALID
    return out[0], out[1]


def check_image(image: Any, role: str) -> NDArray[Any]:
    """Validate one raw image (shape and dtype; :func:`check_pair` checks sizes).

    Raises
    ------
    ShapeError
        Not (H, W) or (H, W, C), or empty.
    InputError
        A dtype other than uint8, uint16 or float32.
    """
    img = np.asarray(image)
    if img.ndim not in (2, 3) or img.size == 0:
        raise ShapeError(
            f"the {role} image must be a non-empty (H, W) or (H, W, C) array, got shape {img.shape}"
        )
    if img.dtype.type not in _DTYPES:
        raise InputError(
            f"the {role} image has dtype {img.dtype}; cv2.remap takes uint8, uint16 or float32 "
            "(convert with .astype(np.float32))"
        )
    return img


def check_pair(
    image_wide: Any, image_tele: Any, wide: Camera, tele: Camera
) -> tuple[NDArray[Any], NDArray[Any]]:
    """Validate a raw pair against the calibration (sizes must be the calibrated ones)."""
    images = (check_image(image_wide, "wide"), check_image(image_tele, "tele"))
    got = [(img.shape[1], img.shape[0]) for img in images]
    want = [wide.size, tele.size]
    if got != want:
        hint = ""
        if got[0] != got[1] and want[0] == want[1]:
            hint = " (the two images differ in size but the calibration's cameras do not)"
        elif got[0] == want[1] and got[1] == want[0]:
            hint = " (wide and tele look swapped: pass WIDE first, then TELE)"
        raise InputError(
            f"the images are wide {got[0][0]}×{got[0][1]} and tele {got[1][0]}×{got[1][1]} px "
            f"but the calibration is for wide {want[0][0]}×{want[0][1]} and tele "
            f"{want[1][0]}×{want[1][1]} px{hint}; use the images the calibration was made for, "
            "or rescale the calibration (Camera.resized) to these images"
        )
    return images


def antialias_sigma(shrink: float) -> float:
    """The Gaussian σ (raw px) :func:`remap_image` blurs with before shrinking by ``shrink``
    (also sizes :meth:`Rectification.remap`'s source box, which must cover the kernel)."""
    return 0.5 * (shrink - 1.0) if shrink > 1.0 + 1e-6 else 0.0


@dataclass(frozen=True, eq=False)
class Source:
    """A raw image ready to resample: the box of it the maps reach, blurred against aliasing
    when the rectification shrinks it, and the maps shifted into that box (float32 (H', W')).

    :meth:`Rectification.sources` prepares both images once; :meth:`remap` then resamples all
    of the window or a part of it, with any interpolation (the ROI flow's coarse step reads a
    bilinear window, its fine matcher a Lanczos-4 part of it: the same pixels there as
    :meth:`Rectification.remap`, since cv2.remap treats every output pixel on its own).
    """

    image: NDArray[Any]
    map_x: NDArray[np.float32]
    map_y: NDArray[np.float32]

    def remap(
        self, interpolation: str = DEFAULT_INTERPOLATION,
        box: tuple[int, int, int, int] | None = None,
    ) -> NDArray[Any]:
        """The rectified image, or its part ``box`` = (x0, y0, x1, y1) (ends exclusive)."""
        mx, my = self.map_x, self.map_y
        if box is not None:
            x0, y0, x1, y1 = box
            mx, my = mx[y0:y1, x0:x1], my[y0:y1, x0:x1]
        return self._resample(mx, my, interpolation)

    def remap_rows(
        self, rows: NDArray[np.int64], interpolation: str = DEFAULT_INTERPOLATION
    ) -> NDArray[Any]:
        """The rectified image's rows ``rows`` (k,), stacked (k, W'[, C]): the same pixels as
        those rows of :meth:`remap`."""
        return self._resample(self.map_x[rows], self.map_y[rows], interpolation)

    def _resample(
        self, map_x: NDArray[np.float32], map_y: NDArray[np.float32], interpolation: str
    ) -> NDArray[Any]:
        """``cv2.remap`` of the prepared image through (a part of) its maps."""
        if interpolation not in _INTERP:
            raise InputError(
                f"interpolation must be one of {list(_INTERP)}, got {interpolation!r}"
            )
        out = cv2.remap(self.image, map_x, map_y, _INTERP[interpolation],
                        borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        return np.asarray(out)


def source(
    image: NDArray[Any], map_x: NDArray[np.float32], map_y: NDArray[np.float32], shrink: float,
    antialias: bool = True,
) -> Source:
    """:class:`Source` of ``image`` (the box the maps reach, maps already shifted into it):
    blurred by :func:`antialias_sigma` when it is shrunk and ``antialias``."""
    sigma = antialias_sigma(shrink) if antialias else 0.0
    if sigma > 0:
        image = cv2.GaussianBlur(image, (0, 0), sigmaX=sigma, sigmaY=sigma)
    return Source(image, map_x, map_y)


def remap_image(
    image: NDArray[Any],
    map_x: NDArray[np.float32],
    map_y: NDArray[np.float32],
    shrink: float,
    antialias: bool = True,
    interpolation: str = DEFAULT_INTERPOLATION,
) -> NDArray[Any]:
    """Resample ``image`` with the maps, pre-filtered when the rectification shrinks it.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        The raw image (uint8, uint16 or float32).
    map_x, map_y : ndarray, float32, shape (H', W')
        From :func:`build_map`.
    shrink : float
        Raw pixels per rectified pixel (f_raw / f_rect); > 1 means downscaling.
    antialias : bool
        Gaussian blur σ = (shrink − 1)/2 raw pixels first when shrink > 1 (scikit-image's
        ``rescale`` rule), against aliasing of the tele's fine texture.
    interpolation : {"lanczos4", "cubic", "linear"}
        OpenCV's interpolation (:data:`DEFAULT_INTERPOLATION` says why Lanczos-4 is the default).
    """
    if interpolation not in _INTERP:
        raise InputError(f"interpolation must be one of {list(_INTERP)}, got {interpolation!r}")
    return source(image, map_x, map_y, shrink, antialias).remap(interpolation)
