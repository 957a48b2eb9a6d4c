"""Fit an even-order OpenCV lens model to a true camera (thesis §3.2: the model a factory uses).

The factory calibration of a real module describes a lens whose radial polynomial has odd
terms with OpenCV's even-order model (§3.2 reason 2). Here that fit is made directly on the
pixel mapping: over a grid of pixels spanning the image, the true ideal normalised coordinates
``(x, y)`` are known, and the model ``q = f·distort(x, y) + c`` is fitted by linear least
squares (with ``a_i = f·k_i`` and ``b_i = f·p_i`` the model is linear in its unknowns). With
``free_intrinsics`` the focal length and principal point are fitted jointly with the lens, like
a calibration does; otherwise K is kept and only the coefficients change.

Examples
--------
>>> from phonestereo.geometry import Camera, make_lens
>>> lens = make_lens("opencv5", [-0.05, 0.01, 0, 0, 0])
>>> true = Camera((2000, 1500), 1500.0, 1500.0, 1000.0, 750.0, lens)
>>> fit = fit_even_lens(true, free_intrinsics=True)
>>> bool(fit_residual_px(true, fit) < 1e-9)       # an even lens is fitted exactly
True
"""

from __future__ import annotations

import numpy as np

from phonestereo.geometry import Camera, make_lens
from phonestereo.geometry.checks import Array

GRID = (41, 31)


def _grid_pixels(camera: Camera, grid: tuple[int, int] = GRID) -> Array:
    w, h = camera.size
    xs = np.linspace(-0.5, w - 0.5, grid[0])
    ys = np.linspace(-0.5, h - 0.5, grid[1])
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], axis=-1)


def _ideal_grid(camera: Camera, grid: tuple[int, int] = GRID) -> tuple[Array, Array]:
    """Ideal normalised points covering the image and their true pixels (forward only: no
    undistortion, so it is cheap for a new lens). The grid spans the image's distorted
    normalised extent plus 15 % (more than any phone lens distorts) and keeps the points that
    project into the image."""
    w, h = camera.size
    corners = camera.pixel_to_distorted(np.array([[-0.5, -0.5], [w - 0.5, h - 0.5]]))
    mid = corners.mean(axis=0)
    lo, hi = mid + 1.15 * (corners[0] - mid), mid + 1.15 * (corners[1] - mid)
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], grid[0]), np.linspace(lo[1], hi[1], grid[1]))
    xy = np.stack([gx.ravel(), gy.ravel()], axis=-1)
    q = camera.normalized_to_pixel(camera.lens.distort(xy))
    keep = camera.contains(q)
    return xy[keep], q[keep]


def fit_even_lens(camera: Camera, *, free_intrinsics: bool = False) -> Camera:
    """The ``opencv5`` camera that best reproduces ``camera``'s pixel mapping.

    Parameters
    ----------
    camera : Camera
        The true camera (any lens model).
    free_intrinsics : bool
        Fit fx = fy and (cx, cy) too (a calibration); else keep K and fit only the lens.

    Returns
    -------
    Camera
        Same size, ``opencv5`` lens (k1, k2, p1, p2, k3), least squares in pixels over a
        41 × 31 grid of rays spanning the image.
    """
    xy, q = _ideal_grid(camera)
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    n = x.size
    # Unknowns: a0 = f, a1..a3 = f·(k1, k2, k3), b1, b2 = f·(p1, p2), cx, cy.
    zero = np.zeros(n)
    one = np.ones(n)
    cols_x = [x, x * r2, x * r2**2, x * r2**3, 2 * x * y, r2 + 2 * x * x, one, zero]
    cols_y = [y, y * r2, y * r2**2, y * r2**3, r2 + 2 * y * y, 2 * x * y, zero, one]
    A = np.concatenate([np.stack(cols_x, axis=1), np.stack(cols_y, axis=1)])
    b = np.concatenate([q[:, 0], q[:, 1]])
    if free_intrinsics:
        sol = np.linalg.lstsq(A, b, rcond=None)[0]
        f, cx, cy = sol[0], sol[6], sol[7]
    else:
        f = camera.f
        cx, cy = camera.cx, camera.cy
        b = b - f * A[:, 0] - cx * A[:, 6] - cy * A[:, 7]
        sub = np.linalg.lstsq(A[:, 1:6], b, rcond=None)[0]
        sol = np.concatenate([[f], sub, [cx, cy]])
    k1, k2, k3, p1, p2 = sol[1:6] / f
    lens = make_lens("opencv5", [k1, k2, p1, p2, k3])
    return Camera(camera.size, float(f), float(f), float(cx), float(cy), lens)


def fit_residual_px(true: Camera, model: Camera, grid: tuple[int, int] = GRID) -> float:
    """Max pixel distance between the two cameras' projections of the same rays over the image.

    Both cameras are assumed to see the same ideal normalised coordinates (same frame).
    """
    q = _grid_pixels(true, grid)
    xy = true.pixel_to_normalized(q)
    ok = np.isfinite(xy).all(axis=-1)
    rays = np.concatenate([xy[ok], np.ones((int(ok.sum()), 1))], axis=-1)
    return float(np.max(np.linalg.norm(model.project(rays) - q[ok], axis=-1)))
