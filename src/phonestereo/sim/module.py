"""The virtual module's specification: the TRUE rig and the magnitude of every effect.

See docs/architecture.md and docs/module.md.

A :class:`ModuleSpec` is what a preset JSON (``sim/presets/<name>.json``) or a user's JSON file
holds. It is the ground truth the simulator draws captures from; the pipeline never sees it (it
sees the factory calibration written beside the images). Units are in the field names
(``_mm``, ``_um``, ``_px``, ``_deg``, ``_s``, ``_c``); everything is converted to metres and
radians by the effect functions.

Frames: the device frame is the wide camera's frame in landscape (x right, y down, z forward).
Gravity in the device frame is (0, 1, 0) in landscape and (0, −1, 0) when flipped by 180°.

Examples
--------
>>> spec = load_module("folded-x3")
>>> round(spec.wide.focal_px_infinity), round(spec.tele.focal_px_infinity)
(1500, 4500)
>>> spec.extrinsics.tele_center_mm[1]      # the folded module's baseline is along device y
12.0
"""

from __future__ import annotations

import json
import re
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from phonestereo.errors import InputError, PhysicsError
from phonestereo.geometry import LENS_MODELS, LensModel, make_lens
from phonestereo.io.json_text import read_text
from phonestereo.sim.isp_spec import IspSpec

PRESET_PACKAGE = "phonestereo.sim"
_STRICT = ConfigDict(extra="forbid", frozen=True)
_INLINE_LIST = re.compile(r"\[\s+([-+0-9.eE,\snul]*?)\s+\]")


def _positive(value: float, name: str, unit: str) -> None:
    if not np.isfinite(value) or value <= 0:
        raise PhysicsError(f"{name} must be a finite positive number of {unit}, got {value}")


class LensSpec(BaseModel):
    """A lens model by name and coefficients (geometry.make_lens), at calibration focus."""

    model_config = _STRICT
    model: Literal["opencv5", "opencv8", "radial-odd"]
    coefficients: tuple[float, ...]

    @model_validator(mode="after")
    def _check(self) -> LensSpec:
        self.build()  # raises InputError on a wrong coefficient count
        return self

    def build(self, coefficients: Any | None = None) -> LensModel:
        """The geometry lens model (optionally with other coefficients of the same model)."""
        return make_lens(self.model, self.coefficients if coefficients is None else coefficients)


class SensorSpec(BaseModel):
    """Sensor noise model (sim.sensor.SensorModel fields); with an ISP, only its full well,
    read noise and exposure are used (the raw bit depth and the JPEG are the ISP's)."""

    model_config = _STRICT
    full_well_e: float = Field(default=6000.0, gt=0)
    read_noise_e: float = Field(default=2.5, ge=0)
    black_level_dn: float = Field(default=0.0, ge=0)
    exposure: float = Field(default=0.8, gt=0, le=1)
    bit_depth: int = Field(default=8, ge=8, le=16)
    jpeg_quality: int | None = Field(default=None, ge=1, le=100)


class CameraSpec(BaseModel):
    """One camera of the module: optics, true lens and its per-camera effect magnitudes."""

    model_config = _STRICT
    size: tuple[int, int]
    focal_length_mm: float
    f_number: float
    pixel_pitch_um: float
    principal_point_offset_px: tuple[float, float] = (0.0, 0.0)
    lens: LensSpec
    lens_per_extension: tuple[float, ...] | None = None
    principal_point_px_per_um: tuple[float, float] = (0.0, 0.0)
    focus_noise_rel: float = Field(default=0.0, ge=0)
    heating_drift_px: tuple[float, float] = (0.0, 0.0)
    sag_px_per_g: float = 0.0
    sensor: SensorSpec = SensorSpec()
    isp: IspSpec | None = None  # None: the raw linear grey path (sim.sensor.capture)

    @model_validator(mode="after")
    def _physics(self) -> CameraSpec:
        w, h = self.size
        if w <= 0 or h <= 0:
            raise PhysicsError(f"size must be two positive pixel counts, got {self.size}")
        _positive(self.focal_length_mm, "focal_length_mm", "millimetres")
        _positive(self.f_number, "f_number", "stops (e.g. 1.8)")
        _positive(self.pixel_pitch_um, "pixel_pitch_um", "micrometres")
        if self.lens_per_extension is not None and len(self.lens_per_extension) != len(
            self.lens.coefficients
        ):
            raise InputError(
                f"lens_per_extension needs one slope per lens coefficient "
                f"({len(self.lens.coefficients)}), got {len(self.lens_per_extension)}"
            )
        return self

    @property
    def focal_length_m(self) -> float:
        """Physical focal length in metres."""
        return self.focal_length_mm * 1e-3

    @property
    def pixel_pitch_m(self) -> float:
        """Pixel pitch in metres."""
        return self.pixel_pitch_um * 1e-6

    @property
    def focal_px_infinity(self) -> float:
        """Focal length in pixels with the lens focused at infinity (f / pitch)."""
        return self.focal_length_m / self.pixel_pitch_m

    @property
    def principal_point_px(self) -> tuple[float, float]:
        """Principal point (cx, cy) at calibration conditions: image centre + offset."""
        w, h = self.size
        dx, dy = self.principal_point_offset_px
        return (w - 1) / 2 + dx, (h - 1) / 2 + dy


