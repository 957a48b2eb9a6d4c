"""The ``isp`` block of a camera in the module JSON: one phone camera's image signal processor.

A phone never hands out its sensor's linear values: a raw Bayer mosaic goes through an ISP
tuned per camera and comes out as an 8-bit JPEG. :class:`IspSpec` holds the parameters of the
simulated ISP (:func:`phonestereo.sim.isp.apply_isp`); the stages, in the order they run:

1. **CFA** (``cfa_pattern``, ``channel_sensitivity``): the grey scene radiance times each colour
   channel's sensitivity, sampled on the Bayer pattern (one colour per pixel);
2. **raw** (``raw_bit_depth``, ``raw_black_level_dn``): shot + read noise per CFA pixel (the
   camera's ``sensor`` block: full well, read noise, exposure) and quantisation to raw DN;
3. **white balance** (``white_balance_gains``): per-channel gains on the mosaic (before the
   demosaicer, as phone ISPs do, so it interpolates a balanced image);
4. **demosaicing** (``demosaic``): OpenCV's bilinear, edge-aware (EA) or VNG interpolation;
5. **colour correction** (``ccm_strength``): a 3×3 matrix whose rows sum to 1 (greys unchanged)
   with negative off-diagonals, which amplifies and correlates noise as a real CCM does;
6. **tone curve** (``tone_gamma``): the sRGB curve with a free exponent;
7. **denoising** (``denoise_strength``, ``denoise_radius_px``): an edge-preserving bilateral
   filter on the luma, after the tone curve (the YUV-domain denoiser of a phone: the curve makes
   shot noise nearly level-independent, so one range σ fits every grey level);
8. **sharpening** (``sharpen_amount``, ``sharpen_radius_px``): unsharp mask on the luma;
9. **chroma** (``chroma_blur_px``, ``chroma_saturation``): chroma noise reduction (a Gaussian
   blur of Cr and Cb) and saturation;
10. **JPEG** (``jpeg_quality``): OpenCV's encoder, 4:2:0; the capture set stores these bytes.

What each stage does to a stereo matcher is in ``docs/module.md``.

Examples
--------
>>> isp = IspSpec(jpeg_quality=92, sharpen_amount=0.8)
>>> isp.cfa_pattern, isp.raw_white_level_dn
('RGGB', 1023)
>>> round(isp.wb_gains[0], 3)                      # ideal AWB: 1 / red sensitivity
1.818
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from phonestereo.errors import PhysicsError

__all__ = ["CFA_PATTERNS", "DEMOSAIC_METHODS", "IspSpec"]

CFA_PATTERNS: tuple[str, ...] = ("RGGB", "BGGR", "GRBG", "GBRG")
DEMOSAIC_METHODS: tuple[str, ...] = ("bilinear", "ea", "vng")

_Positive3 = tuple[float, float, float]


class IspSpec(BaseModel):
    """One camera's ISP (module docstring for the stage order; ``docs/module.md`` for more)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    #: Colour of the top-left 2×2 pixels, row by row. Phone sensors: mostly RGGB or BGGR (a crop or
    #: flip changes it); only the demosaicer's alignment depends on it.
    cfa_pattern: Literal["RGGB", "BGGR", "GRBG", "GBRG"] = "RGGB"
    #: (float, float, float). Raw response of the R, G, B pixels to a grey (daylight-lit) surface,
    #: relative to the full-well response of the camera's ``sensor`` block; > 0. Typical phone
    #: sensors under daylight: R 0.45–0.6, G 1 (by convention), B 0.6–0.8. The dimmer channels are
    #: noisier after white balance.
    channel_sensitivity: _Positive3 = (0.55, 1.0, 0.7)
    #: Bits of the raw ADC, 8–16; phones: 10 (most) or 12 (large main sensors).
    raw_bit_depth: int = Field(default=10, ge=8, le=16)
    #: Pedestal added before quantisation, raw DN (≥ 0, below the white level); keeps the noise of
    #: black pixels unclipped. Phones: 64 at 10 bits, 256 at 12 bits.
    raw_black_level_dn: float = Field(default=64.0, ge=0)
    #: (float, float, float) or None. R, G, B gains; None = ideal auto white balance on the grey
    #: scene (1 / sensitivity). Typical daylight gains 1.6–2.2 (R), 1 (G), 1.3–1.7 (B).
    white_balance_gains: _Positive3 | None = None
    #: OpenCV demosaicing: bilinear, edge-aware (EA) or variable number of gradients (VNG; OpenCV's
    #: VNG takes 8-bit input, so the mosaic is rounded to 8 bits before it). Phone ISPs use
    #: edge-directed methods, closest to "ea".
    demosaic: Literal["bilinear", "ea", "vng"] = "ea"
    #: Colour-correction matrix ``(1 + k)·I − k/3·1`` (rows sum to 1, so greys keep their value); k
    #: ≥ 0. Phone CCMs have off-diagonals of −0.2 to −0.6, i.e. k ≈ 0.4–1.0; it raises the luma
    #: noise a little and the chroma noise a lot.
    ccm_strength: float = Field(default=0.5, ge=0, le=3)
    #: Exponent γ of the sRGB-like curve ``1.055·x^(1/γ) − 0.055`` above a knee, linear below it
    #: (knee and slope make value and slope continuous; γ = 2.4 gives the sRGB knee); in (1, 5].
    #: sRGB is 2.4; phones 2.2–2.6, with local tone mapping on top (not modelled).
    tone_gamma: float = Field(default=2.4, gt=1, le=5)
    #: Range σ of the bilateral luma filter as a multiple of the luma noise σ at 18 % grey that the
    #: sensor model predicts (the phone's noise profile); ≥ 0, 0 = off. Phones: 1–2 on a main camera
    #: in good light, 2–4 on a small-pixel tele or in dim light.
    denoise_strength: float = Field(default=1.5, ge=0, le=20)
    #: Spatial σ of the bilateral filter, pixels (> 0; the window is about ±1.5σ). Phones: 1–2 px at
    #: full resolution.
    denoise_radius_px: float = Field(default=1.5, gt=0, le=10)
    #: Unsharp-mask gain ``Y + a·(Y − G_r * Y)`` on the luma; ≥ 0, 0 = off. Phones: 0.3–1.5 (wide
    #: cameras are sharpened more; 1.8·I − 0.8·G is a strong setting, a = 0.8).
    sharpen_amount: float = Field(default=0.6, ge=0, le=5)
    #: σ of the unsharp mask's Gaussian, pixels (> 0). Phones: 0.7–1.5 px.
    sharpen_radius_px: float = Field(default=1.0, gt=0, le=10)
    #: σ of the Gaussian blur of the chroma planes, pixels (≥ 0, 0 = off). Phones blur chroma hard
    #: (3–8 px): the eye does not see chroma detail, but it sees chroma noise.
    chroma_blur_px: float = Field(default=3.0, ge=0, le=30)
    #: Gain of the chroma planes (≥ 0; 1 = as the CCM left it, 0 = grey). Phones 0.9–1.2.
    chroma_saturation: float = Field(default=1.0, ge=0, le=3)
    #: OpenCV (libjpeg) quality 1–100 of the stored JPEG; None = store a lossless PNG of the ISP
    #: output. Phones: 85–95 (their own quantisation tables; 90–95 in libjpeg terms).
    jpeg_quality: int | None = Field(default=92, ge=1, le=100)
    #: Free text: why these values (the presets say it here).
    notes: str = ""

    @model_validator(mode="after")
    def _physics(self) -> IspSpec:
        for name in ("channel_sensitivity", "white_balance_gains"):
            values = getattr(self, name)
            if values is not None and not all(0 < v <= 10 for v in values):
                raise PhysicsError(
                    f"{name} must be three gains in (0, 10] (R, G, B), got {list(values)}"
                )
        if self.raw_black_level_dn >= self.raw_white_level_dn / 2:
            raise PhysicsError(
                f"raw_black_level_dn {self.raw_black_level_dn} must be below half the "
                f"{self.raw_bit_depth}-bit white level {self.raw_white_level_dn} "
                "(phones: 64 at 10 bits)"
            )
        return self

    @property
    def raw_white_level_dn(self) -> int:
        """Largest raw DN, 2^raw_bit_depth − 1."""
        return int(2**self.raw_bit_depth - 1)

    @property
    def wb_gains(self) -> _Positive3:
        """The white-balance gains used (R, G, B): given, or 1 / sensitivity (ideal AWB)."""
        if self.white_balance_gains is not None:
            return self.white_balance_gains
        r, g, b = self.channel_sensitivity
        return (1.0 / r, 1.0 / g, 1.0 / b)
