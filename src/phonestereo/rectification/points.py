"""Exact point maps between a raw camera and its rectified camera (no image resampling).

Raw → rectified: undistort with the raw camera, rotate the ray by ``R_rect_raw``, project with
the rectified camera (pinhole, or the wide's lens in ``tele-to-wide``). Rectified → raw is the
same chain backwards. Both are exact up to the lens models' Newton undistortion (rounding
level, ``geometry.lens``). Points that no model can map come back NaN: rays behind a camera
and rays beyond a lens's valid field (where the polynomial folds over and would put a second,
false image of the point inside the frame).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from phonestereo.geometry import Camera
from phonestereo.geometry.checks import Array, as_points


def project_valid(camera: Camera, points: Array) -> Array:
    """``camera.project`` with NaN for points outside the lens's valid field, (..., 2) px."""
    with np.errstate(divide="ignore", invalid="ignore"):
        z = points[..., 2]
        xy = points[..., :2] / np.where(z > 0, z, np.nan)[..., None]
    out = camera.normalized_to_pixel(camera.lens.distort(xy))
    radius = camera.lens.valid_radius
    with np.errstate(invalid="ignore"):
        outside = ~(np.hypot(xy[..., 0], xy[..., 1]) < radius)
    out[outside] = np.nan
    return np.asarray(out, dtype=np.float64)


def to_rectified(raw: Camera, rect: Camera, R_rect_raw: Array, q: Any) -> Array:
    """Raw pixels (..., 2) → rectified pixels (..., 2): undistort → rotate → project."""
    rays = raw.unproject(as_points(q, 2, "pixels"))
    return project_valid(rect, rays @ R_rect_raw.T)


def from_rectified(raw: Camera, rect: Camera, R_rect_raw: Array, q: Any) -> Array:
    """Rectified pixels (..., 2) → raw pixels (..., 2): the inverse of :func:`to_rectified`."""
    rays = rect.unproject(as_points(q, 2, "rectified pixels"))
    return project_valid(raw, rays @ R_rect_raw)
