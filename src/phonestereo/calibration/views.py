"""Observations a calibration is made from: board views with labelled corners (thesis §1.3.2)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from phonestereo.errors import InputError, ShapeError


@dataclass(frozen=True, eq=False)
class BoardView:
    """Labelled corners of one board in one image."""

    #: array_like, shape (N, 3). Corner positions in the board frame, metres (z = 0 for a flat
    #: board; the three-plane chart of §1.3.2 has three planes in one board frame).
    object_points: np.ndarray
    #: array_like, shape (N, 2). Detected pixels (x, y) of the same corners.
    image_points: np.ndarray
    #: array_like of int, shape (N,). Corner identifiers, shared between cameras so wide↔tele pairs
    #: are matched by id.
    ids: np.ndarray
    #: Where the view came from (file name), used in messages.
    name: str = ""

    def __post_init__(self) -> None:
        obj = np.asarray(self.object_points, dtype=np.float64)
        img = np.asarray(self.image_points, dtype=np.float64)
        ids = np.asarray(self.ids, dtype=np.int64).reshape(-1)
        if obj.ndim != 2 or obj.shape[1] != 3:
            raise ShapeError(f"view '{self.name}': object_points must be (N, 3), got {obj.shape}")
        if img.shape != (obj.shape[0], 2):
            raise ShapeError(
                f"view '{self.name}': image_points must be (N, 2) with N = {obj.shape[0]}, "
                f"got {img.shape}"
            )
        if ids.shape[0] != obj.shape[0] or len(np.unique(ids)) != ids.shape[0]:
            raise InputError(f"view '{self.name}': ids must be {obj.shape[0]} unique integers")
        if not (np.isfinite(obj).all() and np.isfinite(img).all()):
            raise InputError(f"view '{self.name}': drop undetected corners instead of NaN")
        for arr in (obj, img, ids):
            arr.setflags(write=False)
        object.__setattr__(self, "object_points", obj)
        object.__setattr__(self, "image_points", img)
        object.__setattr__(self, "ids", ids)

    @property
    def n_points(self) -> int:
        """Number of corners in this view."""
        return int(self.ids.shape[0])

    def subset(self, keep: Any) -> BoardView:
        """The view restricted to a boolean mask or index array."""
        k = np.asarray(keep)
        return BoardView(self.object_points[k], self.image_points[k], self.ids[k], self.name)


def chessboard_object_points(pattern: tuple[int, int], square_m: float) -> np.ndarray:
    """Board-frame corners of a chessboard with ``pattern = (cols, rows)`` inner corners.

    Row-major like OpenCV's ``findChessboardCorners`` order: id = row·cols + col, corner
    (row, col) at (col·square, row·square, 0).

    Examples
    --------
    >>> chessboard_object_points((9, 6), 0.025)[10].tolist()
    [0.025, 0.025, 0.0]
    """
    cols, rows = pattern
    if cols < 2 or rows < 2:
        raise InputError(f"board pattern needs at least 2 x 2 inner corners, got {pattern}")
    if not square_m > 0:
        raise InputError(f"square size must be positive (metres), got {square_m}")
    grid = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2).astype(np.float64) * float(square_m)
    return np.concatenate([grid, np.zeros((grid.shape[0], 1))], axis=1)
