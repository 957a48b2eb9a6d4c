"""The planar-object contract every chart implements (used by the renderer and the detectors).

Chart frame: origin at the chart's top-left corner, u to the right, v down, both in metres;
the chart is the plane z = 0 with z pointing away from the viewer (into the chart), so
(u, v, z) is a right-handed frame like the camera frame (x right, y down, z forward).

``intensity`` is the *linear* reflectance of the printed chart in [0, 1] (black ink ≈ 0.05,
white paper ≈ 0.95): a renderer multiplies it by the illumination, and a renderer that writes
display-referred 8-bit images applies its tone curve (e.g. sRGB) afterwards. The print value
that produces a reflectance is :func:`reflectance_to_print`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError, ShapeError

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Reflectance of black ink and of white paper: the printable range (project defaults).
INK_BLACK = 0.05
PAPER_WHITE = 0.95


@dataclass(frozen=True, eq=False)
class Keypoints:
    """Named ground-truth points of a chart.

    Examples
    --------
    >>> kp = Keypoints([[0, 0], [0, 1]], [[0.05, 0.05], [0.075, 0.05]])
    >>> len(kp), round(kp.uv[1, 0] - kp.uv[0, 0], 6)    # one 25 mm square apart
    (2, 0.025)
    """

    #: array_like of int, shape (N, k). Integer labels of each point, e.g. (row, col) of a
    #: chessboard corner or (face, eye).
    ids: IntArray
    #: array_like of float, shape (N, 2). Chart-plane positions, metres (u right, v down from the
    #: top-left corner).
    uv: Array

    def __post_init__(self) -> None:
        ids = np.asarray(self.ids)
        uv = np.asarray(self.uv, dtype=np.float64)
        if ids.ndim != 2 or (ids.size and not np.issubdtype(ids.dtype, np.integer)):
            raise ShapeError(f"Keypoints.ids must be an (N, k) integer array, got {ids.shape}")
        if uv.ndim != 2 or uv.shape[1] != 2 or uv.shape[0] != ids.shape[0]:
            raise ShapeError(
                f"Keypoints.uv must have shape (N, 2) with N = len(ids) = {ids.shape[0]}, "
                f"got {uv.shape}"
            )
        ids = np.array(ids, dtype=np.int64, copy=True)
        uv = np.array(uv, copy=True)
        ids.setflags(write=False)
        uv.setflags(write=False)
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "uv", uv)

    def __len__(self) -> int:
        return int(self.uv.shape[0])


@runtime_checkable
class Chart(Protocol):
    """A planar object that can be rendered, detected and printed.

    Attributes
    ----------
    name : str
        Short name (``"verification"``, ``"faces"``, ...).
    size_m : (float, float)
        (width, height) of the printed chart, metres.
    """

    @property
    def name(self) -> str: ...

    @property
    def size_m(self) -> tuple[float, float]: ...

    def intensity(self, uv: Any) -> Array:
        """Linear reflectance in [0, 1] at chart points ``uv`` (..., 2) metres; NaN outside."""
        ...

    def keypoints(self) -> dict[str, Keypoints]:
        """The named ground-truth points of the chart."""
        ...


def check_uv(uv: Any) -> tuple[Array, Array, tuple[int, ...]]:
    """Split chart points into flat u and v arrays.

    Parameters
    ----------
    uv : array_like, shape (..., 2)
        Chart-plane points, metres.

    Returns
    -------
    u, v : ndarray, shape (N,)
        Flattened coordinates (N = product of the leading dimensions).
    lead : tuple of int
        The leading shape, to reshape results with.

    Raises
    ------
    ShapeError
        If the last axis is not 2 long.
    """
    arr = np.asarray(uv, dtype=np.float64)
    if arr.ndim == 0 or arr.shape[-1] != 2:
        raise ShapeError(f"uv must have shape (..., 2) (u, v metres per point), got {arr.shape}")
    flat = arr.reshape(-1, 2)
    return flat[:, 0], flat[:, 1], arr.shape[:-1]


#: Points per block in :func:`blockwise` (temporaries of 64 K float64 stay in the CPU cache).
BLOCK_POINTS = 1 << 16


def blockwise(fn: Callable[[Array, Array], Array], u: Array, v: Array) -> Array:
    """Evaluate the vectorised ``fn(u, v) -> (n,)`` over blocks of :data:`BLOCK_POINTS` points.

    Same result as ``fn(u, v)``; several times faster for millions of points because every
    temporary array fits in the cache (the loop is over blocks, never over pixels).
    """
    n = u.shape[0]
    if n <= BLOCK_POINTS:
        return fn(u, v)
    out = np.empty(n, dtype=np.float64)
    for s in range(0, n, BLOCK_POINTS):
        out[s : s + BLOCK_POINTS] = fn(u[s : s + BLOCK_POINTS], v[s : s + BLOCK_POINTS])
    return out


def inside_mask(u: Array, v: Array, size_m: tuple[float, float]) -> NDArray[np.bool_]:
    """True where (u, v) lies on the chart [0, w] × [0, h] (NaN points are outside)."""
    w, h = size_m
    return (u >= 0.0) & (u <= w) & (v >= 0.0) & (v <= h)


def require_reflectance(value: float, name: str) -> float:
    """Return ``value`` as float if it is a reflectance in [0, 1], else raise InputError."""
    r = float(value)
    if not 0.0 <= r <= 1.0:
        raise InputError(f"{name} must be a reflectance in [0, 1], got {r}")
    return r


def srgb_to_linear(value: Any) -> Array:
    """Decode sRGB values in [0, 1] to linear light (IEC 61966-2-1).

    >>> round(float(srgb_to_linear(0.5)), 4)
    0.214
    """
    c = np.clip(np.asarray(value, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(value: Any) -> Array:
    """Encode linear light in [0, 1] as sRGB values in [0, 1] (inverse of :func:`srgb_to_linear`).

    >>> round(float(linear_to_srgb(0.214)), 3)
    0.5
    """
    c = np.clip(np.asarray(value, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def print_to_reflectance(value: Any) -> Array:
    """Reflectance of a printed sRGB grey value in [0, 1]: ink 0.05 at 0, paper 0.95 at 1.

    >>> print_to_reflectance([0.0, 1.0]).tolist()
    [0.05, 0.95]
    """
    return INK_BLACK + (PAPER_WHITE - INK_BLACK) * srgb_to_linear(value)


def reflectance_to_print(value: Any) -> Array:
    """sRGB grey value in [0, 1] that prints as reflectance ``value`` (clipped to the ink range).

    >>> reflectance_to_print([0.05, 0.95]).round(6).tolist()
    [0.0, 1.0]
    """
    r = np.asarray(value, dtype=np.float64)
    return linear_to_srgb((r - INK_BLACK) / (PAPER_WHITE - INK_BLACK))
