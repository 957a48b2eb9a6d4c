"""Random virtual modules: a physically consistent wide + tele module drawn from documented ranges.

:func:`random_module` draws a :class:`~phonestereo.sim.module.ModuleSpec` from the ranges of
:class:`ModuleRanges` (defaults shipped in ``sim/random_ranges.json``; a user's JSON overrides
any subset, :func:`load_ranges`). The same seed gives the same module, byte for byte.

How a module is drawn (every range is ``[low, high]``, drawn uniformly unless said otherwise):

- **Output size** ``width_px`` (exactly 4:3: W a multiple of 32, H = 3W/4), the same for both
  cameras (a logical multi-camera streams both physical cameras at one output size).
- **Wide**: horizontal field ``wide_hfov_deg`` gives f in pixels, f_px = (W/2)/tan(hfov/2);
  its output pixel pitch ``pixel_pitch_um`` gives the physical focal length f_mm = f_px·pitch;
  ``wide_f_number``. The sensor diagonal (pitch·diagonal in pixels) must fall within
  ``wide_sensor_diagonal_mm`` (else the pitch is redrawn).
- **Tele**: ``focal_ratio`` r = f_tele_px / f_wide_px (the optical zoom; same output size, so
  the tele's field is 1/r of the wide's and always inside it); its own pitch, physical focal
  length f_mm = r·f_wide_px·pitch within ``tele_focal_length_mm`` (long ones are periscopes)
  and sensor diagonal within ``tele_sensor_diagonal_mm``; f-number in ``tele_f_number``,
  raised so that the aperture f/N is at most ``tele_max_aperture_mm`` (a prism's height).
- **Rig**: baseline length ``baseline_mm`` in the device plane at direction
  ``baseline_direction_deg`` (0° = device x), Z offset ``tz_mm``, rotation vector components
  uniform in ±``rotation_deg``.
- **Lenses**: the ``folded-x3`` preset's models, coefficients and their focus slopes scaled by
  ``distortion_scale`` (one factor per camera); principal-point offsets uniform in
  ±``principal_point_offset_px`` · W/2000; manual-focus noise the preset's times
  ``focus_noise_scale``.
- **Heating**: per-camera drift of magnitude ``heating_drift_px`` in a uniform direction;
  ``heating_tau_s``, ``heating_rise_c``. **Sag**: ``wide_sag_px_per_g``, ``tele_sag_px_per_g``.
- **Autofocus**: ``af_error_dioptre`` (1σ), ``af_failure_rate``.
- **Factory calibration**: the preset's noise times ``factory_noise_scale`` (up to 3×).
- **Reports**: temperature with probability ``temperature_reported_probability``.
- **Hand shake**: ``handheld_rotation_deg``, ``handheld_translation_mm`` (1σ per axis).
- **Sensor**: ``full_well_e``, ``read_noise_e`` per camera.
- **ISP** (``wide_isp``, ``tele_isp``: :class:`IspRanges`, one set of ranges per camera, the
  two drawn independently): CFA pattern and demosaicing method (uniform choices), raw bit depth
  (choice; black level 64 DN at 10 bits, scaled by 2^(bits − 10)), channel sensitivities, CCM
  strength, tone γ, denoise strength and radius, sharpen amount and radius, chroma blur and
  saturation, JPEG quality (an integer). ``isp: false`` gives both cameras the raw linear path.
  The ISP is drawn from its own stream (``[seed, 0x5EED40D, 1]``), so adding it left every
  other parameter of a seed's module as it was.

Examples
--------
>>> spec = random_module(1000)
>>> spec.name, 2.0 <= spec.tele.focal_px_infinity / spec.wide.focal_px_infinity <= 6.0
('random-1000', True)
>>> random_module(1000) == spec
True
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from phonestereo.errors import InputError, PhysicsError
from phonestereo.io.json_text import read_text
from phonestereo.sim.module import ModuleSpec, load_module, parse_module

RANGES_FILE = "random_ranges.json"
#: Draws tried before a seed is declared impossible under the given ranges.
MAX_DRAWS = 2000
Pair = tuple[float, float]


class IspRanges(BaseModel):
    """Ranges of one camera's ISP block (:class:`~phonestereo.sim.isp_spec.IspSpec`); the
    defaults are the wide's (a main camera in good light), ``docs/module-random.md``."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    cfa_patterns: tuple[Literal["RGGB", "BGGR", "GRBG", "GBRG"], ...] = (
        "RGGB", "BGGR", "GRBG", "GBRG")
    demosaic_methods: tuple[Literal["bilinear", "ea", "vng"], ...] = ("ea", "vng")
    raw_bit_depths: tuple[int, ...] = (10, 12)
    red_sensitivity: Pair = (0.45, 0.6)
    blue_sensitivity: Pair = (0.6, 0.8)
    ccm_strength: Pair = (0.4, 1.0)
    tone_gamma: Pair = (2.2, 2.6)
    denoise_strength: Pair = (0.5, 2.0)
    denoise_radius_px: Pair = (1.0, 2.0)
    sharpen_amount: Pair = (0.5, 1.5)
    sharpen_radius_px: Pair = (0.7, 1.5)
    chroma_blur_px: Pair = (3.0, 8.0)
    chroma_saturation: Pair = (0.9, 1.2)
    jpeg_quality: Pair = (88, 97)

    @model_validator(mode="after")
    def _check(self) -> IspRanges:
        _check_pairs(self, "isp ")
        for name in ("cfa_patterns", "demosaic_methods", "raw_bit_depths"):
            if not getattr(self, name):
                raise InputError(f"isp range {name} must list at least one choice")
        if not all(8 <= b <= 16 for b in self.raw_bit_depths):
            raise PhysicsError(f"raw_bit_depths must be 8-16 bits, got {self.raw_bit_depths}")
        return self


