"""A phone camera's ISP: grey radiance → Bayer raw with noise → processing → JPEG bytes.

The stages and their parameters are in :mod:`phonestereo.sim.isp_spec`; the sensor's noise
(full well, read noise, exposure) comes from the camera's ``sensor`` block. Everything is
vectorised NumPy and OpenCV on float32 images (demosaicing on the uint16 mosaic; chroma at
half resolution).

:func:`apply_isp` gives the decoded 8-bit BGR image a phone's JPEG decodes to;
:func:`isp_file` the file bytes a capture set stores (``.jpg``, or ``.png`` when the ISP's
``jpeg_quality`` is None); :func:`gray_of_file` the grey image the pipeline reads from those
bytes (the JPEG's luma, as :func:`phonestereo.io.read_gray` decodes it).

Examples
--------
>>> from phonestereo.sim.sensor import SensorModel
>>> rad = np.full((64, 64), 0.5, np.float32)
>>> bgr = apply_isp(rad, IspSpec(), SensorModel(), np.random.default_rng(0), noise=False)
>>> bgr.shape, bgr.dtype.name
((64, 64, 3), 'uint8')
>>> int(np.median(bgr[..., 1]))                    # 0.5 · 0.8 = 0.4 linear → sRGB 0.665 → 170
170
"""

from __future__ import annotations

import functools
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError, ShapeError
from phonestereo.sim.isp_spec import IspSpec
from phonestereo.sim.sensor import SensorModel

__all__ = ["IspSpec", "apply_isp", "gray_of_file", "isp_file", "luma_noise_sigma", "tone_curve"]

F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]

#: OpenCV colour-conversion codes per (CFA pattern, demosaic method). OpenCV ≥ 4.5 names the
#: Bayer codes by the top-left 2×2 block (``COLOR_BayerRGGB2BGR``), checked on a flat colour.
_DEMOSAIC_CODES: dict[tuple[str, str], int] = {
    (p, m): getattr(cv2, f"COLOR_Bayer{p}2BGR{s}")
    for p in ("RGGB", "BGGR", "GRBG", "GBRG")
    for m, s in (("bilinear", ""), ("ea", "_EA"), ("vng", "_VNG"))
}
_LUMA_BGR = np.array([0.114, 0.587, 0.299])  # BT.601 luma weights (JPEG's Y), B, G, R
_CHANNEL = {"R": 0, "G": 1, "B": 2}
_CODES = 1 << 16  # uint16 codes of [0, 1] (the demosaiced mosaic)
_GREY_18 = 0.18  # reference grey of the noise profile (18 % reflectance)


def _knee(gamma: float) -> tuple[float, float]:
    """Knee x0 and linear slope φ of the sRGB-like curve with continuous value and slope."""
    a = 0.055
    x0 = (a / ((1 + a) * (1 - 1 / gamma))) ** gamma
    return x0, (1 + a) / gamma * x0 ** (1 / gamma - 1)


def tone_curve(x: Any, gamma: float = 2.4) -> NDArray[np.float64]:
    """The sRGB-like tone curve: ``φ·x`` below the knee x0, ``1.055·x^(1/γ) − 0.055`` above.

    Parameters
    ----------
    x : array_like
        Linear values in [0, 1] (clipped).
    gamma : float
        Exponent γ > 1 (2.4 = sRGB).

    Returns
    -------
    ndarray
        Encoded values in [0, 1], same shape; monotonic, T(0) = 0, T(1) = 1.

    Examples
    --------
    >>> np.round(tone_curve([0.0, 0.18, 1.0]), 4).tolist()     # sRGB: 18 % grey → 0.46
    [0.0, 0.4614, 1.0]
    """
    v = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    x0, phi = _knee(gamma)
    return np.where(v <= x0, phi * v, 1.055 * np.power(v, 1 / gamma) - 0.055)


