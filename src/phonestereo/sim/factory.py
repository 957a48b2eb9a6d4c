"""The factory calibration of the virtual module (docs/architecture.md, thesis §1.3.2 and §3 intro).

What a production line would measure: the true rig at calibration conditions (cold, focus at
0.6 m, landscape), described with OpenCV's even-order lens model (fitted to the true odd-order
lens over the image, §3.2), plus estimation noise on every parameter (switch
``factory_noise``). It is written into each capture set as ``calibration.json`` and is all the
pipeline knows about the module.
"""

from __future__ import annotations

import numpy as np

from phonestereo.geometry import Camera, Rig, Transform
from phonestereo.io import Calibration, CalibrationConditions
from phonestereo.sim import effects as fx
from phonestereo.sim.capture import calibration_rig
from phonestereo.sim.lensfit import fit_even_lens
from phonestereo.sim.module import ModuleSpec

PARAMETER_NAMES = (
    "wide.f",
    "wide.cx",
    "wide.cy",
    "tele.f",
    "tele.cx",
    "tele.cy",
    "rotvec.x",
    "rotvec.y",
    "rotvec.z",
    "tele_center.x",
    "tele_center.y",
    "tele_center.z",
)


def _noisy_camera(cam: Camera, focal_rel: float, pp_px: float, draws: np.ndarray) -> Camera:
    s = 1.0 + focal_rel * draws[0]
    return cam.scaled(s).shifted(pp_px * draws[1], pp_px * draws[2])


def factory_calibration(spec: ModuleSpec, rng: np.random.Generator) -> Calibration:
    """The imperfect factory calibration of a module.

    Parameters
    ----------
    spec : ModuleSpec
        The module (true parameters, calibration conditions and noise).
    rng : numpy.random.Generator
        Draws the estimation noise (12 normals, drawn whether or not the noise is on).

    Returns
    -------
    Calibration
        ``opencv5`` cameras, T_tele_wide, the calibration conditions and a diagonal covariance
        over :data:`PARAMETER_NAMES` (the noise the module spec states, in px, rad and m).

    Examples
    --------
    >>> import numpy as np
    >>> from phonestereo.sim.module import load_module
    >>> cal = factory_calibration(load_module("folded-x3"), np.random.default_rng(0))
    >>> cal.rig.wide.lens.name, round(cal.rig.baseline_m * 1000, 1)
    ('opencv5', 12.0)
    """
    true = calibration_rig(spec)
    noise = spec.calibration.noise
    draws = rng.normal(size=12)
    on = spec.effects.factory_noise
    wide = fit_even_lens(true.wide, free_intrinsics=True)
    tele = fit_even_lens(true.tele, free_intrinsics=True)
    R = true.T_tele_wide.R
    center = true.tele_center_in_wide
    if on:
        wide = _noisy_camera(wide, noise.focal_rel[0], noise.principal_point_px[0], draws[0:3])
        tele = _noisy_camera(tele, noise.focal_rel[1], noise.principal_point_px[1], draws[3:6])
        dR = Transform.from_rotvec(draws[6:9] * np.deg2rad(noise.rotation_deg), np.zeros(3)).R
        R = dR @ R
        center = center + draws[9:12] * np.asarray(noise.translation_mm) * 1e-3
    sigmas = np.array(
        [
            noise.focal_rel[0] * true.wide.f,
            noise.principal_point_px[0],
            noise.principal_point_px[0],
            noise.focal_rel[1] * true.tele.f,
            noise.principal_point_px[1],
            noise.principal_point_px[1],
            *([np.deg2rad(noise.rotation_deg)] * 3),
            *(np.asarray(noise.translation_mm) * 1e-3),
        ]
    )
    covariance = np.diag(sigmas**2) if on else None
    conditions = CalibrationConditions(
        focus_distance_m=spec.calibration.focus_distance_m,
        temperature_c=(
            fx.temperature_c(spec, spec.calibration.time_s) if spec.reports.temperature else None
        ),
        orientation=spec.calibration.orientation,
        note=f"factory calibration of virtual module '{spec.name}' (sim)",
        wide_focal_length_mm=spec.wide.focal_length_mm,  # what the phone's metadata reports
    )
    rig = Rig(wide, tele, Transform(R, -R @ center))
    return Calibration(
        rig=rig,
        conditions=conditions,
        covariance=covariance,
        parameter_names=PARAMETER_NAMES if on else (),
    )