def _check_pairs(model: BaseModel, what: str = "") -> None:
    """Every ``[low, high]`` field (annotated :data:`Pair`) finite with low <= high."""
    for name, field in type(model).model_fields.items():
        if field.annotation != Pair:
            continue
        lo, hi = getattr(model, name)
        if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
            raise InputError(f"{what}range {name} must be [low, high] with low <= high, "
                             f"got {[lo, hi]}")


#: The tele's ISP ranges: smaller pixels and a slower lens, so a noisier raw image, denoised
#: harder (1-3x its noise profile) and sharpened less (0.2-1.0), JPEG 85-95.
TELE_ISP = IspRanges(denoise_strength=(1.0, 3.0), denoise_radius_px=(1.2, 2.5),
                     sharpen_amount=(0.2, 1.0), sharpen_radius_px=(0.8, 1.5),
                     jpeg_quality=(85, 95))


#: What a physical range (low, high) must satisfy, by what the message says of it.
_BOUNDS: dict[str, Any] = {"> 0": lambda lo, hi: lo > 0, ">= 0": lambda lo, hi: lo >= 0,
                           "within [0, 1]": lambda lo, hi: lo >= 0 and hi <= 1}
_SIGNS = {
    **dict.fromkeys(("baseline_mm", "wide_hfov_deg", "wide_sensor_diagonal_mm",
                     "tele_sensor_diagonal_mm", "tele_focal_length_mm", "wide_f_number",
                     "tele_f_number", "heating_tau_s", "full_well_e"), "> 0"),
    **dict.fromkeys(("distortion_scale", "focus_noise_scale", "heating_drift_px",
                     "heating_rise_c", "wide_sag_px_per_g", "tele_sag_px_per_g",
                     "af_error_dioptre", "factory_noise_scale", "handheld_rotation_deg",
                     "handheld_translation_mm", "read_noise_e"), ">= 0"),
    "af_failure_rate": "within [0, 1]",
}


