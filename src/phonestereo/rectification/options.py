"""The three rectification modes of the thesis and the options of a rectification.

Modes
-----
``tele-to-wide`` (§1.3.3, the thesis's usual mode)
    The tele is resampled into the wide's view: the wide's orientation (R of T_tele_wide
    removed), the wide's lens distortion and, by default, the wide's focal length (the tele
    downscaled by the zoom factor); the wide is only cropped to the shared field of view (and
    quarter-turned when the baseline is vertical). The non-baseline translation and the
    different image radius of a point in the two views (§3.2 issue 1) are left in.
``undistort-both`` (§3.2 fix 2)
    Both images undistorted to one pinhole camera in the wide's orientation (quarter turn
    aside); the non-baseline translation (t_y, t_z) is left in.
``canonical`` (§3.3)
    Both rotated so that the full baseline vector, t_y and t_z included, is the x axis, and
    undistorted to one pinhole camera: with a perfect calibration e ≡ 0 at every depth.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from phonestereo.errors import InputError, PhysicsError

Mode = Literal["tele-to-wide", "undistort-both", "canonical"]
MODES: tuple[str, ...] = get_args(Mode)
Resolution = Literal["wide", "tele"]
FieldOfView = Literal["shared", "wide"]


def check_mode(mode: str) -> Mode:
    """Return ``mode`` if it is one of :data:`MODES`, else raise :class:`InputError`."""
    if mode not in MODES:
        raise InputError(f"unknown rectification mode {mode!r}; choose one of {list(MODES)}")
    return mode  # type: ignore[return-value]


@dataclass(frozen=True)
class RectifyOptions:
    """How large and how fine the rectified pair is."""

    #: {"wide", "tele"}. Rectified focal length: the wide's (default; the tele is downscaled by the
    #: zoom, the thesis's choice, and in ``tele-to-wide`` the wide is not resampled at all) or the
    #: tele's ("full resolution": no tele detail lost, the wide upsampled by the zoom). Unlike
    #: OpenCV's stereoRectify, which gives both cameras the mean focal length (×1.5 downsampling of
    #: a ×3 tele *and* ×2 upsampling of the wide), one of the two images is always kept at its
    #: native scale.
    resolution: Resolution = "wide"
    #: Extra factor on that focal length (> 0), e.g. 0.5 for a half-size preview.
    scale: float = 1.0
    #: {"shared", "wide"}. Rectified window: the tele's field of view (the only place with
    #: disparity; default) or the wide's whole field of view.
    fov: FieldOfView = "shared"
    #: (x, y, w, h) or None. A window given in raw wide pixels instead (the manifest's ``roi``);
    #: overrides ``fov``.
    roi: tuple[int, int, int, int] | None = None
    #: Rectified pixels added on every side of the window (≥ 0).
    margin_px: int = 0
    #: (w, h) or None. Force the rectified image size; the window is centred on the one
    #: ``fov``/``roi`` gives.
    size: tuple[int, int] | None = None
    #: Spacing of the coarse grid on which the remap maps are computed exactly before bicubic-spline
    #: interpolation (≥ 1; 1 = exact at every pixel, slow).
    grid_step_px: int = 8
    #: Gaussian pre-filter of an image that the rectification shrinks, σ = (s − 1)/2 raw pixels for
    #: a shrink factor s (scikit-image's rule).
    antialias: bool = True
    #: Rectified rows the tele's image is moved down by (its rectified camera's c_y + this), px:
    #: a known row error e = y_wide − y_tele of the calibration (a learned one, or the coarse
    #: step's) taken out, so that searches over a few rows about e = 0 find it. Disparity (x) is
    #: unchanged; an e measured in this frame is the calibration's e less this.
    tele_row_shift_px: float = 0.0

    def __post_init__(self) -> None:
        if self.resolution not in get_args(Resolution):
            raise InputError(f"resolution must be 'wide' or 'tele', got {self.resolution!r}")
        if self.fov not in get_args(FieldOfView):
            raise InputError(f"fov must be 'shared' or 'wide', got {self.fov!r}")
        s = float(self.scale)
        if not np.isfinite(s) or not 0.01 <= s <= 100:
            raise PhysicsError(f"scale must be a number in [0.01, 100], got {self.scale}")
        object.__setattr__(self, "scale", s)
        shift = float(self.tele_row_shift_px)
        if not np.isfinite(shift):
            raise InputError(f"tele_row_shift_px must be finite, got {self.tele_row_shift_px}")
        object.__setattr__(self, "tele_row_shift_px", shift)
        if self.roi is not None:
            object.__setattr__(self, "roi", _ints(self.roi, 4, "roi (x, y, w, h)"))
            if self.roi[2] <= 0 or self.roi[3] <= 0:
                raise InputError(f"roi width and height must be > 0, got {list(self.roi)}")
        if self.size is not None:
            object.__setattr__(self, "size", _ints(self.size, 2, "size (w, h)"))
            if min(self.size) <= 0:
                raise InputError(f"size must be two positive pixel counts, got {self.size}")
        for name, low in (("margin_px", 0), ("grid_step_px", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < low:
                raise InputError(f"{name} must be an integer >= {low}, got {v!r}")
            object.__setattr__(self, name, int(v))

    def to_dict(self) -> dict[str, object]:
        """JSON-ready dict of the options (``tele_row_shift_px`` only when not 0)."""
        out: dict[str, object] = {
            "resolution": self.resolution,
            "scale": self.scale,
            "fov": self.fov,
            "roi": None if self.roi is None else list(self.roi),
            "margin_px": self.margin_px,
            "size": None if self.size is None else list(self.size),
            "grid_step_px": self.grid_step_px,
            "antialias": self.antialias,
        }
        if self.tele_row_shift_px:
            out["tele_row_shift_px"] = self.tele_row_shift_px
        return out


def _ints(value: object, n: int, name: str) -> tuple[int, ...]:
    try:
        vals = [float(v) for v in value]  # type: ignore[attr-defined]
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be {n} integers, got {value!r}") from exc
    if len(vals) != n or not all(np.isfinite(v) and v == round(v) for v in vals):
        raise InputError(f"{name} must be {n} integers, got {value!r}")
    return tuple(int(v) for v in vals)