def _tone_slope(x: float, gamma: float) -> float:
    x0, phi = _knee(gamma)
    return phi if x <= x0 else 1.055 / gamma * x ** (1 / gamma - 1)


def _ccm(k: float) -> NDArray[np.float32]:
    """Colour-correction matrix (1 + k)·I − k/3 (rows sum to 1: greys are unchanged)."""
    return ((1 + k) * np.eye(3) - k / 3).astype(np.float32)


def luma_noise_sigma(isp: IspSpec, sensor: SensorModel, grey: float = _GREY_18) -> float:
    """Luma noise σ after the tone curve (units of full scale) at a grey: the noise profile.

    Shot + read noise of each CFA channel after white balance, through the CCM into BT.601
    luma, times the tone curve's slope; demosaicing and quantisation are neglected (this is
    what a phone's tuning calls the noise profile, the scale of ``denoise_strength``).

    Examples
    --------
    >>> round(255 * luma_noise_sigma(IspSpec(), SensorModel()), 2)   # DN at 18 % grey
    1.38
    """
    fw = sensor.full_well_e
    gains = np.array(isp.wb_gains)
    sens = np.array(isp.channel_sensitivity)
    mu = grey * sensor.exposure * sens * fw  # electrons per channel, R G B
    sigma_lin = gains * np.sqrt(mu + sensor.read_noise_e**2) / fw
    u = _ccm(isp.ccm_strength).T.astype(np.float64) @ _LUMA_BGR[::-1]  # luma weights of R G B
    y_lin = float(np.sum(_LUMA_BGR[::-1] * gains * sens)) * grey * sensor.exposure
    return float(_tone_slope(y_lin, isp.tone_gamma) * np.sqrt(np.sum((u * sigma_lin) ** 2)))


