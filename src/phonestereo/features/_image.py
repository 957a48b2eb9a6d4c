"""Small image helpers shared by the chart detectors: gray input, pyramid, sampling, noise.

Pyramid convention: level ``L`` halves level ``L − 1`` by 2 × 2 area averaging (OpenCV
``INTER_AREA`` on an even-cropped image), so pixel centre ``x_L`` of level ``L`` sits at
``x_0 = 2^L · x_L + (2^L − 1) / 2`` on level 0 (pixel (0, 0) is the centre of the top-left pixel).
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError, ShapeError

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]


def as_gray_float(image: Any) -> F32:
    """A grayscale float32 copy of ``image`` (H, W) or (H, W, 3|4) (BGR order, as OpenCV reads).

    Raises
    ------
    ShapeError
        Not a 2-D image or a 3/4-channel colour image.
    InputError
        Empty, too small (< 16 px a side) or non-finite.
    """
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        code = cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        img = cv2.cvtColor(img.astype(np.float32), code)
    if img.ndim != 2:
        raise ShapeError(f"image must be (H, W) grayscale or (H, W, 3) BGR, got shape {img.shape}")
    if min(img.shape) < 16:
        raise InputError(f"image is too small to hold a chart: {img.shape}; pass the full image")
    out = np.asarray(img, dtype=np.float32)
    if not np.isfinite(out).all():
        raise InputError("image has NaN or infinite pixels; replace them before detection")
    return out


def level_to_base(points: Any, level: int) -> F64:
    """Pixel (x, y) on pyramid ``level`` → level 0.

    >>> level_to_base([[0.0, 0.0], [10.0, 5.0]], 1).tolist()
    [[0.5, 0.5], [20.5, 10.5]]
    """
    k = float(2**level)
    return np.asarray(points, dtype=np.float64) * k + (k - 1.0) / 2.0


def base_to_level(points: Any, level: int) -> F64:
    """Pixel (x, y) on level 0 → pyramid ``level`` (inverse of :func:`level_to_base`)."""
    k = float(2**level)
    return (np.asarray(points, dtype=np.float64) - (k - 1.0) / 2.0) / k


def pyramid(image: F32, levels: int) -> list[F32]:
    """``[level 0, level 1, ...]``, each the 2 × 2 area mean of the previous (≤ ``levels`` + 1)."""
    out = [image]
    for _ in range(levels):
        prev = out[-1]
        h, w = prev.shape[0] // 2, prev.shape[1] // 2
        if min(h, w) < 32:
            break
        even = prev[: 2 * h, : 2 * w]
        out.append(cv2.resize(even, (w, h), interpolation=cv2.INTER_AREA))
    return out


_MAP_COLS = 4096  # points per row of the remap grid (OpenCV maps stay < SHRT_MAX)


def sample(image: F32, points: Any) -> F32:
    """Bilinear samples of ``image`` at pixel (x, y) ``points`` (..., 2); borders replicated."""
    p = np.asarray(points, dtype=np.float32)
    lead = p.shape[:-1]
    n = int(np.prod(lead))
    if n == 0:
        return np.zeros(lead, dtype=np.float32)
    # cv2.remap needs maps under 32767 rows and columns: lay the points out as a 2-D grid
    cols = min(n, _MAP_COLS)
    rows = -(-n // cols)
    grid = np.zeros((rows * cols, 2), np.float32)
    grid[:n] = p.reshape(-1, 2)
    grid = grid.reshape(rows, cols, 2)
    out = cv2.remap(
        image,
        np.ascontiguousarray(grid[..., 0]),
        np.ascontiguousarray(grid[..., 1]),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )
    return np.asarray(out, dtype=np.float32).reshape(-1)[:n].reshape(lead)


def noise_sigma(image: F32) -> float:
    """Robust temporal-noise σ of ``image`` from horizontal pixel differences (MAD), DN.

    Edges are a small fraction of the differences, so the median ignores them.

    >>> rng = np.random.default_rng(0)
    >>> img = (100 + 2.0 * rng.standard_normal((200, 200))).astype(np.float32)
    >>> round(noise_sigma(img), 1)                         # σ = 2 DN
    2.0
    """
    sub = image[::2]
    d = (sub[:, 1:] - sub[:, :-1]).ravel()
    mad = float(np.median(np.abs(d - np.median(d))))
    return 1.4826 * mad / np.sqrt(2.0)
