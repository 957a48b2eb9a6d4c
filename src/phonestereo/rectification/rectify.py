"""The :class:`Rectification` of a wide/tele rig in one of the thesis's three modes.

Thesis §1.3.3 (``tele-to-wide``), §3.2 fix 2 (``undistort-both``), §3.3 (``canonical``); the modes
are described in :mod:`phonestereo.rectification.options`. Conventions (docs/conventions.md): after
rectification d = x_wide − x_tele > 0 in front and e = y_wide − y_tele; the tele centre is on the
rectified +x axis side. A vertical-baseline module is quarter-turned (its rectified images have
width and height swapped; :mod:`~phonestereo.rectification.frames`).

Point rectification is exact (undistort → rotate → project, no resampling) and reproduces what
each mode's images show, including ``tele-to-wide``'s distortion mismatch: there a tele pixel
goes to where the *wide* camera, moved to the tele's centre, would see the point (the wide's
lens and focal length, the wide's orientation), and a wide pixel only moves by the integer crop
(and the quarter turn).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import ShapeError
from phonestereo.features._threads import background
from phonestereo.geometry import Camera, Rig, depth_from_disparity
from phonestereo.geometry.checks import Array, as_points, frozen
from phonestereo.rectification import frames, maps
from phonestereo.rectification.options import Mode, RectifyOptions, check_mode
from phonestereo.rectification.points import from_rectified, to_rectified
from phonestereo.rectification.window import place_window


@dataclass(frozen=True, eq=False)
class Rectification:
    """A rectified wide/tele pair: rotations, rectified cameras, point and image maps.

    Build it with :meth:`from_rig`. Attributes are read-only.

    Examples
    --------
    A folded ×3 module, tele 12 mm below the wide: a point 2 m in front of the wide gives
    d = f·B/Z = 1500 · 0.012 / 2 = 9 px along the rectified x axis, and the rectified images
    are portrait (the tele's 2000×1500 view at the wide's scale, turned by 90°).

    >>> from phonestereo.geometry import Transform
    >>> wide = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
    >>> rig = Rig(wide, wide.scaled(3.0), Transform.from_rotvec([0, 0, 0], [0, -0.012, 0]))
    >>> rect = Rectification.from_rig(rig, "canonical")
    >>> q_wide, q_tele = rig.project([[0.05, -0.02, 2.0]])
    >>> d, e = rect.disparity(q_wide, q_tele)
    >>> round(float(d[0]), 9), round(float(e[0]), 9), rect.wide_rect.size
    (9.0, 0.0, (501, 667))
    >>> round(float(rect.depth(d)[0]), 9)
    2.0
    """

    #: {"tele-to-wide", "undistort-both", "canonical"}.
    mode: Mode
    #: The calibration it was built from.
    rig: Rig
    options: RectifyOptions
    #: ``R_rect_wide``, ``R_rect_tele``: ndarray, shape (3, 3). Wide / tele camera frame → rectified
    #: frame (directions).
    R_rect_wide: Array
    #: See ``R_rect_wide`` above.
    R_rect_tele: Array
    #: ``wide_rect``, ``tele_rect``: The rectified cameras (same K and size, the tele's c_y moved
    #: by ``options.tele_row_shift_px``; pinhole except in ``tele-to-wide``, where both carry the
    #: wide's lens).
    wide_rect: Camera
    #: See ``wide_rect`` above.
    tele_rect: Camera
    #: k of the k·90° turn about the optical axis that puts the baseline nearest +x (for
    #: ``canonical`` the nearest such turn, contained in R_rect_wide).
    quarter_turns: int
    _cache: dict[tuple[str, int], tuple[NDArray[np.float32], NDArray[np.float32]]] = field(
        default_factory=dict, repr=False
    )

    def __post_init__(self) -> None:
        check_mode(self.mode)
        for name in ("R_rect_wide", "R_rect_tele"):
            r = np.asarray(getattr(self, name), dtype=np.float64)
            if r.shape != (3, 3) or not np.allclose(r @ r.T, np.eye(3), atol=1e-9):
                raise ShapeError(f"{name} must be a 3×3 rotation matrix")
            object.__setattr__(self, name, frozen(r))

    # --- construction ---------------------------------------------------------------------
    @classmethod
    def from_rig(
        cls, rig: Rig, mode: str = "canonical", options: RectifyOptions | None = None
    ) -> Rectification:
        """Rectify ``rig`` in ``mode``.

        Parameters
        ----------
        rig : Rig
            Wide, tele and T_tele_wide (e.g. ``load_calibration(path).rig``).
        mode : {"tele-to-wide", "undistort-both", "canonical"}
        options : RectifyOptions, optional
            Resolution, window and map grid.

        Raises
        ------
        InputError
            Unknown mode, ROI outside the wide image, a skewed camera to quarter-turn.
        PhysicsError
            A baseline mostly along the optical axis, or a calibration whose views do not
            overlap.
        """
        m = check_mode(mode)
        opts = options or RectifyOptions()
        center = rig.tele_center_in_wide
        k = frames.quarter_turns_for(center)
        R_wide = frames.canonical_rotation(center) if m == "canonical" else frames.quarter_turn(k)
        R_tele = R_wide @ rig.T_tele_wide.R.T
        if m == "tele-to-wide":
            template = frames.quarter_turn_camera(rig.wide, k)
            factor = opts.scale * (rig.zoom if opts.resolution == "tele" else 1.0)
            if factor != 1.0:
                template = template.resized(factor)
        else:
            f = opts.scale * (rig.wide.f if opts.resolution == "wide" else rig.tele.f)
            template = Camera((1, 1), f, f, 0.0, 0.0)
        cams = {"wide": (rig.wide, R_wide), "tele": (rig.tele, R_tele)}
        rect = place_window(template, cams, opts)
        tele_rect = rect.shifted(0.0, opts.tele_row_shift_px) if opts.tele_row_shift_px else rect
        return cls(m, rig, opts, R_wide, R_tele, rect, tele_rect, k)

    def with_tele_rows(self, shift_px: float) -> Rectification:
        """This rectification with the tele's rows moved by ``shift_px`` in all
        (:attr:`RectifyOptions.tele_row_shift_px`; itself when that is unchanged)."""
        if float(shift_px) == self.options.tele_row_shift_px:
            return self
        opts = replace(self.options, tele_row_shift_px=float(shift_px))
        return Rectification.from_rig(self.rig, self.mode, opts)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Rectification:
        """Rebuild from :meth:`to_dict` (from its rig, mode and options)."""
        opts = RectifyOptions(**{k: v for k, v in data["options"].items()})
        return cls.from_rig(Rig.from_dict(data["rig"]), data["mode"], opts)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: mode, f_px, baseline_m, rectified cameras, rotations, options, rig."""
        return {
            "mode": self.mode,
            "f_px": self.f_px,
            "baseline_m": self.baseline_m,
            "quarter_turns": self.quarter_turns,
            "size": list(self.wide_rect.size),
            "tele_center_rect_m": self.tele_center_rect.tolist(),
            "R_rect_wide": self.R_rect_wide.tolist(),
            "R_rect_tele": self.R_rect_tele.tolist(),
            "wide_rect": self.wide_rect.to_dict(),
            "tele_rect": self.tele_rect.to_dict(),
            "options": self.options.to_dict(),
            "rig": self.rig.to_dict(),
        }

    # --- scalars --------------------------------------------------------------------------
    @property
    def tele_center_rect(self) -> Array:
        """Tele optical centre in the rectified frame (3,), metres; (|c|, 0, 0) if canonical."""
        return frozen(self.R_rect_wide @ self.rig.tele_center_in_wide)

    @property
    def baseline_m(self) -> float:
        """B of eq. (4): the tele centre's rectified x coordinate (= |t| in ``canonical``)."""
        return float(self.tele_center_rect[0])

    @property
    def f_px(self) -> float:
        """f of eq. (4): the rectified focal length along x, pixels."""
        return float(self.wide_rect.fx)

    # --- points ---------------------------------------------------------------------------
    def points_wide(self, q: Any) -> Array:
        """Raw wide pixels (..., 2) → rectified pixels (..., 2), exact; NaN if unmappable."""
        return to_rectified(self.rig.wide, self.wide_rect, self.R_rect_wide, q)

    def points_tele(self, q: Any) -> Array:
        """Raw tele pixels (..., 2) → rectified pixels (..., 2), exact; NaN if unmappable."""
        return to_rectified(self.rig.tele, self.tele_rect, self.R_rect_tele, q)

    def unrectify_wide(self, q: Any) -> Array:
        """Rectified wide pixels (..., 2) → raw wide pixels (..., 2): the inverse point map."""
        return from_rectified(self.rig.wide, self.wide_rect, self.R_rect_wide, q)

    def unrectify_tele(self, q: Any) -> Array:
        """Rectified tele pixels (..., 2) → raw tele pixels (..., 2): the inverse point map."""
        return from_rectified(self.rig.tele, self.tele_rect, self.R_rect_tele, q)

    def disparity(
        self, q_wide: Any, q_tele: Any, *, rectified: bool = False
    ) -> tuple[Array, Array]:
        """Disparity d = x_wide − x_tele and non-disparity error e = y_wide − y_tele, pixels.

        Parameters
        ----------
        q_wide, q_tele : array_like, shape (..., 2)
            Matching pixels, raw (default) or already rectified (``rectified=True``).

        Returns
        -------
        d, e : ndarray, shape (...)
            Rectified pixels; d > 0 in front (docs/conventions.md).
        """
        qw = as_points(q_wide, 2, "q_wide")
        qt = as_points(q_tele, 2, "q_tele")
        if qw.shape != qt.shape:
            raise ShapeError(
                f"q_wide and q_tele must have the same shape (one match per row), got "
                f"{qw.shape} and {qt.shape}"
            )
        if not rectified:
            qw, qt = self.points_wide(qw), self.points_tele(qt)
        diff = qw - qt
        return np.asarray(diff[..., 0]), np.asarray(diff[..., 1])

    def depth(self, d: Any) -> Array:
        """Z = f·B/d (eq. 4) along the rectified z axis, metres; NaN for d ≤ 0.

        Exact for ``canonical`` with a perfect calibration; in the rotation-only modes t_z and
        the non-baseline translation make it approximate (§3.3), and in ``tele-to-wide`` the
        lens distortion too.
        """
        return depth_from_disparity(d, self.f_px, self.baseline_m)

    def backproject(self, q_wide_rect: Any, d: Any) -> Array:
        """Rectified wide pixels (..., 2) and disparities (...) → wide-frame points (..., 3), m.

        Z = f·B/d along the rectified ray of each pixel, rotated back into the wide frame
        (R_rect_wideᵀ), so the depth along the wide's own optical axis is ``[..., 2]``.
        """
        rays = self.wide_rect.unproject(as_points(q_wide_rect, 2, "q_wide_rect"))
        z = self.depth(d)
        return np.asarray((rays * z[..., None]) @ self.R_rect_wide, dtype=np.float64)

    # --- images ---------------------------------------------------------------------------
    def _maps(self, role: str, step: int | None) -> tuple[NDArray[np.float32], ...]:
        s = self.options.grid_step_px if step is None else int(step)
        key = (role, s)
        if key not in self._cache:
            raw, rect, R = self._chain(role)
            self._cache[key] = maps.build_map(raw, rect, R, s)
        return self._cache[key]

    def _chain(self, role: str) -> tuple[Camera, Camera, Array]:
        if role == "wide":
            return self.rig.wide, self.wide_rect, self.R_rect_wide
        return self.rig.tele, self.tele_rect, self.R_rect_tele

    def maps_wide(self, step: int | None = None) -> tuple[NDArray[np.float32], ...]:
        """(map_x, map_y), float32 (H', W') raw wide pixels per rectified pixel, for cv2.remap.

        ``step`` overrides ``options.grid_step_px`` (1: exact at every pixel). Pixels with no
        raw source hold :data:`~phonestereo.rectification.maps.INVALID`.
        """
        return self._maps("wide", step)

    def maps_tele(self, step: int | None = None) -> tuple[NDArray[np.float32], ...]:
        """(map_x, map_y) of the tele, as :meth:`maps_wide`."""
        return self._maps("tele", step)

    def remap(
        self, image_wide: Any, image_tele: Any, *, interpolation: str = maps.DEFAULT_INTERPOLATION
    ) -> tuple[NDArray[Any], NDArray[Any]]:
        """Rectify an image pair → (wide_rect, tele_rect), each (H', W'[, C]).

        Raises
        ------
        InputError, ShapeError
            Empty images, a dtype OpenCV cannot remap, or an image whose size is not its
            calibrated camera's (the message names both sizes).
        """
        images = maps.check_pair(image_wide, image_tele, self.rig.wide, self.rig.tele)
        # the tele's maps, blur and remap on the helper thread while this one does the wide's
        # (OpenCV releases the GIL; the same pixels either way)
        tele = background(lambda: self.source("tele", images[1]).remap(interpolation))
        return self.source("wide", images[0]).remap(interpolation), tele.result()

    def sources(self, image_wide: Any, image_tele: Any) -> tuple[maps.Source, maps.Source]:
        """Both raw images prepared for resampling (:class:`~.maps.Source`: the box the maps
        reach, blurred against aliasing once), to remap several times or in parts.

        ``rect.sources(w, t)[i].remap(interpolation)`` is :meth:`remap`'s image i.

        Raises
        ------
        InputError, ShapeError
            As :meth:`remap`.
        """
        images = maps.check_pair(image_wide, image_tele, self.rig.wide, self.rig.tele)
        tele = background(self.source, "tele", images[1])
        return self.source("wide", images[0]), tele.result()

    def source(self, role: str, image: Any) -> maps.Source:
        """One raw image (``role`` "wide" or "tele", checked by :func:`~.maps.check_pair`
        beforehand) prepared for resampling, as in :meth:`sources`."""
        img = np.asarray(image)
        raw, rect, _ = self._chain(role)
        shrink = raw.f / rect.f
        (x0, y0, x1, y1), mx, my = self._source(role, shrink, (img.shape[1], img.shape[0]))
        return maps.source(img[y0:y1, x0:x1], mx, my, shrink, self.options.antialias)

    def prepare(self, role: str) -> None:
        """Build and cache what :meth:`source` needs for an image of ``role`` at its calibrated
        size (the maps, the raw box they reach): image-independent work that a caller can
        start on the helper thread before the images are at hand."""
        raw, rect, _ = self._chain(role)
        self._source(role, raw.f / rect.f, raw.size)

    def _source(
        self, role: str, shrink: float, size: tuple[int, int]
    ) -> tuple[tuple[int, int, int, int], NDArray[np.float32], NDArray[np.float32]]:
        """The raw box (x0, y0, x1, y1) the maps sample and the maps shifted into it (cached).

        When the image is blurred against aliasing (``antialias``, shrink > 1) only this box is
        blurred and remapped: a window rectification samples a part of a 12 MP tele. The box
        holds every tap of every sampled pixel plus the blur's kernel radius, so the result is
        bit-identical to blurring the whole image (the maps move by whole pixels, exact in
        float32; tests/rectification/test_rect_source_box.py).
        """
        key = (f"source-{role}-{size}", int(self.options.antialias and shrink > 1.0 + 1e-6))
        if key not in self._cache:
            mx, my = self._maps(role, None)
            w, h = size
            box = (0, 0, w, h)
            # OpenCV's Gaussian kernel reaches ≤ 4σ + 1 px; Lanczos-4 taps ≤ 4 px.
            m = int(np.ceil(4 * maps.antialias_sigma(shrink))) + 1 + 4 + 1
            n_valid = mx.size
            if key[1] and not _corners_span(mx, my, m, size):
                ok = cv2.compare(mx, float(maps.INVALID), cv2.CMP_NE)  # uint8 mask
                n_valid = cv2.countNonZero(ok)
                if n_valid:
                    (x_lo, x_hi, *_), (y_lo, y_hi, *_) = (cv2.minMaxLoc(a, ok) for a in (mx, my))
                    lo = np.floor([x_lo, y_lo]).astype(int) - m
                    hi = np.ceil([x_hi, y_hi]).astype(int) + m + 1
                    box = (max(int(lo[0]), 0), max(int(lo[1]), 0),
                           min(int(hi[0]), w), min(int(hi[1]), h))
            if box[2] <= box[0] or box[3] <= box[1]:
                box = (0, 0, w, h)
            if box[:2] != (0, 0):
                if n_valid == mx.size:  # no invalid pixel to keep
                    mx, my = mx - np.float32(box[0]), my - np.float32(box[1])
                else:
                    mx = np.where(mx == np.float32(maps.INVALID), mx, mx - np.float32(box[0]))
                    my = np.where(my == np.float32(maps.INVALID), my, my - np.float32(box[1]))
            self._cache[key] = (box, mx, my)  # type: ignore[assignment]
        box, mx, my = self._cache[key]  # type: ignore[misc]
        return box, mx, my


def _corners_span(mx: NDArray[np.float32], my: NDArray[np.float32], margin: int,
                  size: tuple[int, int]) -> bool:
    """True when the maps' valid corner values, ± ``margin``, already reach every image border:
    the box of all values (which holds the corners') is then the whole image (no search)."""
    cx, cy = mx[[0, 0, -1, -1], [0, -1, 0, -1]], my[[0, 0, -1, -1], [0, -1, 0, -1]]
    ok = cx != np.float32(maps.INVALID)
    if not ok.any():
        return False
    cx, cy = cx[ok], cy[ok]
    return bool(cx.min() - margin <= 0 and cy.min() - margin <= 0
                and cx.max() + margin + 1 >= size[0] and cy.max() + margin + 1 >= size[1])