class ExtrinsicsSpec(BaseModel):
    """Where the tele sits relative to the wide (device frame), at calibration conditions.

    ``tele_center_mm`` is the tele optical centre in the wide frame (mm): the baseline plus the
    non-baseline and Z components of §3.3. ``rotation_deg`` is the rotation vector of
    R_tele_wide in degrees (a few tenths of a degree on a real module).
    """

    model_config = _STRICT
    tele_center_mm: tuple[float, float, float]
    rotation_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @model_validator(mode="after")
    def _physics(self) -> ExtrinsicsSpec:
        if float(np.linalg.norm(self.tele_center_mm)) < 1e-3:
            raise PhysicsError(
                f"tele_center_mm {list(self.tele_center_mm)} gives a zero baseline; a stereo "
                "module needs the camera centres apart (e.g. [0, 12, 1.5] mm)"
            )
        if float(np.linalg.norm(self.rotation_deg)) > 10:
            raise PhysicsError(
                f"rotation_deg {list(self.rotation_deg)} is over 10°; a wide/tele module is "
                "aligned to a few tenths of a degree"
            )
        return self


class HeatingSpec(BaseModel):
    """Warm-up curve shared by drift and temperature: value·(1 − e^(−t/τ)) (thesis §3.1)."""

    model_config = _STRICT
    tau_s: float = Field(default=70.0, gt=0)
    ambient_c: float = 25.0
    rise_c: float = Field(default=15.0, ge=0)


class AutofocusSpec(BaseModel):
    """Autofocus: aim error (dioptres, 1σ) and the probability that a capture misses focus."""

    model_config = _STRICT
    error_dioptre: float = Field(default=0.03, ge=0)
    failure_rate: float = Field(default=0.05, ge=0, le=1)


class FactoryNoiseSpec(BaseModel):
    """1σ estimation noise of the factory calibration."""

    model_config = _STRICT
    focal_rel: tuple[float, float] = (2e-4, 5e-4)
    principal_point_px: tuple[float, float] = (0.3, 0.5)
    rotation_deg: float = Field(default=0.01, ge=0)
    translation_mm: tuple[float, float, float] = (0.05, 0.1, 0.3)


class CalibrationSpec(BaseModel):
    """Factory calibration conditions (cold, close focus, landscape) and its estimation noise.

    The factory describes both lenses with OpenCV's even-order ``opencv5`` model (§3.2).
    """

    model_config = _STRICT
    focus_distance_m: float = 0.6
    time_s: float = Field(default=0.0, ge=0)
    orientation: Literal["landscape", "landscape-flipped"] = "landscape"
    noise: FactoryNoiseSpec = FactoryNoiseSpec()

    @model_validator(mode="after")
    def _physics(self) -> CalibrationSpec:
        _positive(self.focus_distance_m, "calibration.focus_distance_m", "metres")
        return self


class HandheldSpec(BaseModel):
    """Hand shake between captures: 1σ rotation (deg, per axis) and translation (mm, per axis)."""

    model_config = _STRICT
    rotation_deg: float = Field(default=0.3, ge=0)
    translation_mm: float = Field(default=2.0, ge=0)


class ReportsSpec(BaseModel):
    """What the module reports in the manifest (the pipeline sees only these).

    ``focus_position`` is the wide camera's focus distance in dioptres (1/m, as Android's
    LENS_FOCUS_DISTANCE), with 1σ noise ``focus_position_noise_dioptre``.
    """

    model_config = _STRICT
    temperature: bool = False
    focus_position: bool = True
    focus_position_noise_dioptre: float = Field(default=0.3, ge=0)


class EffectsSpec(BaseModel):
    """One switch per effect of docs/architecture.md (all on by default)."""

    model_config = _STRICT
    focus_breathing: bool = True
    focus_noise: bool = True
    af_failures: bool = True
    distortion_vs_focus: bool = True
    odd_distortion: bool = True
    non_baseline_translation: bool = True
    heating: bool = True
    sag: bool = True
    handheld: bool = True
    factory_noise: bool = True
    sensor_noise: bool = True
    defocus: bool = True
    isp: bool = True  # off: the linear grey sensor path, whatever the cameras' isp blocks


EFFECT_NAMES: tuple[str, ...] = tuple(EffectsSpec.model_fields)


