"""The naive depth pipeline of thesis §3 (intro): factory calibration, Z = f·B/d, no fixes.

The analysis steps of the thesis's first experiment (§3, Figure 3-1): extract corners in both
images, rectify them with the calibration, take the disparity, and convert it with the naive
stereo formula (eq. 4) using the calibration's extrinsics. Nothing of chapter 3 is corrected:
not heating, focus breathing, the residual (odd) distortion, the non-baseline / Z translation,
sag or the calibration's estimation error. It is the reference every chapter-3 analysis starts
from (the thesis measures ~30 % relative error with it at 1–4 m).

Rectification here is the rotation-only one of §1.3.3 applied to points: both pixels are
undistorted with their calibrated cameras, the tele ray is rotated into the wide's orientation
(Rᵀ), and the disparity is taken along the calibrated baseline direction (the image-plane
direction of the tele centre as seen in the wide frame), in wide-focal pixels.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from phonestereo.errors import ShapeError
from phonestereo.geometry import depth_from_disparity
from phonestereo.geometry.checks import Array, as_points
from phonestereo.io import Calibration

if TYPE_CHECKING:
    from phonestereo.sim.ground_truth import CaptureTruth


def naive_disparity(q_wide: Any, q_tele: Any, calibration: Calibration) -> Array:
    """Disparity d along the calibrated baseline direction, wide-focal pixels.

    Parameters
    ----------
    q_wide, q_tele : array_like, shape (..., 2)
        Matching pixels in the wide and tele images.
    calibration : Calibration
        The factory calibration.

    Returns
    -------
    ndarray, shape (...)
        d = f_wide · (x_wide − Rᵀx_tele) · b̂, with b̂ the unit image-plane direction of the
        baseline; NaN where a pixel cannot be undistorted.
    """
    qw = as_points(q_wide, 2, "q_wide")
    qt = as_points(q_tele, 2, "q_tele")
    if qw.shape != qt.shape:
        raise ShapeError(f"q_wide and q_tele must have the same shape, got {qw.shape}, {qt.shape}")
    rig = calibration.rig
    xw = rig.wide.pixel_to_normalized(qw)
    rays_t = rig.tele.unproject(qt)
    rays_tw = rays_t @ rig.T_tele_wide.R  # Rᵀ·ray for each row
    with np.errstate(divide="ignore", invalid="ignore"):
        xt = rays_tw[..., :2] / rays_tw[..., 2:3]
    c = rig.tele_center_in_wide
    b = c[:2] / np.linalg.norm(c[:2])
    return np.asarray(rig.wide.f * ((xw - xt) @ b), dtype=np.float64)


def naive_depth(q_wide: Any, q_tele: Any, calibration: Calibration) -> Array:
    """Depth Z = f_wide·B/d (eq. 4) of matching pixels with the factory calibration.

    Parameters
    ----------
    q_wide, q_tele, calibration
        As for :func:`naive_disparity` (B = |t| of the calibration's T_tele_wide, f = its wide
        focal length).

    Returns
    -------
    ndarray, shape (...)
        Depth in metres; NaN where the disparity is ≤ 0 or a pixel cannot be undistorted.

    Examples
    --------
    A canonical ×3 rig with the tele 12 mm along +y sees a point at 2 m with 9 px disparity:

    >>> from phonestereo.geometry import Camera, Rig, Transform
    >>> wide = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
    >>> rig = Rig(wide, wide.scaled(3.0), Transform.from_rotvec([0, 0, 0], [0, -0.012, 0]))
    >>> qw, qt = rig.project([0.1, 0.05, 2.0])
    >>> round(float(naive_depth(qw, qt, Calibration(rig))), 9)
    2.0
    """
    d = naive_disparity(q_wide, q_tele, calibration)
    return depth_from_disparity(d, calibration.rig.wide.f, calibration.rig.baseline_m)


def naive_relative_errors(
    capture: CaptureTruth, calibration: Calibration, keypoints: str = "corners"
) -> Array:
    """|Z_naive − Z_true| / Z_true of every keypoint seen by both cameras in one simulated
    capture, from the true pixel positions (no detection error) and the factory calibration.

    Parameters
    ----------
    capture : CaptureTruth
        One capture of a simulated set's ground truth.
    calibration : Calibration
        The set's factory calibration.
    keypoints : str
        Keypoint set name ("corners" for verification charts, "pupils" for the face chart).

    Returns
    -------
    ndarray, shape (M,)
        Relative depth errors of the M keypoints visible in both images (all objects); inf
        where the naive disparity is ≤ 0 (the point at or beyond infinity).
    """
    errs = []
    for obj in capture.objects:
        if keypoints not in obj.keypoints:
            continue
        kt = obj.keypoints[keypoints].arrays()
        ok = np.isfinite(kt.wide_px).all(axis=1) & np.isfinite(kt.tele_px).all(axis=1)
        q_wide, q_tele = kt.wide_px[ok], kt.tele_px[ok]
        z = naive_depth(q_wide, q_tele, calibration)
        err = np.abs(z - kt.depth_m[ok]) / kt.depth_m[ok]
        # a naive disparity ≤ 0 puts the point at or beyond infinity: an unbounded error (a
        # calibration that reads disparities low, random-3004); a pixel that cannot be
        # undistorted has none and is left out
        beyond = np.isnan(z) & (naive_disparity(q_wide, q_tele, calibration) <= 0)
        errs.append(np.where(beyond, np.inf, err)[np.isfinite(err) | beyond])
    return np.concatenate(errs) if errs else np.zeros(0)
