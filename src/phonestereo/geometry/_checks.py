"""Shape and value checks shared by the geometry modules (kornia-style, typed errors)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import PhysicsError, ShapeError

Array = NDArray[np.float64]


def as_points(value: Any, dim: int, name: str) -> Array:
    """Return ``value`` as a float64 array whose last axis has length ``dim``.

    Parameters
    ----------
    value : array_like, shape (..., dim)
        Points; leading dimensions broadcast.
    dim : int
        Required length of the last axis (2 for pixels, 3 for camera-frame points).
    name : str
        Name used in the error message.

    Raises
    ------
    ShapeError
        If the last axis is not ``dim`` long.
    """
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0 or arr.shape[-1] != dim:
        raise ShapeError(
            f"{name} must have shape (..., {dim}) (float (x, y{', z' if dim == 3 else ''}) "
            f"per point), got shape {arr.shape}"
        )
    return arr


def as_matrix(value: Any, shape: tuple[int, ...], name: str) -> Array:
    """Return ``value`` as a float64 array of exactly ``shape`` or raise :class:`ShapeError`."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != shape:
        raise ShapeError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ShapeError(f"{name} must be finite, got {arr.tolist()}")
    return arr


def require_positive(value: float, name: str, unit: str = "") -> float:
    """Return ``value`` as float if finite and > 0, else raise :class:`PhysicsError`."""
    v = float(value)
    if not np.isfinite(v) or v <= 0.0:
        raise PhysicsError(
            f"{name} must be a finite positive number{unit and ' in ' + unit}, got {v}"
        )
    return v


def frozen(arr: Array) -> Array:
    """Return a read-only copy (getters never leak writable arrays, docs/conventions.md)."""
    out = np.array(arr, dtype=np.float64, copy=True)
    out.setflags(write=False)
    return out
