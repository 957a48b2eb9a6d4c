"""The wide camera's focus breathing between the factory calibration and use (thesis §3.5).

The factory calibrates the wide focused at one close distance (``CalibrationConditions.
focus_distance_m``, typically 0.4–0.6 m). In use it focuses on the subject. A lens focused at
distance Z sits at the image distance v = f / (1 − f/Z) (thin lens), and the pinhole focal
length in pixels is v / pitch, so the wide's focal length at a working focus Z_w is

    f_w = f_cal · (1 − f/Z_cal) / (1 − f/Z_w)                                   (thin lens)

— about f[mm] · 0.1 % smaller per dioptre focused farther (a 6 mm wide focused at 4 m after
a 0.6 m calibration: −0.81 %).

**Why it matters after the learned correction.** The IPD ruler and the disparity both read in
the wide's pixels, so the correction learned from faces is blind to this scale (the face
depth f·IPD/ipd_px and f·B/d scale alike). What is left is a depth scale error of the
application capture alone: Z = f_cal·B/d' reads Z_true · f_cal / f_w. The product knows
f_cal, Z_cal and — from the phone's metadata — the wide's physical focal length f (Camera2
``LENS_INFO_AVAILABLE_FOCAL_LENGTHS``, EXIF ``FocalLength``). The working focus is the capture's
reported focus position (the manifest's ``focus_position``, dioptres as Camera2's
``LENS_FOCUS_DISTANCE``) when there is one — a wide that stays focused at 1.5 m while the
subject is at 4 m must not be corrected for 4 m — else the measured depth itself (the wide
focused on the ROI). :func:`correct_depth` scales the depth by f_w / f_cal.

Examples
--------
A 5.85 mm wide calibrated at 0.6 m, focused at 4 m: its focal length is 0.83 % shorter.

>>> round(focal_breathing_scale(5.85, 0.6, 4.0), 5)
0.9917
>>> round(correct_depth(4.0334, 5.85, 0.6), 3)      # a depth read 0.83 % long
4.0
>>> round(correct_depth(4.0334, 5.85, 0.6, focus_dioptre=0.25), 3)   # reported: 4 m
4.0
"""

from __future__ import annotations

import numpy as np

from phonestereo.errors import InputError


def focal_breathing_scale(
    focal_length_mm: float, calibration_focus_m: float, focus_m: float
) -> float:
    """f_w / f_cal of a thin lens focused at ``focus_m`` after calibration at
    ``calibration_focus_m`` (module docstring).

    Parameters
    ----------
    focal_length_mm : float
        Physical focal length of the lens, millimetres (> 0).
    calibration_focus_m, focus_m : float
        Focus distances, metres (> focal length; ``inf`` for infinity).

    Raises
    ------
    InputError
        A non-positive focal length, or a focus distance inside the focal length.
    """
    f = float(focal_length_mm) * 1e-3
    if not f > 0:
        raise InputError(f"focal_length_mm must be > 0 millimetres, got {focal_length_mm}")
    zc, zw = float(calibration_focus_m), float(focus_m)
    if not (zc > f and zw > f):
        raise InputError(
            f"focus distances {zc} m and {zw} m must exceed the focal length ({f * 1e3} mm)"
        )
    return float((1.0 - f / zc) / (1.0 - f / zw))


def correct_depth(
    depth_m: float,
    focal_length_mm: float,
    calibration_focus_m: float,
    focus_dioptre: float | None = None,
) -> float:
    """The depth corrected for the wide's breathing (module docstring).

    Parameters
    ----------
    depth_m : float
        Depth read through the factory focal length, metres. Non-finite or non-positive
        depths come back unchanged.
    focal_length_mm, calibration_focus_m : float
        As for :func:`focal_breathing_scale`.
    focus_dioptre : float or None
        The wide's reported focus, dioptres (0 = infinity). None: the wide focused at the true
        depth, and the scale is evaluated there (two fixed-point steps: the scale moves by
        ~1e-5 per % of depth).
    """
    z = float(depth_m)
    if not (np.isfinite(z) and z > 0):
        return z
    if focus_dioptre is not None and np.isfinite(focus_dioptre) and focus_dioptre >= 0:
        focus = 1.0 / focus_dioptre if focus_dioptre > 0 else float("inf")
        return z * focal_breathing_scale(focal_length_mm, calibration_focus_m, focus)
    z_true = z
    for _ in range(2):
        z_true = z * focal_breathing_scale(focal_length_mm, calibration_focus_m, z_true)
    return z_true


def focus_sigma_rel(focal_length_mm: float, focus_dioptre: float, sigma_dioptre: float) -> float:
    """Relative σ of the breathing scale from a reported focus's σ (thin lens, module
    docstring): d ln(f_w)/dD = f / (1 − f·D), so σ_rel = f·σ_D / (1 − f·D).

    Parameters
    ----------
    focal_length_mm : float
        Physical focal length of the wide, millimetres (> 0).
    focus_dioptre : float
        The reported focus, dioptres (≥ 0).
    sigma_dioptre : float
        Its σ, dioptres (≥ 0).

    Examples
    --------
    A 5.8 mm wide reported at 0.5 D with 0.3 D of σ:

    >>> round(focus_sigma_rel(5.8, 0.5, 0.3) * 100, 3)     # % of the depth
    0.175
    """
    f = float(focal_length_mm) * 1e-3
    if not (f > 0 and np.isfinite(f)) or not (sigma_dioptre >= 0) or not (focus_dioptre >= 0):
        raise InputError(
            f"focus_sigma_rel needs a focal length > 0 mm and a focus and σ ≥ 0 D, got "
            f"{focal_length_mm}, {focus_dioptre}, {sigma_dioptre}"
        )
    return float(f * sigma_dioptre / (1.0 - f * focus_dioptre))


__all__ = ["correct_depth", "focal_breathing_scale", "focus_sigma_rel"]