class ModuleRanges(BaseModel):
    """The ranges random modules are drawn from (module docstring; units in the names)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    schema_version: int = 1
    width_px: Pair = (2000, 4000)
    wide_hfov_deg: Pair = (64.0, 80.0)
    pixel_pitch_um: Pair = (0.8, 2.8)
    wide_sensor_diagonal_mm: Pair = (4.0, 16.0)
    tele_sensor_diagonal_mm: Pair = (2.5, 12.0)
    focal_ratio: Pair = (2.0, 6.0)
    tele_focal_length_mm: Pair = (4.0, 25.0)
    wide_f_number: Pair = (1.5, 2.0)
    tele_f_number: Pair = (2.2, 4.0)
    tele_max_aperture_mm: float = Field(default=5.0, gt=0)
    baseline_mm: Pair = (8.0, 25.0)
    baseline_direction_deg: Pair = (0.0, 360.0)
    tz_mm: Pair = (0.0, 6.0)
    rotation_deg: float = Field(default=0.6, ge=0, le=5)
    principal_point_offset_px: float = Field(default=10.0, ge=0)
    distortion_scale: Pair = (0.5, 1.5)
    focus_noise_scale: Pair = (0.5, 2.0)
    heating_drift_px: Pair = (0.0, 7.0)
    heating_tau_s: Pair = (40.0, 120.0)
    heating_rise_c: Pair = (8.0, 20.0)
    wide_sag_px_per_g: Pair = (0.0, 0.3)
    tele_sag_px_per_g: Pair = (0.0, 1.5)
    af_error_dioptre: Pair = (0.01, 0.08)
    af_failure_rate: Pair = (0.0, 0.12)
    factory_noise_scale: Pair = (0.5, 3.0)
    temperature_reported_probability: float = Field(default=0.5, ge=0, le=1)
    handheld_rotation_deg: Pair = (0.15, 0.5)
    handheld_translation_mm: Pair = (1.0, 3.0)
    full_well_e: Pair = (3000.0, 8000.0)
    read_noise_e: Pair = (1.5, 3.5)

    isp: bool = True
    wide_isp: IspRanges = IspRanges()
    tele_isp: IspRanges = TELE_ISP

    @model_validator(mode="after")
    def _check(self) -> ModuleRanges:
        _check_pairs(self)
        if self.width_px[0] < 64:
            raise PhysicsError(f"width_px {list(self.width_px)} is too small for a camera")
        if self.pixel_pitch_um[0] <= 0 or self.focal_ratio[0] < 1:
            raise PhysicsError("pixel_pitch_um must be > 0 and focal_ratio >= 1 (a tele)")
        for name, sign in _SIGNS.items():
            lo, hi = getattr(self, name)
            if not _BOUNDS[sign](lo, hi):
                why = " (a stereo pair's cameras stand apart)" if name == "baseline_mm" else ""
                raise PhysicsError(f"range {name} must be {sign}{why}, got {[lo, hi]}")
        if self.wide_hfov_deg[1] >= 180:
            raise PhysicsError(f"range wide_hfov_deg must be < 180, got {list(self.wide_hfov_deg)}")
        return self


def load_ranges(path: str | Path | None = None) -> ModuleRanges:
    """The shipped ranges, overridden by the keys of a user's JSON file (any subset).

    Raises
    ------
    InputError
        Unreadable file, malformed JSON, an unknown key or an empty range (low > high).
    """
    base = json.loads(resources.files("phonestereo.sim").joinpath(RANGES_FILE).read_text())
    if path is not None:
        p = Path(path)
        text = read_text(p, "--ranges file")
        try:
            user = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(f"--ranges file {p} is not valid JSON: {exc.msg} at line "
                             f"{exc.lineno}") from None
        if not isinstance(user, dict):
            raise InputError(f"--ranges file {p} must hold a JSON object of ranges")
        for key, value in user.items():  # the ISP ranges merge key by key
            if key.endswith("_isp") and isinstance(value, dict) and isinstance(base.get(key),
                                                                               dict):
                base[key] = {**base[key], **value}
            else:
                base[key] = value
    try:
        return ModuleRanges.model_validate(base)
    except ValidationError as err:
        msgs = "; ".join(("{}: ".format(".".join(map(str, e["loc"]))) if e["loc"] else "")
                         + e["msg"].removeprefix("Value error, ") for e in err.errors())
        raise InputError(
            f"--ranges: the ranges are invalid ({msgs}); the keys and defaults are in "
            f"phonestereo/sim/{RANGES_FILE} (docs/module-random.md)"
        ) from None


def _u(rng: np.random.Generator, pair: Pair) -> float:
    return float(rng.uniform(pair[0], pair[1]))


def _draw_optics(rng: np.random.Generator, r: ModuleRanges) -> dict[str, Any] | None:
    """Sizes, focal lengths, pitches and f-numbers; None when this draw is not physical."""
    width = int(32 * round(_u(rng, r.width_px) / 32))  # exactly 4:3, both multiples of 8
    height = width * 3 // 4
    diag_px = float(np.hypot(width, height))
    hfov = np.deg2rad(_u(rng, r.wide_hfov_deg))
    f_w_px = (width / 2) / np.tan(hfov / 2)
    pitch_w = _u(rng, r.pixel_pitch_um)
    ratio = _u(rng, r.focal_ratio)
    pitch_t = _u(rng, r.pixel_pitch_um)
    f_w_mm, f_t_mm = f_w_px * pitch_w * 1e-3, ratio * f_w_px * pitch_t * 1e-3
    lo_w, hi_w = r.wide_sensor_diagonal_mm
    lo_t, hi_t = r.tele_sensor_diagonal_mm
    if not (lo_w <= diag_px * pitch_w * 1e-3 <= hi_w and lo_t <= diag_px * pitch_t * 1e-3 <= hi_t):
        return None
    if not (r.tele_focal_length_mm[0] <= f_t_mm <= r.tele_focal_length_mm[1]):
        return None
    n_t = max(_u(rng, r.tele_f_number), f_t_mm / r.tele_max_aperture_mm)
    return {"size": (width, height), "ratio": ratio,
            "wide": (round(f_w_mm, 4), round(pitch_w, 4), round(_u(rng, r.wide_f_number), 2)),
            "tele": (round(f_t_mm, 4), round(pitch_t, 4), round(n_t, 2))}


def _camera(base: dict[str, Any], optics: tuple[float, float, float], size: tuple[int, int],
            rng: np.random.Generator, r: ModuleRanges, sag: Pair) -> dict[str, Any]:
    f_mm, pitch, n = optics
    k = _u(rng, r.distortion_scale)
    drift, angle = _u(rng, r.heating_drift_px), rng.uniform(0, 2 * np.pi)
    pp = rng.uniform(-1, 1, size=2) * r.principal_point_offset_px * size[0] / 2000
    cam = dict(base)
    cam.update(
        size=list(size), focal_length_mm=f_mm, f_number=n, pixel_pitch_um=pitch,
        principal_point_offset_px=[round(float(v), 2) for v in pp],
        lens={"model": base["lens"]["model"],
              "coefficients": [round(k * c, 6) for c in base["lens"]["coefficients"]]},
        lens_per_extension=[round(k * c, 6) for c in base["lens_per_extension"]],
        focus_noise_rel=round(base["focus_noise_rel"] * _u(rng, r.focus_noise_scale), 7),
        heating_drift_px=[round(drift * np.cos(angle), 3), round(drift * np.sin(angle), 3)],
        sag_px_per_g=round(_u(rng, sag), 3),
        sensor={**base["sensor"], "full_well_e": round(_u(rng, r.full_well_e)),
                "read_noise_e": round(_u(rng, r.read_noise_e), 2)},
    )
    return cam


def _isp(rng: np.random.Generator, r: IspRanges) -> dict[str, Any]:
    """One camera's ISP block drawn from its ranges (module docstring)."""
    bits = int(rng.choice(r.raw_bit_depths))
    return {
        "cfa_pattern": str(rng.choice(r.cfa_patterns)),
        "channel_sensitivity": [round(_u(rng, r.red_sensitivity), 3), 1.0,
                                round(_u(rng, r.blue_sensitivity), 3)],
        "raw_bit_depth": bits,
        "raw_black_level_dn": float(64 * 2 ** (bits - 10)),
        "white_balance_gains": None,
        "demosaic": str(rng.choice(r.demosaic_methods)),
        "ccm_strength": round(_u(rng, r.ccm_strength), 3),
        "tone_gamma": round(_u(rng, r.tone_gamma), 3),
        "denoise_strength": round(_u(rng, r.denoise_strength), 3),
        "denoise_radius_px": round(_u(rng, r.denoise_radius_px), 3),
        "sharpen_amount": round(_u(rng, r.sharpen_amount), 3),
        "sharpen_radius_px": round(_u(rng, r.sharpen_radius_px), 3),
        "chroma_blur_px": round(_u(rng, r.chroma_blur_px), 2),
        "chroma_saturation": round(_u(rng, r.chroma_saturation), 3),
        "jpeg_quality": int(rng.integers(int(r.jpeg_quality[0]), int(r.jpeg_quality[1]) + 1)),
        "notes": "drawn by phonestereo module random from the ranges of docs/module-random.md",
    }


