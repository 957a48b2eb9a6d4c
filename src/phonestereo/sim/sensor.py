"""The image sensor of the virtual module: shot + read noise, gain, quantisation, JPEG.

See docs/architecture.md.

Model, per pixel of radiance ``ρ ∈ [0, 1]`` (scene reflectance × illumination)::

    mean electrons    μ = ρ · exposure · full_well_e
    electrons         e = μ + sqrt(μ + read_noise_e²) · n,  n ~ N(0, 1), clipped to [0, full well]
    digital number    DN = round(black_level_dn + e · gain)
    gain              (2^bits − 1 − black_level_dn) / full_well_e
    optional          JPEG encode/decode at ``jpeg_quality`` through OpenCV

The Gaussian is the normal approximation of Poisson shot noise (exact to < 1 % in σ for
μ ≳ 25 e⁻, i.e. anything brighter than the darkest DN) plus Gaussian read noise. The expected
DN standard deviation of a flat patch is therefore ``gain · sqrt(μ + read²)`` before
quantisation, and ``sqrt(that² + 1/12)`` after rounding.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError, PhysicsError, ShapeError

__all__ = ["SensorModel", "capture"]


@dataclass(frozen=True)
class SensorModel:
    """Noise and quantisation parameters of one camera's sensor.

    Examples
    --------
    >>> s = SensorModel()
    >>> round(s.gain_dn_per_e, 5), s.white_level_dn      # 255 DN over 6000 e⁻
    (0.0425, 255)
    >>> round(s.expected_std_dn(0.5), 3)                 # flat grey patch, before rounding
    2.085
    """

    #: Full-well capacity, electrons (> 0).
    full_well_e: float = 6000.0
    #: Read noise standard deviation, electrons (≥ 0).
    read_noise_e: float = 2.5
    #: Black level, DN (≥ 0, below the white level).
    black_level_dn: float = 0.0
    #: Fraction of the full well reached by reflectance 1 (0 < exposure ≤ 1 keeps white below
    #: saturation; larger values clip highlights).
    exposure: float = 0.8
    #: Bits per pixel of the quantised output, 1–16 (uint8 up to 8 bits, else uint16).
    bit_depth: int = 8
    #: OpenCV JPEG quality 1–100 for a compression round trip (8-bit only); None = none.
    jpeg_quality: int | None = None

    def __post_init__(self) -> None:
        for name in ("full_well_e", "exposure"):
            v = float(getattr(self, name))
            if not np.isfinite(v) or v <= 0:
                raise PhysicsError(f"sensor {name} must be a finite positive number, got {v}")
            object.__setattr__(self, name, v)
        for name in ("read_noise_e", "black_level_dn"):
            v = float(getattr(self, name))
            if not np.isfinite(v) or v < 0:
                raise PhysicsError(f"sensor {name} must be finite and >= 0, got {v}")
            object.__setattr__(self, name, v)
        if int(self.bit_depth) != self.bit_depth or not 1 <= int(self.bit_depth) <= 16:
            raise InputError(f"sensor bit_depth must be an integer in 1..16, got {self.bit_depth}")
        object.__setattr__(self, "bit_depth", int(self.bit_depth))
        if self.black_level_dn >= self.white_level_dn:
            raise PhysicsError(
                f"sensor black_level_dn {self.black_level_dn} must be below the white level "
                f"{self.white_level_dn} of a {self.bit_depth}-bit output"
            )
        q = self.jpeg_quality
        if q is not None:
            if int(q) != q or not 1 <= int(q) <= 100:
                raise InputError(f"sensor jpeg_quality must be an integer 1..100 or None, got {q}")
            if self.bit_depth > 8:
                raise InputError(
                    "JPEG needs an 8-bit output: set bit_depth <= 8 or jpeg_quality=None"
                )
            object.__setattr__(self, "jpeg_quality", int(q))

    @property
    def white_level_dn(self) -> int:
        """Largest digital number, 2^bit_depth − 1."""
        return int(2**self.bit_depth - 1)

    @property
    def gain_dn_per_e(self) -> float:
        """Conversion gain, DN per electron (full well → white level)."""
        return (self.white_level_dn - self.black_level_dn) / self.full_well_e

    def expected_mean_dn(self, radiance: float) -> float:
        """Mean DN of a flat patch of ``radiance`` (no clipping, before rounding)."""
        return self.black_level_dn + float(radiance) * self.exposure * self.full_well_e * (
            self.gain_dn_per_e
        )

    def expected_std_dn(self, radiance: float) -> float:
        """Temporal noise σ in DN of a flat patch of ``radiance`` (shot + read, before rounding)."""
        mu = float(radiance) * self.exposure * self.full_well_e
        return self.gain_dn_per_e * float(np.sqrt(mu + self.read_noise_e**2))


def capture(
    radiance: Any,
    rng: np.random.Generator,
    sensor: SensorModel | None = None,
    noise: bool = True,
) -> NDArray[Any]:
    """Turn a rendered radiance image into the sensor's digital image.

    Parameters
    ----------
    radiance : array_like, shape (H, W)
        Radiance, 1 = white paper under nominal light (e.g. ``RenderedView.radiance``); values
        whose electrons exceed the full well saturate, negative values count as 0.
    rng : numpy.random.Generator
        Source of the noise; the output is a pure function of its state.
    sensor : SensorModel, optional
        Sensor parameters (default ``SensorModel()``).
    noise : bool
        False gives the clean quantised image (no shot/read noise; the rng is not used).

    Returns
    -------
    ndarray, shape (H, W), uint8 (bit_depth ≤ 8) or uint16
        Digital numbers.

    Examples
    --------
    >>> img = capture(np.full((2, 2), 0.5), np.random.default_rng(0), noise=False)
    >>> img.tolist()                                     # 0.5 · 0.8 · 255 = 102
    [[102, 102], [102, 102]]
    """
    s = sensor if sensor is not None else SensorModel()
    rad = np.asarray(radiance, dtype=np.float32)
    if rad.ndim != 2:
        raise ShapeError(f"radiance must be a 2-D (H, W) image, got shape {rad.shape}")
    mu = np.maximum(rad, 0.0) * np.float32(s.exposure * s.full_well_e)
    if noise:
        n = rng.standard_normal(mu.shape, dtype=np.float32)
        e = mu + np.sqrt(mu + np.float32(s.read_noise_e**2)) * n
        np.clip(e, 0.0, s.full_well_e, out=e)
    else:
        e = np.minimum(mu, np.float32(s.full_well_e))
    dn = np.rint(e * np.float32(s.gain_dn_per_e) + np.float32(s.black_level_dn))
    np.clip(dn, 0, s.white_level_dn, out=dn)
    out = dn.astype(np.uint8 if s.bit_depth <= 8 else np.uint16)
    if s.jpeg_quality is not None:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, s.jpeg_quality])
        if not ok:  # pragma: no cover - OpenCV always encodes a valid uint8 image
            raise InputError("OpenCV could not JPEG-encode the image")
        out = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
    return out
