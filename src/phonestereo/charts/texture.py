"""A textured plane: band-limited random texture for matching tests on depth scenes.

The texture is white Gaussian noise on a grid of ``feature_m / 6`` texels, low-passed by a
Gaussian of σ = ``feature_m / 4`` (blobs about ``feature_m`` across; the power above a spatial
frequency f is exp(−4π²σ²f²) of the total: 8.5 % above 1/``feature_m``, ~10⁻⁵ above
3/``feature_m``, the grid's Nyquist frequency), mapped smoothly into the printable range
(0.5 ± 0.45·tanh), and evaluated anywhere by cubic B-spline interpolation — a smooth (C²)
function of (u, v), deterministic per ``seed``, with no aliasing to speak of when a camera
samples it at a texel or coarser.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import ndimage

from phonestereo.charts.base import Array, Keypoints, blockwise, check_uv, inside_mask
from phonestereo.errors import InputError

_TEXELS_PER_FEATURE = 6.0
_SIGMA_FEATURES = 0.25
_PAD_TEXELS = 4
_MAX_TEXELS = 40_000_000


@dataclass(frozen=True, eq=False)
class TexturedPlane:
    """A planar object covered by a smooth random texture.

    Examples
    --------
    >>> plane = TexturedPlane((0.5, 0.4), seed=3, feature_m=0.01)
    >>> r = plane.intensity(np.random.default_rng(0).uniform(0, 0.4, (10000, 2)))
    >>> bool(0.45 < r.mean() < 0.55 and 0.1 < r.std() < 0.3 and r.min() > 0.0)
    True
    """

    #: (width, height) of the plane, metres.
    size_m: tuple[float, float] = (1.0, 1.0)
    #: Random seed; the same seed gives the same texture.
    seed: int = 0
    #: Typical blob size, metres (Gaussian low-pass σ = feature_m / 4).
    feature_m: float = 0.01
    #: Approximate standard deviation of the reflectance (mean 0.5, range (0.05, 0.95)).
    contrast: float = 0.2
    #: Short name.
    name: str = "texture"
    _coeffs: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        w, h = (float(s) for s in self.size_m)
        if not (np.isfinite(w) and np.isfinite(h) and w > 0 and h > 0):
            raise InputError(f"size_m must be two positive lengths in metres, got {self.size_m}")
        f = float(self.feature_m)
        if not (np.isfinite(f) and f > 0):
            raise InputError(f"feature_m must be a positive length in metres, got {f}")
        if not 0 < self.contrast <= 0.45:
            raise InputError(f"contrast must be in (0, 0.45], got {self.contrast}")
        texel = f / _TEXELS_PER_FEATURE
        nx = int(np.ceil(w / texel)) + 1 + 2 * _PAD_TEXELS
        ny = int(np.ceil(h / texel)) + 1 + 2 * _PAD_TEXELS
        if nx * ny > _MAX_TEXELS:
            raise InputError(
                f"a {w} × {h} m plane with feature_m = {f} m needs {nx * ny} texels "
                f"(> {_MAX_TEXELS}); use a larger feature_m or a smaller plane"
            )
        noise = np.random.default_rng(self.seed).standard_normal((ny, nx))
        sigma_px = _SIGMA_FEATURES * _TEXELS_PER_FEATURE
        z = ndimage.gaussian_filter(noise, sigma_px, mode="wrap", truncate=5.0)
        z = (z - z.mean()) / z.std()
        refl = 0.5 + 0.45 * np.tanh(z * float(self.contrast) / 0.45)
        coeffs = ndimage.spline_filter(refl, order=3, mode="mirror")
        coeffs.setflags(write=False)
        object.__setattr__(self, "size_m", (w, h))
        object.__setattr__(self, "feature_m", f)
        object.__setattr__(self, "_coeffs", coeffs)

    @property
    def texel_m(self) -> float:
        """Spacing of the texture's control grid, metres."""
        return self.feature_m / _TEXELS_PER_FEATURE

    def intensity(self, uv: Any) -> Array:
        """Reflectance at plane points ``uv`` (..., 2) metres (cubic B-spline); NaN outside."""
        u, v, lead = check_uv(uv)
        return blockwise(self._intensity, u, v).reshape(lead)

    def _intensity(self, u: Array, v: Array) -> Array:
        out = np.full(u.shape, np.nan)
        idx = np.flatnonzero(inside_mask(u, v, self.size_m))
        inv = 1.0 / self.texel_m
        coords = np.stack([v[idx] * inv + _PAD_TEXELS, u[idx] * inv + _PAD_TEXELS])
        vals = ndimage.map_coordinates(self._coeffs, coords, order=3, prefilter=False)
        out[idx] = np.clip(vals, 0.0, 1.0)
        return out

    def keypoints(self) -> dict[str, Keypoints]:
        """``"corners"``: the plane's four corners, ids 0–3 clockwise from the top left."""
        w, h = self.size_m
        uv = np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]])
        return {"corners": Keypoints(np.arange(4)[:, None], uv)}