def random_module(seed: int, ranges: ModuleRanges | None = None) -> ModuleSpec:
    """Draw a physically consistent module (module docstring); same seed → same module.

    Parameters
    ----------
    seed : int
        >= 0; the module is named ``random-<seed>``.
    ranges : ModuleRanges, optional
        Default: the shipped ranges (:func:`load_ranges`).

    Raises
    ------
    InputError
        A negative seed, or ranges under which no physical module was found in
        :data:`MAX_DRAWS` draws (the message names the conflicting ranges).
    """
    if not isinstance(seed, int | np.integer) or seed < 0:
        raise InputError(f"seed must be an integer >= 0, got {seed!r}")
    r = ranges if ranges is not None else load_ranges()
    rng = np.random.default_rng([int(seed), 0x5EED_40D])
    for _ in range(MAX_DRAWS):
        optics = _draw_optics(rng, r)
        if optics is not None:
            break
    else:
        raise InputError(
            f"no physical module in {MAX_DRAWS} draws: the ranges pixel_pitch_um, width_px, "
            "*_sensor_diagonal_mm and tele_focal_length_mm contradict each other; widen them"
        )
    base = load_module("folded-x3").model_dump(mode="json")
    size = optics["size"]
    b, phi, tz = (
        _u(rng, r.baseline_mm),
        np.deg2rad(_u(rng, r.baseline_direction_deg)),
        _u(rng, r.tz_mm),
    )
    rot = rng.uniform(-r.rotation_deg, r.rotation_deg, size=3)
    noise, k = base["calibration"]["noise"], _u(rng, r.factory_noise_scale)
    temperature = bool(rng.uniform() < r.temperature_reported_probability)
    data = {
        **base,
        "name": f"random-{int(seed)}",
        "wide": _camera(base["wide"], optics["wide"], size, rng, r, r.wide_sag_px_per_g),
        "tele": _camera(base["tele"], optics["tele"], size, rng, r, r.tele_sag_px_per_g),
        "extrinsics": {
            "tele_center_mm": [round(b * np.cos(phi), 3), round(b * np.sin(phi), 3), round(tz, 3)],
            "rotation_deg": [round(float(v), 4) for v in rot],
        },
        "heating": {"tau_s": round(_u(rng, r.heating_tau_s), 1), "ambient_c": 25.0,
                    "rise_c": round(_u(rng, r.heating_rise_c), 2)},
        "autofocus": {"error_dioptre": round(_u(rng, r.af_error_dioptre), 4),
                      "failure_rate": round(_u(rng, r.af_failure_rate), 4)},
        "calibration": {**base["calibration"], "noise": {
            "focal_rel": [round(k * v, 7) for v in noise["focal_rel"]],
            "principal_point_px": [round(k * v, 4) for v in noise["principal_point_px"]],
            "rotation_deg": round(k * noise["rotation_deg"], 5),
            "translation_mm": [round(k * v, 4) for v in noise["translation_mm"]]}},
        "handheld": {"rotation_deg": round(_u(rng, r.handheld_rotation_deg), 3),
                     "translation_mm": round(_u(rng, r.handheld_translation_mm), 3)},
        "reports": {**base["reports"], "temperature": temperature},
    }
    isp_rng = np.random.default_rng([int(seed), 0x5EED_40D, 1])  # its own stream (docstring)
    for role, isp_ranges in (("wide", r.wide_isp), ("tele", r.tele_isp)):
        data[role]["isp"] = _isp(isp_rng, isp_ranges) if r.isp else None
    data["description"] = _describe(data, optics["ratio"], k)
    return parse_module(data, f"random module (seed {seed})")


