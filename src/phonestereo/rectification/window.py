"""The rectified window: which part of the rectified plane becomes the output images.

The window is the bounding box of a footprint — the border of the tele image (``fov="shared"``),
of the wide image (``fov="wide"``) or of a wide ROI — mapped into the rectified plane through
the rotation only (points at infinity; the disparity of near points shifts the tele by up to
d_max, which ``margin_px`` can cover, as the thesis's crop is "correct up to the difference in
disparity"), clipped to the wide's own footprint. Both rectified cameras share it, so
d = x_wide − x_tele needs no principal-point offset.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from phonestereo.errors import InputError, PhysicsError
from phonestereo.geometry import Camera
from phonestereo.geometry.checks import Array
from phonestereo.rectification.options import RectifyOptions
from phonestereo.rectification.points import to_rectified

MAX_SIDE_PX = 30000
_EPS = 1e-6


def border_pixels(x: float, y: float, w: float, h: float, n: int = 64) -> Array:
    """Points (4n, 2) along the outer edges of the pixel block [x, x+w) × [y, y+h)."""
    t = np.linspace(0.0, 1.0, n, endpoint=False)
    x0, y0, x1, y1 = x - 0.5, y - 0.5, x + w - 0.5, y + h - 0.5
    return np.concatenate(
        [
            np.stack([x0 + (x1 - x0) * t, np.full(n, y0)], axis=-1),
            np.stack([np.full(n, x1), y0 + (y1 - y0) * t], axis=-1),
            np.stack([x1 - (x1 - x0) * t, np.full(n, y1)], axis=-1),
            np.stack([np.full(n, x0), y1 - (y1 - y0) * t], axis=-1),
        ]
    )


def check_roi(roi: tuple[int, int, int, int], wide: Camera) -> None:
    """Raise :class:`InputError` unless the ROI lies inside the wide image."""
    x, y, w, h = roi
    W, H = wide.size
    if x < 0 or y < 0 or x + w > W or y + h > H:
        raise InputError(
            f"roi [x, y, w, h] = {list(roi)} lies outside the {W}×{H} wide image; give it in raw "
            f"wide pixels with x, y >= 0, x + w <= {W} and y + h <= {H}"
        )


def _bbox(points: Array, what: str) -> tuple[float, float, float, float]:
    ok = np.isfinite(points).all(axis=-1)
    if ok.sum() < 3:
        raise PhysicsError(
            f"the {what} does not map into the rectified view (rays behind the camera or "
            "outside the lens field); check the calibration's rotation and lens coefficients"
        )
    p = points[ok]
    return float(p[:, 0].min()), float(p[:, 1].min()), float(p[:, 0].max()), float(p[:, 1].max())


def place_window(
    template: Camera,
    cameras: dict[str, tuple[Camera, Array]],
    options: RectifyOptions,
) -> Camera:
    """The rectified camera: ``template`` with its size and principal point set to the window.

    Parameters
    ----------
    template : Camera
        The rectified camera with the window's origin still undecided (its size is ignored).
    cameras : {"wide": (Camera, R_rect_wide), "tele": (Camera, R_rect_tele)}
        The raw cameras and their rectifying rotations.
    options : RectifyOptions
        ``fov``, ``roi``, ``margin_px`` and ``size``.

    Raises
    ------
    InputError
        An ROI outside the wide image.
    PhysicsError
        A footprint that does not map (bad calibration), an empty overlap, or a window larger
        than :data:`MAX_SIDE_PX`.
    """
    wide, R_wide = cameras["wide"]
    tele, R_tele = cameras["tele"]
    border = border_pixels(0, 0, *wide.size)
    if options.roi is not None:
        check_roi(options.roi, wide)
        # the wide's border and the ROI's in one call (each point is mapped on its own)
        roi_border = border_pixels(*options.roi)
        pts = to_rectified(wide, template, R_wide, np.concatenate([border, roi_border]))
        clip, box = _bbox(pts[: len(border)], "wide"), _bbox(pts[len(border) :], "ROI")
    else:
        clip = _bbox(to_rectified(wide, template, R_wide, border), "wide")
        if options.fov == "wide":
            box = clip
        else:
            pts = to_rectified(tele, template, R_tele, border_pixels(0, 0, *tele.size))
            box = _bbox(pts, "tele image")
    lo = (max(box[0], clip[0]), max(box[1], clip[1]))
    hi = (min(box[2], clip[2]), min(box[3], clip[3]))
    if lo[0] >= hi[0] or lo[1] >= hi[1]:
        raise PhysicsError(
            "the tele's field of view does not overlap the wide's in the rectified view; "
            "check T_tele_wide (rotation in radians, translation in metres)"
        )
    # Pixel centres i whose pixel [i − 0.5, i + 0.5] touches the box.
    m = options.margin_px
    x0, y0 = (math.floor(v + 0.5 + _EPS) - m for v in lo)
    x1, y1 = (math.ceil(v - 0.5 - _EPS) + m for v in hi)
    if options.size is not None:
        w, h = options.size
        x0 = round((x0 + x1) / 2 - (w - 1) / 2)
        y0 = round((y0 + y1) / 2 - (h - 1) / 2)
    else:
        w, h = x1 - x0 + 1, y1 - y0 + 1
    if max(w, h) > MAX_SIDE_PX:
        raise PhysicsError(
            f"the rectified window would be {w}×{h} px; lower `scale` or use fov='shared' "
            "(or check the calibration: a huge window means a wrong rotation or focal length)"
        )
    return replace(template, size=(w, h), cx=template.cx - x0, cy=template.cy - y0)
