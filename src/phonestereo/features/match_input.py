"""Input checks for the sparse matcher: images, region of interest and the working crop."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError, ShapeError

F32 = NDArray[np.float32]


def as_image(image: Any, name: str) -> NDArray[Any]:
    """``image`` checked and made gray (H, W) from (H, W) or (H, W, 3|4) BGR(A), DN.

    The dtype is kept (the matcher converts only the part it uses to float32).

    Raises
    ------
    InputError
        None, empty or non-finite.
    ShapeError
        Not a 2-D gray or 3/4-channel colour image.

    >>> as_image(np.full((4, 5, 3), 10, np.uint8), "left").shape
    (4, 5)
    """
    if image is None:
        raise InputError(f"{name} image is missing (None); pass a decoded image array")
    img = np.asarray(image)
    if img.size == 0:
        raise InputError(f"{name} image is empty (shape {img.shape}); check that it was read")
    if img.ndim == 3 and img.shape[2] in (3, 4):
        code = cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        img = cv2.cvtColor(img.astype(np.float32), code)
    if img.ndim != 2:
        raise ShapeError(f"{name} image must be (H, W) gray or (H, W, 3) BGR, got {img.shape}")
    if not np.issubdtype(img.dtype, np.number) or np.issubdtype(img.dtype, np.complexfloating):
        raise InputError(f"{name} image must hold real numbers, got dtype {img.dtype}")
    if np.issubdtype(img.dtype, np.floating) and not np.isfinite(img).all():
        raise InputError(f"{name} image has NaN or infinite pixels; replace them first")
    return img


def check_pair(left: F32, right: F32, min_side: int) -> None:
    """Both images the same size and large enough for one window and its search rows."""
    if left.shape != right.shape:
        raise ShapeError(
            f"left {left.shape[::-1]} and right {right.shape[::-1]} images differ in size "
            "(W, H); rectify both to the same size first"
        )
    if min(left.shape) < 2 * min_side + 1:
        raise InputError(
            f"images {left.shape[::-1]} (W, H) are too small: need at least "
            f"{2 * min_side + 1} px a side for the matching window and search band"
        )


def parse_roi(roi: Any, size: tuple[int, int]) -> tuple[int, int, int, int]:
    """(x, y, w, h) of the ROI in left pixels, checked to lie inside the (W, H) image.

    >>> parse_roi(None, (640, 480))
    (0, 0, 640, 480)
    >>> parse_roi("10,20,100,50", (640, 480))
    (10, 20, 100, 50)
    """
    w, h = size
    if roi is None:
        return 0, 0, w, h
    if isinstance(roi, str):
        try:
            vals = [float(v) for v in roi.replace(" ", "").split(",")]
        except ValueError as exc:
            raise InputError(f"roi must be 'x,y,w,h' in pixels, got '{roi}'") from exc
    else:
        vals = [float(v) for v in np.ravel(np.asarray(roi, dtype=np.float64))]
    if len(vals) != 4 or not all(np.isfinite(vals)) or any(v != int(v) for v in vals):
        raise InputError(f"roi must be four integers x, y, w, h (pixels), got {roi!r}")
    x, y, rw, rh = (int(v) for v in vals)
    if rw <= 0 or rh <= 0:
        raise InputError(f"roi width and height must be > 0, got w={rw}, h={rh}")
    if x < 0 or y < 0 or x + rw > w or y + rh > h:
        raise InputError(
            f"roi (x={x}, y={y}, w={rw}, h={rh}) is not inside the {w}×{h} image; "
            f"keep 0 ≤ x, x + w ≤ {w}, 0 ≤ y, y + h ≤ {h}"
        )
    return x, y, rw, rh


def crop_box(
    roi: tuple[int, int, int, int], size: tuple[int, int], dmin: int, dmax: int, margin: int
) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) of the image part the matcher needs for ``roi`` (ends exclusive).

    Left windows need the ROI ± margin; the right search needs columns x − dmax … x − dmin.

    >>> crop_box((100, 50, 200, 100), (640, 480), 0, 64, 20)
    (16, 30, 320, 170)
    """
    x, y, rw, rh = roi
    w, h = size
    x0 = max(min(x, x - dmax) - margin, 0)
    x1 = min(max(x + rw, x + rw - dmin) + margin, w)
    return x0, max(y - margin, 0), x1, min(y + rh + margin, h)