def _cfa_map(pattern: str, shape: tuple[int, ...], values: tuple[float, float, float]) -> F32:
    """Per-pixel value of its CFA colour: ``values`` (R, G, B) tiled on the Bayer pattern."""
    block = np.array([values[_CHANNEL[c]] for c in pattern], np.float32).reshape(2, 2)
    h, w = shape[:2]
    return np.tile(block, ((h + 1) // 2, (w + 1) // 2))[:h, :w]


def _raw(
    rad: F32, isp: IspSpec, sensor: SensorModel, rng: np.random.Generator, noise: bool
) -> NDArray[np.uint16]:
    """The white-balanced mosaic, [0, 1] as uint16 codes: CFA sampling, noise, raw DN, WB."""
    fw = np.float32(sensor.full_well_e)
    mu = np.maximum(rad, 0.0) * _cfa_map(isp.cfa_pattern, rad.shape, isp.channel_sensitivity)
    mu *= np.float32(sensor.exposure) * fw
    if noise:
        e = mu + np.sqrt(mu + np.float32(sensor.read_noise_e**2)) * rng.standard_normal(
            mu.shape, dtype=np.float32
        )
        np.clip(e, 0.0, fw, out=e)
    else:
        e = np.minimum(mu, fw)
    black, white = np.float32(isp.raw_black_level_dn), np.float32(isp.raw_white_level_dn)
    dn = np.rint(e * ((white - black) / fw) + black)
    np.clip(dn, 0, white, out=dn)
    dn -= black
    gain = _cfa_map(isp.cfa_pattern, rad.shape, isp.wb_gains) * ((_CODES - 1) / (white - black))
    out: NDArray[np.uint16] = cv2.multiply(dn, gain, dtype=cv2.CV_16U)  # rounds, saturates
    return out


@functools.lru_cache(maxsize=8)
def _vng_shift(pattern: str) -> tuple[int, int]:
    """The integer (rows, columns) by which this OpenCV's VNG output is shifted against the
    mosaic, measured once on a smooth random texture against bilinear demosaicing.

    OpenCV 4.11's VNG moves its output up by 2 rows (opencv/opencv#27225, fixed upstream by
    #27226); no phone ISP does that, and the simulator would hand the flows a constant offset
    (random-1009, -1011, -1012: +0.3 … +1.7 px). Measured rather than assumed, so a fixed
    OpenCV gives (0, 0)."""
    rng = np.random.default_rng(0)
    tex = cv2.GaussianBlur(rng.uniform(0, 255, (96, 96)).astype(np.float32), (0, 0), 2.5)
    mosaic = cv2.normalize(tex, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    ref = cv2.demosaicing(mosaic, _DEMOSAIC_CODES[(pattern, "bilinear")])[..., 1].astype(np.float32)
    vng = cv2.demosaicing(mosaic, _DEMOSAIC_CODES[(pattern, "vng")])[..., 1].astype(np.float32)
    # ZNCC of the bilinear image's centre over VNG shifts of ±3 px (cv2.matchTemplate)
    score = cv2.matchTemplate(vng[5:-5, 5:-5], ref[8:-8, 8:-8], cv2.TM_CCOEFF_NORMED)
    i, j = np.unravel_index(int(np.argmax(score)), score.shape)
    return int(i) - 3, int(j) - 3


def _demosaic(mosaic: NDArray[np.uint16], isp: IspSpec) -> F32:
    """OpenCV demosaicing of the uint16 mosaic → linear BGR float32 in [0, 1]."""
    code = _DEMOSAIC_CODES[(isp.cfa_pattern, isp.demosaic)]
    if isp.demosaic == "vng":  # OpenCV's VNG takes 8-bit input only
        bgr8 = cv2.demosaicing(cv2.convertScaleAbs(mosaic, alpha=255 / (_CODES - 1)), code)
        dy, dx = _vng_shift(isp.cfa_pattern)
        if dy or dx:  # undo this OpenCV's shift (edge rows/columns replicated)
            shift = np.array([[1, 0, -dx], [0, 1, -dy]], dtype=np.float32)
            bgr8 = cv2.warpAffine(bgr8, shift,
                                  (bgr8.shape[1], bgr8.shape[0]), flags=cv2.INTER_NEAREST,
                                  borderMode=cv2.BORDER_REPLICATE)
        return bgr8.astype(np.float32) * np.float32(1 / 255)
    bgr16 = cv2.demosaicing(mosaic, code)
    return bgr16.astype(np.float32) * np.float32(1 / (_CODES - 1))


def _tone(lin: F32, gamma: float) -> F32:
    """:func:`tone_curve` on float32 images: the power branch is concave and the linear branch
    is its tangent through the origin, so the curve is their minimum."""
    _, phi = _knee(gamma)
    x = np.clip(lin, 0.0, 1.0)
    p = cv2.pow(x, 1.0 / gamma)
    out: F32 = cv2.min(cv2.addWeighted(p, 1.055, p, 0.0, -0.055), x * np.float32(phi))
    return out


def process(mosaic: NDArray[np.uint16], isp: IspSpec, sensor: SensorModel) -> U8:
    """Every ISP stage after the sensor's and before the JPEG encoder: the white-balanced
    mosaic (H, W) of :func:`_raw` → 8-bit BGR (H, W, 3).

    ``isp`` and ``sensor`` are those of :func:`apply_isp`. Luma is processed at full
    resolution, chroma at half resolution (as phone ISPs and JPEG's 4:2:0 do; chroma is linear
    in the toned RGB, so area-downsampling the RGB first gives the same chroma).
    """
    h, w = mosaic.shape
    lin = _demosaic(mosaic, isp)
    if isp.ccm_strength > 0:
        lin = cv2.transform(lin, _ccm(isp.ccm_strength))
    tone = _tone(lin, isp.tone_gamma)
    y = cv2.transform(tone, _LUMA_BGR[None].astype(np.float32))  # BT.601 luma, (H, W)
    if isp.denoise_strength > 0:
        sigma = float(isp.denoise_strength * luma_noise_sigma(isp, sensor))
        y = cv2.bilateralFilter(y, 0, sigma, isp.denoise_radius_px)
    a = isp.sharpen_amount
    blur = cv2.GaussianBlur(y, (0, 0), isp.sharpen_radius_px) if a > 0 else y
    y8 = cv2.addWeighted(y, 255 * (1 + a), blur, -255 * a, 0.0, dtype=cv2.CV_8U)
    half = cv2.resize(tone, ((w + 1) // 2, (h + 1) // 2), interpolation=cv2.INTER_AREA)
    _, cr, cb = cv2.split(cv2.cvtColor(half, cv2.COLOR_BGR2YCrCb))  # float: zero at 0.5
    sat, chroma = isp.chroma_saturation, []
    for c in (cr, cb):
        if isp.chroma_blur_px > 0:
            c = cv2.GaussianBlur(c, (0, 0), isp.chroma_blur_px / 2)  # σ in half-res pixels
        c8 = cv2.addWeighted(c, 255 * sat, c, 0.0, 128 - 127.5 * sat, dtype=cv2.CV_8U)  # 128 = 0
        chroma.append(cv2.resize(c8, (w, h), interpolation=cv2.INTER_LINEAR))
    out: U8 = cv2.cvtColor(cv2.merge([y8, *chroma]), cv2.COLOR_YCrCb2BGR)
    return out


def isp_file(
    radiance: Any,
    isp: IspSpec,
    sensor: SensorModel,
    rng: np.random.Generator,
    noise: bool = True,
) -> tuple[bytes, str]:
    """The file a phone would store: (bytes, suffix) — JPEG at the ISP's quality, or a PNG.

    Parameters are those of :func:`apply_isp`. The suffix is ``".jpg"`` or ``".png"`` (when
    ``isp.jpeg_quality`` is None).
    """
    rad = np.asarray(radiance, dtype=np.float32)
    if rad.ndim != 2:
        raise ShapeError(f"radiance must be a 2-D (H, W) image, got shape {rad.shape}")
    bgr = process(_raw(rad, isp, sensor, rng, noise), isp, sensor)
    if isp.jpeg_quality is None:
        ok, buf = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_COMPRESSION, 3])
        suffix = ".png"
    else:
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(isp.jpeg_quality)])
        suffix = ".jpg"
    if not ok:  # pragma: no cover - OpenCV always encodes a valid uint8 image
        raise InputError(f"OpenCV could not encode the ISP output as {suffix}")
    return buf.tobytes(), suffix


def apply_isp(
    radiance: Any,
    isp: IspSpec,
    sensor: SensorModel,
    rng: np.random.Generator,
    noise: bool = True,
) -> U8:
    """Run the phone ISP on a rendered radiance image; the decoded 8-bit BGR image.

    Parameters
    ----------
    radiance : array_like, shape (H, W)
        Grey scene radiance, 1 = white paper under nominal light (``RenderedView.radiance``).
    isp : IspSpec
        The camera's ISP parameters.
    sensor : SensorModel
        Full well, read noise and exposure of the sensor (its bit depth, black level and JPEG
        quality are the linear path's and are not used here).
    rng : numpy.random.Generator
        Source of the sensor noise (one standard normal per pixel, drawn first).
    noise : bool
        False: no shot or read noise (the rng is not used).

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
        BGR, as the phone's JPEG decodes (or the lossless ISP output if jpeg_quality is None).
    """
    data, _ = isp_file(radiance, isp, sensor, rng, noise)
    out: U8 = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    return out


def gray_of_file(data: bytes) -> U8:
    """The grey image the pipeline reads from an image file's bytes (``read_gray``'s decode).

    For a JPEG this is its luma plane (libjpeg decodes Y directly); for a PNG, BT.601 luma.
    """
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise InputError("the image bytes do not decode (not a PNG or JPEG)")
    out: U8 = np.ascontiguousarray(img, dtype=np.uint8)
    return out
