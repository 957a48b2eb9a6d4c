"""Even vs odd-degree lens models on the same board views (thesis §3.2 fix 3).

:func:`compare_lens_models` calibrates the same board views with each model and reports the
radial component of the residuals (:func:`radial_residuals`) and its systematic part, the
binned profile over the radius (:func:`radial_residual_profile`, what an insufficient radial
model leaves, free of detection noise); :func:`radial_mapping_error` compares two cameras'
pixel mappings (e.g. a calibration against a known lens) radially.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from phonestereo.calibration.result import CalibrationResult
from phonestereo.calibration.solve import CalibrationOptions, calibrate_camera
from phonestereo.calibration.views import BoardView
from phonestereo.fixes.distortion import radial_geometry
from phonestereo.geometry import Camera

F64 = np.ndarray


def radial_residuals(result: CalibrationResult, camera_index: int = 0) -> tuple[F64, F64]:
    """Radius r (M,) px and radial component dr (M,) px of a calibration's inlier residuals
    (predicted − observed) about that camera's principal point (Figure 3-6 style)."""
    cam = result.cameras[camera_index]
    sel = (result.camera_index == camera_index) & result.inliers
    r, u = radial_geometry(result.image_points[sel], (cam.cx, cam.cy))
    return r, np.sum(result.residuals[sel] * u, axis=1)


def radial_mapping_error(
    reference: Camera,
    other: Camera,
    *,
    max_radius_px: float | None = None,
    n: int = 41,
    remove_scale: bool = False,
) -> tuple[F64, F64]:
    """Radial pixel difference of two cameras' mappings over the reference image.

    Rays through an n × n grid of ``reference`` pixels (within ``max_radius_px`` of its
    principal point, if given) are projected by ``other``; returns the radius r (M,) px and
    the radial component dr (M,) px of other − reference. Use it to compare a calibrated
    camera with a known lens (a simulator's, or a lab reference). ``remove_scale`` subtracts
    the best linear term a·r (a focal-length difference, not distortion) first.

    Examples
    --------
    >>> cam = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
    >>> r, dr = radial_mapping_error(cam, cam.scaled(1.001), max_radius_px=500)
    >>> round(float(np.max(dr)), 2)          # a 0.1 % scale error is 0.5 px at r = 500 px
    0.5
    """
    w, h = reference.size
    gx, gy = np.meshgrid(np.linspace(0, w - 1, n), np.linspace(0, h - 1, n))
    q = np.stack([gx.ravel(), gy.ravel()], axis=1)
    r, u = radial_geometry(q, (reference.cx, reference.cy))
    keep = np.ones(len(q), bool) if max_radius_px is None else r <= max_radius_px
    xy = reference.pixel_to_normalized(q[keep])
    rays = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
    dq = other.project(rays) - q[keep]
    dr = np.sum(dq * u[keep], axis=1)
    ok = np.isfinite(dr)
    rk, dr = r[keep][ok], dr[ok]
    if remove_scale and len(rk):
        dr = dr - rk * float(rk @ dr) / max(float(rk @ rk), 1e-12)
    return rk, dr


