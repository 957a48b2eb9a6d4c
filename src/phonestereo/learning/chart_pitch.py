"""The face chart's grid as the ruler of its plane (face-chart mode, beyond thesis §3.6).

The printed face chart (:class:`~phonestereo.charts.faces.FaceChart`) puts every face's eye
midpoint on a square grid of pitch ``cell_m`` (0.325 m, 4 × 2 cells). Between two faces the
midpoints lie ``pitch·√(a² + b²)`` apart for whole a ≤ 3, b ≤ 1, five times the IPD or more,
and a landmark detector that reads both pupils of a face a little inwards or outwards (its IPD
bias: −0.1…−0.6 % on the renders, −0.3…+0.3 % by face size on the shipped portraits; session 10
of docs/module-random.md) moves the midpoint by nothing. So once
:func:`~phonestereo.learning.ipd.fit_face_plane` has found the plane from the IPDs (its tilt
and a first scale), :func:`grid_scale` rescales it so that the midpoints' separations match the
grid: the median of pitch·√(a² + b²) / separation over the pairs of faces whose separation is
within ``tol`` of such a length. On the kept renders the IPD ruler read the faces 0.2–0.6 % too
far; the grid removes it.

Examples
--------
Four faces 2 m away on the grid, seen by a 1500 px camera, their IPDs read 0.4 % short (so the
IPD plane sits 0.4 % too far):

>>> from phonestereo.geometry import Camera
>>> cam = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
>>> mids = np.array([[x, y, 2.0] for x in (-0.4875, -0.1625) for y in (-0.1625, 0.1625)])
>>> eyes = np.stack([mids - [0.0315 * 0.996, 0, 0], mids + [0.0315 * 0.996, 0, 0]], axis=1)
>>> scale, pairs = grid_scale(np.full(4, 2.0 / 0.996), cam.project(eyes), cam)
>>> round(scale * 2.0 / 0.996, 6), pairs
(2.0, 6)
"""

from __future__ import annotations

from typing import Any

import numpy as np

from phonestereo.charts.faces import FaceChart
from phonestereo.geometry import Camera

#: The shipped face chart's cell: the midpoints' grid pitch, metres.
CHART_PITCH_M = float(FaceChart.cell_m)
#: Largest grid offsets (a, b) between two faces of the shipped chart (4 × 2 cells).
MAX_OFFSET = (3, 1)


def grid_scale(
    depth_m: Any,
    pupils_px: Any,
    camera: Camera,
    pitch_m: float = CHART_PITCH_M,
    *,
    tol: float = 0.025,
) -> tuple[float, int]:
    """The factor that puts the faces' eye midpoints on the chart's grid, and the pairs used.

    Parameters
    ----------
    depth_m : array_like, shape (N,)
        Each face's midpoint depth on the fitted plane, metres (NaN: not on it).
    pupils_px : array_like, shape (N, 2, 2)
        The faces' pupils, raw pixels of ``camera``.
    camera : Camera
    pitch_m : float
        The grid's pitch, metres.
    tol : float
        Relative tolerance of a separation to a grid length (the grid lengths up to 3.16 pitch
        lie ≥ 5.4 % apart; the IPD plane is good to ~1 %).

    Returns
    -------
    scale, pairs : float, int
        Multiply the depths by ``scale``; 1.0 and 0 when no pair of faces lies on the grid.
    """
    z = np.asarray(depth_m, dtype=np.float64)
    rays = np.asarray(camera.unproject(np.asarray(pupils_px, dtype=np.float64)))
    ok = np.isfinite(z) & np.isfinite(rays).all(axis=(1, 2))
    if ok.sum() < 2:
        return 1.0, 0
    mids = z[ok, None] * rays[ok].mean(axis=1)  # the rays have z = 1
    a, b = np.meshgrid(np.arange(MAX_OFFSET[0] + 1), np.arange(MAX_OFFSET[1] + 1))
    lengths = pitch_m * np.hypot(a, b).ravel()[1:]  # (0, 0) left out
    i, j = np.triu_indices(len(mids), k=1)
    sep = np.linalg.norm(mids[i] - mids[j], axis=1)
    ratio = lengths[None, :] / sep[:, None]  # (pairs, lengths)
    best = ratio[np.arange(len(sep)), np.argmin(np.abs(np.log(ratio)), axis=1)]
    used = np.abs(best - 1.0) <= tol
    if not used.any():
        return 1.0, 0
    return float(np.median(best[used])), int(used.sum())


__all__ = ["CHART_PITCH_M", "MAX_OFFSET", "grid_scale"]
