"""The pinhole-plus-lens camera (thesis §1.1.1, eq. 1–2).

Pixel convention (docs/conventions.md): (x, y) with (0, 0) at the centre of the top-left pixel, so a
``w × h`` image spans x ∈ [−0.5, w − 0.5]. Camera frame: x right, y down, z forward.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from phonestereo.errors import InputError
from phonestereo.geometry.checks import Array, as_matrix, as_points, frozen, require_positive
from phonestereo.geometry.lens import LensModel
from phonestereo.geometry.lens_models import lens_from_dict, make_lens


def _default_lens() -> LensModel:
    return make_lens("opencv5")


@dataclass(frozen=True)
class Camera:
    """Intrinsics of one camera: image size, K (eq. 2) and a lens model.

    Examples
    --------
    >>> cam = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
    >>> cam.project([0.1, 0.0, 2.0]).tolist()     # 1500·0.05 + 999.5
    [1074.5, 749.5]
    """

    #: Image (width, height) in pixels.
    size: tuple[int, int]
    #: ``fx``, ``fy``: Focal lengths in pixels (> 0).
    fx: float
    #: See ``fx`` above.
    fy: float
    #: ``cx``, ``cy``: Principal point in pixels.
    cx: float
    #: See ``cx`` above.
    cy: float
    #: Distortion model on normalised coordinates; pinhole ``opencv5`` zeros by default.
    lens: LensModel = field(default_factory=_default_lens)
    #: K[0, 1]; zero for every phone camera (eq. 2), kept for OpenCV round trips.
    skew: float = 0.0

    def __post_init__(self) -> None:
        w, h = (int(v) for v in self.size)
        if w <= 0 or h <= 0 or (w, h) != tuple(self.size):
            raise InputError(
                f"camera size must be two positive integers (width, height), got {self.size}"
            )
        object.__setattr__(self, "size", (w, h))
        object.__setattr__(self, "fx", require_positive(self.fx, "camera fx", "pixels"))
        object.__setattr__(self, "fy", require_positive(self.fy, "camera fy", "pixels"))
        for name in ("cx", "cy", "skew"):
            v = float(getattr(self, name))
            if not np.isfinite(v):
                raise InputError(f"camera {name} must be finite, got {v}")
            object.__setattr__(self, name, v)
        if not isinstance(self.lens, LensModel):
            raise InputError(f"camera lens must be a LensModel, got {type(self.lens).__name__}")

    # --- construction ---------------------------------------------------------------------
    @classmethod
    def from_matrix(cls, size: tuple[int, int], K: Any, lens: LensModel | None = None) -> Camera:
        """Build from a 3×3 camera matrix K (eq. 2)."""
        k = as_matrix(K, (3, 3), "K")
        if (
            abs(k[1, 0]) > 1e-12
            or abs(k[2, 0]) > 1e-12
            or abs(k[2, 1]) > 1e-12
            or abs(k[2, 2] - 1) > 1e-12
        ):
            raise InputError(f"K must be upper triangular with K[2, 2] = 1, got {k.tolist()}")
        return cls(size, k[0, 0], k[1, 1], k[0, 2], k[1, 2], lens or _default_lens(), k[0, 1])

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Camera:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls.from_matrix(tuple(data["size"]), data["K"], lens_from_dict(data["lens"]))
        except KeyError as exc:
            raise InputError(f"camera entry needs 'size', 'K' and 'lens'; missing {exc}") from exc

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: size, K (3×3 list) and lens."""
        return {"size": list(self.size), "K": self.K.tolist(), "lens": self.lens.to_dict()}

    # --- getters --------------------------------------------------------------------------
    @property
    def K(self) -> Array:
        """Camera matrix (3, 3), a read-only copy."""
        return frozen(
            np.array([[self.fx, self.skew, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])
        )

    @property
    def width(self) -> int:
        """Image width in pixels."""
        return self.size[0]

    @property
    def height(self) -> int:
        """Image height in pixels."""
        return self.size[1]

    @property
    def f(self) -> float:
        """Mean focal length (fx + fy) / 2 in pixels, the f of eq. (4)."""
        return 0.5 * (self.fx + self.fy)

    # --- copies for focus breathing, heating and sag --------------------------------------
    def scaled(self, s: float) -> Camera:
        """Focus breathing: the same camera with fx, fy multiplied by ``s`` (eq. 8, K·D(s))."""
        s = require_positive(s, "focal scale s")
        return replace(self, fx=self.fx * s, fy=self.fy * s, skew=self.skew * s)

    def shifted(self, dx: float, dy: float) -> Camera:
        """The same camera with the principal point moved by (dx, dy) pixels."""
        return replace(self, cx=self.cx + float(dx), cy=self.cy + float(dy))

    def with_lens(self, lens: LensModel) -> Camera:
        """The same camera with another lens model."""
        return replace(self, lens=lens)

    def resized(self, factor: float) -> Camera:
        """The camera of the image resized by ``factor`` (pixel-centre convention kept)."""
        factor = require_positive(factor, "resize factor")
        w, h = (max(1, round(v * factor)) for v in self.size)
        return replace(
            self,
            size=(w, h),
            fx=self.fx * factor,
            fy=self.fy * factor,
            skew=self.skew * factor,
            cx=(self.cx + 0.5) * factor - 0.5,
            cy=(self.cy + 0.5) * factor - 0.5,
        )

    # --- projection -----------------------------------------------------------------------
    def normalized_to_pixel(self, xy_d: Any) -> Array:
        """Apply K to distorted normalised coordinates, shape (..., 2) → pixels (..., 2)."""
        p = as_points(xy_d, 2, "xy_d")
        x = self.fx * p[..., 0] + self.skew * p[..., 1] + self.cx
        y = self.fy * p[..., 1] + self.cy
        return np.stack([x, y], axis=-1)

    def pixel_to_distorted(self, q: Any) -> Array:
        """Apply K⁻¹ to pixels, shape (..., 2) → distorted normalised coordinates (..., 2)."""
        p = as_points(q, 2, "pixels")
        yn = (p[..., 1] - self.cy) / self.fy
        xn = (p[..., 0] - self.cx - self.skew * yn) / self.fx
        return np.stack([xn, yn], axis=-1)

    def project(self, points: Any) -> Array:
        """Project camera-frame points to pixels (eq. 1 with distortion).

        Parameters
        ----------
        points : array_like, shape (..., 3)
            Camera-frame points in metres.

        Returns
        -------
        ndarray, shape (..., 2)
            Pixel coordinates (x, y); NaN for points with Z ≤ 0.
        """
        p = as_points(points, 3, "points")
        z = p[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = p[..., :2] / np.where(z > 0, z, np.nan)[..., None]
        return self.normalized_to_pixel(self.lens.distort(xy))

    def pixel_to_normalized(self, q: Any) -> Array:
        """Undistorted normalised coordinates (X/Z, Y/Z) of pixels, shape (..., 2).

        NaN where the lens model cannot be inverted (outside its valid field).
        """
        return self.lens.undistort(self.pixel_to_distorted(q))

    def unproject(self, q: Any) -> Array:
        """Rays through pixels, shape (..., 2) → (..., 3) with Z = 1.

        Examples
        --------
        >>> cam = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
        >>> (cam.unproject([1074.5, 749.5]) * 2.0).tolist()
        [0.1, 0.0, 2.0]
        """
        xy = self.pixel_to_normalized(q)
        return np.concatenate([xy, np.ones((*xy.shape[:-1], 1))], axis=-1)

    def contains(self, q: Any, margin: float = 0.0) -> Any:
        """Boolean mask (...,) of pixels inside the image, ``margin`` pixels from the border."""
        p = as_points(q, 2, "pixels")
        w, h = self.size
        lo = -0.5 + margin
        return (
            np.isfinite(p).all(axis=-1)
            & (p[..., 0] >= lo)
            & (p[..., 1] >= lo)
            & (p[..., 0] <= w - 0.5 - margin)
            & (p[..., 1] <= h - 0.5 - margin)
        )