class ModuleSpec(BaseModel):
    """The whole virtual module (the preset JSON schema)."""

    model_config = _STRICT
    schema_version: Literal[1] = 1
    name: str = Field(min_length=1)
    description: str = ""
    wide: CameraSpec
    tele: CameraSpec
    extrinsics: ExtrinsicsSpec
    heating: HeatingSpec = HeatingSpec()
    autofocus: AutofocusSpec = AutofocusSpec()
    calibration: CalibrationSpec = CalibrationSpec()
    handheld: HandheldSpec = HandheldSpec()
    reports: ReportsSpec = ReportsSpec()
    effects: EffectsSpec = EffectsSpec()

    @model_validator(mode="after")
    def _physics(self) -> ModuleSpec:
        for role in ("wide", "tele"):
            cam: CameraSpec = getattr(self, role)
            if self.calibration.focus_distance_m <= 2 * cam.focal_length_m:
                raise PhysicsError(
                    f"calibration.focus_distance_m = {self.calibration.focus_distance_m} m is "
                    f"too close for the {role} lens (f = {cam.focal_length_mm} mm)"
                )
        return self

    def camera(self, role: str) -> CameraSpec:
        """The wide or tele camera spec."""
        if role not in ("wide", "tele"):
            raise InputError(f"camera role must be 'wide' or 'tele', got {role!r}")
        cam: CameraSpec = getattr(self, role)
        return cam

    def isp(self, role: str) -> IspSpec | None:
        """The ISP a camera's images go through, or None (no isp block, or switch ``isp`` off)."""
        return self.camera(role).isp if self.effects.isp else None

    def with_effects(self, **switches: bool) -> ModuleSpec:
        """A copy with some effect switches changed, e.g. ``spec.with_effects(heating=False)``."""
        unknown = sorted(set(switches) - set(EFFECT_NAMES))
        if unknown:
            raise InputError(f"unknown effect(s) {unknown}; known effects: {list(EFFECT_NAMES)}")
        effects = self.effects.model_copy(update=switches)
        return self.model_copy(update={"effects": effects})

    def all_effects_off(self) -> ModuleSpec:
        """A copy with every effect switched off (an ideal module, for isolating one effect)."""
        return self.with_effects(**dict.fromkeys(EFFECT_NAMES, False))

    def to_json(self) -> str:
        """The JSON text of this spec (the preset schema), deterministic; number lists inline."""
        text = json.dumps(self.model_dump(mode="json"), indent=2)
        return _INLINE_LIST.sub(lambda m: "[" + " ".join(m.group(1).split()) + "]", text) + "\n"


def list_presets() -> tuple[str, ...]:
    """Names of the shipped module presets, sorted."""
    files = resources.files(PRESET_PACKAGE).joinpath("presets").iterdir()
    return tuple(sorted(p.name[:-5] for p in files if p.name.endswith(".json")))


def _format_validation(err: ValidationError, source: str) -> str:
    lines = []
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"]) or "(top level)"
        msg = e["msg"].removeprefix("Value error, ")
        lines.append(f"  field '{loc}': {msg}")
    return f"module spec {source} is invalid:\n" + "\n".join(lines)


def parse_module(data: Any, source: str = "<dict>") -> ModuleSpec:
    """Validate a module spec given as a dict; typed errors naming the field.

    Raises
    ------
    PhysicsError
        Non-physical parameters (negative focal length, zero baseline, ...).
    InputError
        Any other malformed field (unknown keys, wrong types, wrong coefficient counts).
    """
    if not isinstance(data, dict):
        raise InputError(f"module spec {source} must be a JSON object, got {type(data).__name__}")
    try:
        return ModuleSpec.model_validate(data)
    except ValidationError as err:
        message = _format_validation(err, source)
        physics = any(isinstance(e.get("ctx", {}).get("error"), PhysicsError) for e in err.errors())
        raise (PhysicsError if physics else InputError)(message) from None


def load_module(name_or_path: str | Path) -> ModuleSpec:
    """Load a preset by name (``folded-x3``, ``nonfolded-x2``) or a module JSON file by path.

    Raises
    ------
    InputError
        Unknown preset (the message lists the presets), unreadable file, malformed JSON (with
        line and column) or an invalid field; :class:`PhysicsError` for non-physical values.
    """
    text_name = str(name_or_path)
    if text_name in list_presets():
        text = resources.files(PRESET_PACKAGE).joinpath("presets", f"{text_name}.json").read_text()
        source = f"preset '{text_name}'"
    else:
        path = Path(name_or_path)
        if not path.is_file():
            raise InputError(
                f"unknown module '{text_name}': not a preset and no such file; presets are "
                f"{list(list_presets())}, or pass the path of a module JSON file "
                "(`phonestereo module show folded-x3 --json` prints the schema)"
            )
        text = read_text(path, "module file", "pass a module JSON (UTF-8)")
        source = f"file {path}"
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(
            f"module {source} is not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}"
        ) from None
    return parse_module(data, source)


__all__ = [
    "EFFECT_NAMES",
    "LENS_MODELS",
    "AutofocusSpec",
    "CalibrationSpec",
    "CameraSpec",
    "EffectsSpec",
    "ExtrinsicsSpec",
    "FactoryNoiseSpec",
    "HandheldSpec",
    "HeatingSpec",
    "IspSpec",
    "LensSpec",
    "ModuleSpec",
    "ReportsSpec",
    "SensorSpec",
    "list_presets",
    "load_module",
    "parse_module",
]
