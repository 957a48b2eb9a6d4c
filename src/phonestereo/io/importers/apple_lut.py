"""Apple's lens-distortion lookup tables and their fit to the ``radial-odd`` lens model.

``AVCameraCalibrationData.lensDistortionLookupTable`` holds magnifications ``m`` at radii
linearly spaced from 0 (at ``lensDistortionCenter``) to ``r_max``, the distance from the centre
to the farthest corner of an image of ``intrinsicMatrixReferenceDimensions``. Apple's
reference code (``lensDistortionPointForPoint`` in AVCameraCalibrationData.h) moves a point
``p`` of the undistorted (rectilinear) image to the distorted image as::

    v = p − centre,  r = |v|,  m = interp(r · (n − 1) / r_max, table)  (last value beyond r_max)
    p_distorted = centre + (1 + m) · v

The inverse table maps distorted points back the same way. The map is radial about
``lensDistortionCenter``, which on a real module is not the principal point, so it is fitted by
our ``radial-odd-centred`` model: ``g = 1 + Σ kᵢ rⁱ`` (plus tangential p1, p2) about the
distortion centre c = K⁻¹·lensDistortionCenter, on normalised coordinates — for the known
centre a linear least-squares problem on a grid over the image. (About the principal point,
``radial-odd`` with p1, p2 absorbs only the first-order part of a moved centre: 0.12 px left on
the virtual iPhone's wide camera, whose centre is 37 reference pixels off.) The fit's residual
(pixels of the reference dimensions) is reported, never hidden.

Examples
--------
>>> import numpy as np
>>> apple_distort(np.array([[200.0, 100.0]]), (100.0, 100.0), [0.0, 0.1], (200.0, 200.0)).round(3)
array([[207.071, 100.   ]])
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from phonestereo.geometry import LensModel, make_lens

N_RADIAL = 6
GRID = (65, 49)


def r_max(center: Any, ref_size: Sequence[float]) -> float:
    """Apple's maximum radius: centre to the farthest image corner (reference pixels)."""
    cx, cy = center
    w, h = ref_size
    return float(np.hypot(max(cx, w - cx), max(cy, h - cy)))


def apple_distort(
    points: Any, center: Any, table: Any, ref_size: Sequence[float]
) -> NDArray[np.float64]:
    """Apply a lookup table to points (N, 2) in reference pixels (corner origin), as Apple does."""
    p = np.asarray(points, dtype=np.float64)
    c = np.asarray(center, dtype=np.float64)
    lut = np.asarray(table, dtype=np.float64)
    v = p - c
    r = np.hypot(v[..., 0], v[..., 1])
    m = np.interp(r, np.linspace(0.0, r_max(center, ref_size), lut.size), lut)
    return c + (1.0 + m)[..., None] * v


def image_grid(ref_size: Sequence[float], shape: tuple[int, int] = GRID) -> NDArray[np.float64]:
    """Points (N, 2) covering the whole image, corners included (reference pixels)."""
    w, h = ref_size
    xs, ys = np.meshgrid(np.linspace(0.0, w, shape[0]), np.linspace(0.0, h, shape[1]))
    return np.stack([xs.ravel(), ys.ravel()], axis=-1)


def fit_radial_odd_centred(
    K: Any,
    center: Sequence[float],
    table: Sequence[float],
    ref_size: Sequence[float],
    n_radial: int = N_RADIAL,
) -> tuple[LensModel, float]:
    """Fit ``radial-odd-centred`` (n radial terms + p1, p2 about the table's centre) to a table.

    Parameters
    ----------
    K : (3, 3)
        Camera matrix in reference pixels, corner origin (Apple's own).
    center, table, ref_size
        ``lensDistortionCenter``, ``lensDistortionLookupTable`` and
        ``intrinsicMatrixReferenceDimensions``.

    Returns
    -------
    (LensModel, float)
        The lens and the fit's max residual in reference pixels over :func:`image_grid`.
    """
    k = np.asarray(K, dtype=np.float64)
    pu = image_grid(ref_size)
    pd = apple_distort(pu, center, table, ref_size)
    inv = np.linalg.inv(k)
    c = (np.asarray(center, dtype=np.float64) - k[:2, 2]) @ inv[:2, :2].T  # normalised
    xu = (pu - k[:2, 2]) @ inv[:2, :2].T - c
    xd = (pd - k[:2, 2]) @ inv[:2, :2].T - c
    x, y = xu[:, 0], xu[:, 1]
    r = np.hypot(x, y)
    cols_x = [x * r**i for i in range(1, n_radial + 1)] + [2 * x * y, r * r + 2 * x * x]
    cols_y = [y * r**i for i in range(1, n_radial + 1)] + [r * r + 2 * y * y, 2 * x * y]
    fx, fy = k[0, 0], k[1, 1]
    A = np.concatenate([fx * np.stack(cols_x, -1), fy * np.stack(cols_y, -1)])
    b = np.concatenate([fx * (xd[:, 0] - x), fy * (xd[:, 1] - y)])
    coef, *_ = np.linalg.lstsq(A, b, rcond=None)
    res = (A @ coef - b).reshape(2, -1)
    lens = make_lens("radial-odd-centred", [*coef, *c])
    return lens, float(np.hypot(res[0], res[1]).max())


def inverse_consistency(
    center: Sequence[float],
    table: Sequence[float],
    inverse_table: Sequence[float],
    ref_size: Sequence[float],
) -> float:
    """Max distance (reference pixels) of inverse(forward(p)) from p over the image: how well
    the two tables agree."""
    pu = image_grid(ref_size, (17, 13))
    back = apple_distort(
        apple_distort(pu, center, table, ref_size), center, inverse_table, ref_size
    )
    return float(np.hypot(*(back - pu).T).max())
