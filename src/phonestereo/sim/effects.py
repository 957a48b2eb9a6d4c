"""The effects of the virtual module, each a small pure function with its own switch.

See docs/architecture.md.

Every function takes the :class:`~phonestereo.sim.module.ModuleSpec` (magnitudes and switches),
the capture conditions and, where the effect is random, a ``numpy.random.Generator``; it returns
that effect's contribution only. :mod:`phonestereo.sim.capture` composes them into the true
per-capture state. A switched-off effect returns its neutral value (zero shift, the calibration
focus, the calibration pose), so each fix can be tested in isolation (thesis §2.4).

Thesis sections: focus §3.5 (breathing, manual-focus repeatability, autofocus and its
failures), heating §3.1, distortion §3.2, non-baseline/Z translation §3.3, orientation §3.4.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from phonestereo.errors import InputError
from phonestereo.geometry import LensModel, Transform
from phonestereo.sim import optics
from phonestereo.sim.module import ModuleSpec

Role = Literal["wide", "tele"]

#: Gravity in the world frame: the world is the device frame of a landscape capture at rest.
GRAVITY_WORLD = (0.0, 1.0, 0.0)
#: Nearest and farthest distance (m) a failed autofocus may land on.
AF_FAIL_RANGE_M = (0.1, 10.0)


def _check_role(role: str) -> None:
    if role not in ("wide", "tele"):
        raise InputError(f"camera role must be 'wide' or 'tele', got {role!r}")


# --- heating (§3.1) ------------------------------------------------------------------------
def heating_fraction(spec: ModuleSpec, time_s: float) -> float:
    """Warm-up fraction 1 − e^(−t/τ) at ``time_s`` since the camera app started; 0 when off.

    Examples
    --------
    >>> from phonestereo.sim.module import load_module
    >>> spec = load_module("folded-x3")
    >>> round(heating_fraction(spec, 180.0), 3)    # ~3 min: saturated (thesis §3.1)
    0.924
    """
    if not spec.effects.heating:
        return 0.0
    if time_s < 0:
        raise InputError(f"time_s must be >= 0 (seconds since the camera app started), {time_s}")
    return 1.0 - math.exp(-time_s / spec.heating.tau_s)


def temperature_c(spec: ModuleSpec, time_s: float) -> float:
    """Module temperature in °C on the warm-up curve (ambient when heating is off)."""
    return spec.heating.ambient_c + spec.heating.rise_c * heating_fraction(spec, time_s)


def heating_drift_px(spec: ModuleSpec, role: Role, time_s: float) -> tuple[float, float]:
    """Principal-point drift A·(1 − e^(−t/τ)) of one camera, pixels (dx, dy)."""
    _check_role(role)
    frac = heating_fraction(spec, time_s) - heating_fraction(spec, spec.calibration.time_s)
    ax, ay = spec.camera(role).heating_drift_px
    return ax * frac, ay * frac


# --- orientation (§3.4) --------------------------------------------------------------------
def calibration_gravity(spec: ModuleSpec) -> tuple[float, float, float]:
    """Device-frame gravity at calibration: (0, 1, 0) landscape, (0, −1, 0) flipped."""
    return (0.0, 1.0, 0.0) if spec.calibration.orientation == "landscape" else (0.0, -1.0, 0.0)


def sag_shift_px(
    spec: ModuleSpec, role: Role, gravity: tuple[float, float, float]
) -> tuple[float, float]:
    """Principal-point shift from gravity sag relative to calibration, pixels (dx, dy).

    The shift is ``sag_px_per_g`` times the in-plane gravity (g_x, g_y) in the device frame;
    relative to the calibration orientation (landscape) a flipped device moves the tele's
    principal point by 2·0.5 = 1 px.
    """
    _check_role(role)
    if not spec.effects.sag:
        return 0.0, 0.0
    s = spec.camera(role).sag_px_per_g
    g0 = calibration_gravity(spec)
    return s * (gravity[0] - g0[0]), s * (gravity[1] - g0[1])


def orientation_label(gravity: tuple[float, float, float]) -> str:
    """``landscape`` when gravity points down the device y axis, else ``landscape-flipped``."""
    return "landscape" if gravity[1] >= 0 else "landscape-flipped"


def device_gravity(T_world_device: Transform) -> tuple[float, float, float]:
    """Unit gravity vector in the device frame for a device pose in the world."""
    g = T_world_device.R.T @ np.asarray(GRAVITY_WORLD)
    g = g / np.linalg.norm(g)
    return float(g[0]), float(g[1]), float(g[2])


# --- focus (§3.5) --------------------------------------------------------------------------
def autofocus_distance(
    spec: ModuleSpec, role: Role, subject_m: float, rng: np.random.Generator
) -> tuple[float, bool]:
    """Where autofocus puts the focus for a subject at ``subject_m``: (focus_m, failed).

    The aim error is Gaussian in dioptres (switch ``focus_noise``); with probability
    ``autofocus.failure_rate`` (switch ``af_failures``) the lens lands anywhere in dioptres
    between 0.1 m and 10 m instead. Both draws are always made so the random stream does not
    depend on the switches.
    """
    _check_role(role)
    if subject_m <= 0:
        raise InputError(f"autofocus subject distance must be > 0 m, got {subject_m}")
    err, u_fail, u_where = rng.normal(), rng.uniform(), rng.uniform()
    dioptre = 1.0 / subject_m
    if spec.effects.focus_noise:
        dioptre += spec.autofocus.error_dioptre * err
    failed = bool(spec.effects.af_failures and u_fail < spec.autofocus.failure_rate)
    if failed:
        near, far = AF_FAIL_RANGE_M
        dioptre = 1.0 / far + u_where * (1.0 / near - 1.0 / far)
    dioptre = max(dioptre, 0.05)  # never past 20 m: keeps the thin lens finite
    return 1.0 / dioptre, failed


def lens_image_distance_m(spec: ModuleSpec, role: Role, focus_m: float, eps: float = 0.0) -> float:
    """Actual lens-to-sensor distance v for a focus distance, with lens-position noise.

    v = f·s/(s − f) (thin lens, :func:`phonestereo.sim.optics.image_distance_m`) times
    (1 + σ·eps) when ``focus_noise`` is on, with ``eps`` a standard-normal draw and σ the
    camera's ``focus_noise_rel`` (≈ 2·10⁻⁴ wide, 8·10⁻⁴ tele: manual focus does not land on
    the same lens position twice, thesis §3.5.3).

    Examples
    --------
    >>> from phonestereo.sim.module import load_module
    >>> round(lens_image_distance_m(load_module("folded-x3"), "wide", 0.6) * 1e3, 4)   # mm
    4.2296
    """
    cam = spec.camera(role)
    v = optics.image_distance_m(cam.focal_length_m, focus_m)
    if spec.effects.focus_noise:
        v *= 1.0 + cam.focus_noise_rel * eps
    return float(v)


def calibration_image_distance_m(spec: ModuleSpec, role: Role) -> float:
    """Lens-to-sensor distance at the calibration focus (no noise)."""
    return lens_image_distance_m(spec, role, spec.calibration.focus_distance_m)


def focal_px(spec: ModuleSpec, role: Role, image_distance_m: float) -> float:
    """Focal length in pixels, v / pitch (focus breathing); the calibration value when off.

    Examples
    --------
    >>> from phonestereo.sim.module import load_module
    >>> spec = load_module("folded-x3")
    >>> v = lens_image_distance_m(spec, "tele", 1.5)
    >>> f_cal = focal_px(spec, "tele", calibration_image_distance_m(spec, "tele"))
    >>> round(focal_px(spec, "tele", v) / f_cal, 4)     # tele breathes −1.3 % from 0.6 to 1.5 m
    0.9873
    """
    cam = spec.camera(role)
    v = (
        image_distance_m
        if spec.effects.focus_breathing
        else calibration_image_distance_m(spec, role)
    )
    return float(v / cam.pixel_pitch_m)


def lens_travel_um(spec: ModuleSpec, role: Role, image_distance_m: float) -> float:
    """Lens travel from the calibration position, micrometres (v − v_cal)."""
    return (image_distance_m - calibration_image_distance_m(spec, role)) * 1e6


def lens_at_focus(spec: ModuleSpec, role: Role, image_distance_m: float) -> LensModel:
    """True lens at a lens position: coefficients + slope·(v − v_cal)/f (switch
    ``distortion_vs_focus``); the calibration-focus lens when off."""
    cam = spec.camera(role)
    base = np.asarray(cam.lens.coefficients, dtype=np.float64)
    if spec.effects.distortion_vs_focus and cam.lens_per_extension is not None:
        rel = lens_travel_um(spec, role, image_distance_m) * 1e-6 / cam.focal_length_m
        base = base + np.asarray(cam.lens_per_extension) * rel
    return cam.lens.build(base)


def focus_principal_point_shift_px(
    spec: ModuleSpec, role: Role, image_distance_m: float
) -> tuple[float, float]:
    """Principal-point shift from lens travel (a slightly tilted barrel), pixels (dx, dy)."""
    if not spec.effects.distortion_vs_focus:
        return 0.0, 0.0
    travel = lens_travel_um(spec, role, image_distance_m)
    kx, ky = spec.camera(role).principal_point_px_per_um
    return kx * travel, ky * travel


def reported_focus_position(
    spec: ModuleSpec, role: Role, image_distance_m: float, rng: np.random.Generator
) -> float | None:
    """What the module reports as focus position: the focus distance of the actual lens
    position in dioptres (as Android's LENS_FOCUS_DISTANCE), plus a large noise (thesis §3.5:
    the report is unreliable), clipped at 0; None if the module reports none.

    Examples
    --------
    >>> import numpy as np
    >>> from phonestereo.sim.module import load_module
    >>> spec = load_module("folded-x3").with_effects()
    >>> v = lens_image_distance_m(spec, "wide", 0.5)
    >>> 0.0 <= reported_focus_position(spec, "wide", v, np.random.default_rng(0)) < 4.0
    True
    """
    noise = rng.normal()
    if not spec.reports.focus_position:
        return None
    f = spec.camera(role).focal_length_m
    dioptre = (image_distance_m - f) / (f * image_distance_m)  # 1/s = 1/f − 1/v
    return round(max(0.0, dioptre + spec.reports.focus_position_noise_dioptre * noise), 4)


# --- extrinsics (§3.3) and hand shake ---------------------------------------------------------
def tele_center_m(spec: ModuleSpec) -> np.ndarray:
    """True tele optical centre in the wide frame (3,), metres, at calibration conditions.

    With ``non_baseline_translation`` off only the baseline component (the larger of x, y)
    is kept, so the rig is a pure baseline plus rotation.
    """
    c = np.asarray(spec.extrinsics.tele_center_mm, dtype=np.float64) * 1e-3
    if not spec.effects.non_baseline_translation:
        axis = int(np.argmax(np.abs(c[:2])))
        pure = np.zeros(3)
        pure[axis] = c[axis]
        c = pure
    return c


def true_T_tele_wide(
    spec: ModuleSpec, travel_wide_um: float = 0.0, travel_tele_um: float = 0.0
) -> Transform:
    """True T_tele_wide. Each optical centre moves along z with its lens travel (focus
    breathing moves the lenses independently, thesis §3.5.3), so t_z changes with focus."""
    R = Transform.from_rotvec(np.deg2rad(spec.extrinsics.rotation_deg), np.zeros(3)).R
    c = tele_center_m(spec)
    if spec.effects.focus_breathing:
        c = c + np.array([0.0, 0.0, (travel_tele_um - travel_wide_um) * 1e-6])
    return Transform(R, -R @ c)


def handheld_offset(spec: ModuleSpec, rng: np.random.Generator) -> Transform:
    """Hand shake as a device-frame perturbation δ: T_world_device' = T_world_device @ δ.

    Identity when ``handheld`` is off (tripod); the draws are made either way.
    """
    rot = rng.normal(size=3) * np.deg2rad(spec.handheld.rotation_deg)
    trans = rng.normal(size=3) * spec.handheld.translation_mm * 1e-3
    if not spec.effects.handheld:
        return Transform.identity()
    return Transform.from_rotvec(rot, trans)