def _describe(data: dict[str, Any], ratio: float, noise_scale: float) -> str:
    w, t, ex = data["wide"], data["tele"], data["extrinsics"]["tele_center_mm"]
    kind = "periscope" if t["focal_length_mm"] > 9 else "tele"
    return (
        f"Random module: x{ratio:.2f} {kind} (f {t['focal_length_mm']:.2f} mm f/{t['f_number']}, "
        f"{t['pixel_pitch_um']:.2f} um), wide f {w['focal_length_mm']:.2f} mm "
        f"f/{w['f_number']} {w['pixel_pitch_um']:.2f} um, {w['size'][0]}x{w['size'][1]} px; "
        f"baseline {np.hypot(ex[0], ex[1]):.1f} mm, t_z {ex[2]:.1f} mm; factory noise "
        f"x{noise_scale:.2f}; temperature {'' if data['reports']['temperature'] else 'not '}"
        f"reported; ISP {_isp_text(w.get('isp'))} (wide), {_isp_text(t.get('isp'))} (tele)."
    )


def _isp_text(isp: dict[str, Any] | None) -> str:
    if isp is None:
        return "off"
    return (f"{isp['cfa_pattern']} {isp['demosaic']}, denoise {isp['denoise_strength']:.2f}, "
            f"sharpen {isp['sharpen_amount']:.2f}, JPEG q{isp['jpeg_quality']}")


__all__ = [
    "MAX_DRAWS",
    "RANGES_FILE",
    "TELE_ISP",
    "IspRanges",
    "ModuleRanges",
    "load_ranges",
    "random_module",
]
