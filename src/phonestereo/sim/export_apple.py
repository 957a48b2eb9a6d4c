"""Export a simulated capture set as an Apple AVFoundation dump (docs/import-apple.md).

The inverse of :mod:`phonestereo.io.importers.apple`. The virtual iPhone:

* the wide camera is the reference camera (identity ``extrinsicMatrix``); the tele's
  ``extrinsicMatrix`` is ``T_wide_tele`` (``X_wide = R·X_tele + t``, t in mm);
* ``intrinsicMatrixReferenceDimensions`` is twice the image size (the photo is a half-size
  resampling), with the pixel-corner origin;
* the lens is given as Apple gives it: a radial lookup table of :data:`LUT_SIZE`
  magnifications about a fitted ``lensDistortionCenter``, least-squares fitted to our lens on
  a grid over the image, and its inverse table. A radial table cannot hold tangential
  distortion, so the export loses what the moved centre cannot absorb;
  :func:`lut_for_camera` returns that loss (max, pixels) so tests can state it;
* ``timestamp_s`` = ``first_frame_time_s + time_s``; ``CMDeviceMotion.gravity`` =
  ``R_backᵀ g``; ``lensPosition`` = focus_position / 10 (a 0.1 m close-focus lens reports
  dioptres / 10 on Apple's 0–1 scale), clipped to [0, 1].
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from phonestereo.geometry import Camera
from phonestereo.io import Calibration, CaptureEntry, Manifest
from phonestereo.io.importers.apple import R_BACK
from phonestereo.io.importers.apple_lut import apple_distort, image_grid, r_max
from phonestereo.io.importers.apple_schema import FORMAT_CAPTURE, FORMAT_SESSION
from phonestereo.io.importers.common import image_to_platform_K
from phonestereo.sim.export_common import capture_docs, write_dump

LUT_SIZE = 42
FIRST_FRAME_S = 5.0
IDS = {"wide": "BackWideAngle", "tele": "BackTelephoto"}
LENS_POSITION_PER_DIOPTRE = 0.1


def _ref_camera(cam: Camera) -> tuple[np.ndarray, tuple[float, float]]:
    fx, fy, cx, cy, s = image_to_platform_K(cam.K, (0.0, 0.0), (0.5, 0.5))
    K = np.array([[fx, s, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    return K, (2.0 * cam.width, 2.0 * cam.height)


def _table_lsq(
    src: np.ndarray, dst: np.ndarray, center: np.ndarray, ref: tuple[float, float], n: int
) -> tuple[np.ndarray, np.ndarray]:
    """The table m minimising |apple_distort(src) − dst| for a fixed centre: linear least
    squares (a table value enters through the interpolation weights). Returns (m, residual)."""
    v = src - center
    r = np.hypot(v[:, 0], v[:, 1])
    pos = np.clip(r / r_max(center, ref) * (n - 1), 0.0, n - 1.0)
    lo = np.minimum(pos.astype(int), n - 2)
    frac = pos - lo
    W = np.zeros((r.size, n))
    W[np.arange(r.size), lo] = 1.0 - frac
    W[np.arange(r.size), lo + 1] += frac
    A = np.concatenate([W * v[:, :1], W * v[:, 1:]])
    b = np.concatenate([dst[:, 0] - src[:, 0], dst[:, 1] - src[:, 1]])
    m, *_ = np.linalg.lstsq(A, b, rcond=None)
    return m, A @ m - b


def lut_for_camera(cam: Camera, n: int = LUT_SIZE) -> dict[str, Any]:
    """Apple's distortion description of ``cam``: centre, table, inverse table, and the loss.

    The centre is found by variable projection (for a fixed centre the table is a linear
    least-squares problem).

    Returns
    -------
    dict
        ``center`` (x, y), ``table`` (n,), ``inverse`` (n,) in reference pixels, and
        ``loss_px``: max distance over the image between Apple's map and ours, image pixels.
    """
    K, ref = _ref_camera(cam)
    inv = np.linalg.inv(K)
    pu = image_grid(ref, (41, 31))
    xn = (pu - K[:2, 2]) @ inv[:2, :2].T
    pd = cam.lens.distort(xn) @ K[:2, :2].T + K[:2, 2]
    sol = least_squares(lambda c: _table_lsq(pu, pd, c, ref, n)[1], K[:2, 2], x_scale=10.0)
    center = sol.x
    table, res = _table_lsq(pu, pd, center, ref, n)
    loss = float(np.hypot(*res.reshape(2, -1)).max()) * 0.5
    # The inverse table: least squares too, so that inverse(forward(p)) ≈ p over the image.
    inverse, _ = _table_lsq(apple_distort(pu, center, table, ref), pu, center, ref, n)
    return {"center": center, "table": table, "inverse": inverse, "loss_px": loss}


def _calibration_data(cam: Camera, R: np.ndarray, t_mm: np.ndarray) -> dict[str, Any]:
    K, ref = _ref_camera(cam)
    lut = lut_for_camera(cam)
    E = np.concatenate([R, t_mm[:, None]], axis=1)  # 3×4, written column-major
    return {
        "intrinsicMatrix": [float(v) for v in K.T.ravel()],
        "intrinsicMatrixReferenceDimensions": {"width": ref[0], "height": ref[1]},
        "extrinsicMatrix": [float(v) for v in E.T.ravel()],
        "pixelSize": 0.0014,
        "lensDistortionCenter": {"x": float(lut["center"][0]), "y": float(lut["center"][1])},
        "lensDistortionLookupTable": [float(v) for v in lut["table"]],
        "inverseLensDistortionLookupTable": [float(v) for v in lut["inverse"]],
    }


def apple_dump(cal: Calibration, manifest: Manifest) -> tuple[dict[str, Any], dict[str, Any]]:
    """The dump documents: (session.json, {capture file name: capture JSON})."""
    T = cal.rig.T_tele_wide.inverse()  # T_wide_tele: X_wide = R X_tele + t
    session = {
        "format": FORMAT_SESSION,
        "version": 1,
        "first_frame_time_s": FIRST_FRAME_S,
        "cameras": {
            IDS["tele"]: _calibration_data(cal.rig.tele, T.R, T.t * 1e3),
            IDS["wide"]: _calibration_data(cal.rig.wide, np.eye(3), np.zeros(3)),
        },
    }
    return session, capture_docs(FORMAT_CAPTURE, manifest, "an Apple dump", _gravity, _shot, IDS)


def _gravity(g: Any) -> dict[str, list[float]]:
    return {"gravity": [float(v) for v in R_BACK.T @ g]}


def _shot(c: CaptureEntry, role: str, time_s: float) -> dict[str, Any]:
    shot: dict[str, Any] = {
        "timestamp_s": FIRST_FRAME_S + time_s,
        "focusMode": 0 if c.focus_mode == "manual" else 2,
    }
    if c.focus_position is not None:
        lp = c.focus_position * LENS_POSITION_PER_DIOPTRE
        shot["lensPosition"] = min(1.0, max(0.0, lp))
    return shot


def write_apple_dump(
    folder: str | os.PathLike[str], cal: Calibration, manifest: Manifest, set_root: Path
) -> Path:
    """Write the dump into ``folder`` (session.json, captures/, images/ linked from the set)."""
    return write_dump(folder, *apple_dump(cal, manifest), manifest, set_root, IDS)