def radial_residual_profile(r: F64, dr: F64, n_bins: int = 12) -> tuple[F64, F64, F64]:
    """The systematic radial residual: mean radial residual in radius bins (Figure 3-6 style).

    A lens model too poor for the lens leaves a radial residual that is a function of the
    radius (the thesis's P(r)); corner detection noise does not, and averages out in each bin
    (to σ/√(M/n_bins)). The bins are quantiles of r, so each holds about M/n_bins points.

    Parameters
    ----------
    r, dr : ndarray, shape (M,)
        Radius and radial residual, px (:func:`radial_residuals`).
    n_bins : int
        Number of radius bins.

    Returns
    -------
    r_bin : ndarray, shape (n_bins,)
        Median radius per bin, px (NaN for an empty bin).
    dr_bin : ndarray, shape (n_bins,)
        Mean radial residual per bin, px (NaN for an empty bin).
    count : ndarray of int, shape (n_bins,)

    Examples
    --------
    >>> r = np.linspace(0.0, 1000.0, 1200)
    >>> rb, db, n = radial_residual_profile(r, 1e-4 * r)
    >>> int(n.sum()), round(float(db[-1]), 3)
    (1200, 0.096)
    """
    r, dr = np.asarray(r, np.float64), np.asarray(dr, np.float64)
    if r.shape != dr.shape or r.ndim != 1:
        raise ValueError(f"r and dr must be matching (M,) arrays, got {r.shape} and {dr.shape}")
    if len(r) == 0:
        nan = np.full(n_bins, np.nan)
        return nan, nan.copy(), np.zeros(n_bins, np.int64)
    edges = np.quantile(r, np.linspace(0.0, 1.0, n_bins + 1))
    idx = np.clip(np.searchsorted(edges, r, side="right") - 1, 0, n_bins - 1)
    count = np.bincount(idx, minlength=n_bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        dr_bin = np.bincount(idx, weights=dr, minlength=n_bins) / count
    r_bin = np.array([np.median(r[idx == k]) if count[k] else np.nan for k in range(n_bins)])
    return r_bin, dr_bin, count


def systematic_radial_rms(r: F64, dr: F64, n_bins: int = 12) -> float:
    """RMS over the points of their bin's mean radial residual (:func:`radial_residual_profile`),
    px: the radial error a lens model leaves, without the detection noise."""
    _, dr_bin, count = radial_residual_profile(r, dr, n_bins)
    ok = count > 0
    if not ok.any():
        return float("nan")
    return float(np.sqrt(np.sum(count[ok] * dr_bin[ok] ** 2) / np.sum(count[ok])))


@dataclass(frozen=True)
class LensModelFit:
    """One lens model's calibration of a camera and its residuals.

    ``rms_px``: per-point RMS of all inlier residuals; ``radial_rms_px``: RMS of their radial
    component (detection noise included); ``radial_systematic_px``: the RMS of the binned
    radial residual profile (:func:`systematic_radial_rms`), the part of the radial residual
    that depends on the radius — what an insufficient radial model leaves (§3.2 reason 2).
    """

    model: str
    camera: Camera
    rms_px: float
    radial_rms_px: float
    result: CalibrationResult
    radial_systematic_px: float = float("nan")


def compare_lens_models(
    views: Sequence[BoardView],
    size: tuple[int, int],
    models: Sequence[str] = ("opencv5", "radial-odd"),
    *,
    n_radial: int = 4,
) -> dict[str, LensModelFit]:
    """Calibrate the same board views with each lens model (thesis §3.2 fix 3).

    Parameters
    ----------
    views : sequence of BoardView
        One camera's board views (>= 3 tilted poses).
    size : (int, int)
        Image (width, height), px.
    models : sequence of str
        Lens model names (``opencv5`` even-only, ``radial-odd`` with the odd degrees).
    n_radial : int
        Radial terms of ``radial-odd`` (4: r..r⁴, one more than opencv5's r², r⁴, r⁶; more
        terms extrapolate wildly beyond the observed radius).

    Returns
    -------
    dict of str to LensModelFit
    """
    out = {}
    for model in models:
        res = calibrate_camera(views, size, CalibrationOptions(model=model, n_radial=n_radial))
        r, dr = radial_residuals(res)
        out[model] = LensModelFit(
            model,
            res.cameras[0],
            res.rms_px_per_point,
            float(np.sqrt(np.mean(dr**2))) if len(dr) else float("nan"),
            res,
            systematic_radial_rms(r, dr),
        )
    return out


__all__ = [
    "LensModelFit",
    "compare_lens_models",
    "radial_mapping_error",
    "radial_residual_profile",
    "radial_residuals",
    "systematic_radial_rms",
]
