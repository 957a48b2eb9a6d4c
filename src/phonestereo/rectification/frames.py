"""Rectifying rotations and quarter turns (thesis §1.3.3, §3.3; docs/conventions.md).

A rectifying rotation ``R_rect_cam`` maps directions of a camera frame into the rectified frame.
Both cameras share the rectified orientation, so ``R_rect_tele = R_rect_wide · Rᵀ`` with R the
rotation of ``T_tele_wide``. After rectification the disparity axis is x and the tele optical
centre sits on the +x side of the wide, so d = x_wide − x_tele > 0 in front (docs/conventions.md).

- Rotation-only modes (``tele-to-wide``, ``undistort-both``) keep the wide's orientation up to a
  *quarter turn* about the optical axis: the k·90° turn that brings the image-plane direction of
  the baseline closest to +x. A vertical-baseline module (folded-x3, tele 12 mm along device y)
  gets k = 1; its rectified images are the raw ones turned by 90° (width and height swap).
- ``canonical`` (§3.3): x is the full baseline direction c/|c| (t_y, t_z included), z the wide's
  optical axis made orthogonal to it (the rotation about the baseline that keeps the wide's axis
  closest to z), y = z × x.

A quarter turn of a camera with a lens is exact: radial terms are rotation invariant and the
OpenCV tangential vector (p2, p1) turns with the image, so the turned camera is again a
:class:`~phonestereo.geometry.Camera` (see :func:`quarter_turn_camera`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from phonestereo.errors import InputError, PhysicsError
from phonestereo.geometry import Camera, LensModel
from phonestereo.geometry.checks import Array, as_matrix

# Smallest share of the baseline that must lie in the image plane: beyond ~60° of tilt the
# canonical frame would look mostly sideways and the rotation-only modes see no disparity.
MIN_IN_PLANE_FRACTION = 0.5


def quarter_turn(k: int) -> Array:
    """Rotation (3, 3) by k·90° about the optical axis: (x, y) → Q_k·(x, y), z kept.

    k = 1 maps the camera's +y (image down) onto +x: (x, y, z) → (y, −x, z).

    Examples
    --------
    >>> quarter_turn(1) @ np.array([0.0, 0.012, 0.0])      # tele 12 mm below → on +x
    array([0.012, 0.   , 0.   ])
    """
    q = np.eye(3)
    c, s = [(1, 0), (0, 1), (-1, 0), (0, -1)][int(k) % 4]
    q[:2, :2] = [[c, s], [-s, c]]
    return q


def quarter_turns_for(center: Any) -> int:
    """The k in 0..3 whose quarter turn puts the baseline closest to +x.

    Parameters
    ----------
    center : array_like, shape (3,)
        Tele optical centre in the wide frame, metres.

    Raises
    ------
    PhysicsError
        If less than :data:`MIN_IN_PLANE_FRACTION` of the baseline lies in the image plane.

    Examples
    --------
    >>> quarter_turns_for([0.0004, 0.012, 0.0015]), quarter_turns_for([0.010, 0.0003, 0.0003])
    (1, 0)
    """
    c = _baseline(center)
    return int(np.argmax([(quarter_turn(k) @ c)[0] for k in range(4)]))


def canonical_rotation(center: Any) -> Array:
    """R_rect_wide (3, 3) whose x axis is the full baseline direction (thesis §3.3).

    Rows are the rectified axes in the wide frame: x = c/|c|; z = the wide's optical axis minus
    its component along x, normalised (the remaining rotation about the baseline keeps the
    wide's axis as close to z as possible); y = z × x.

    Parameters
    ----------
    center : array_like, shape (3,)
        Tele optical centre in the wide frame, metres.

    Returns
    -------
    ndarray, shape (3, 3)
        Rotation with ``R @ center = (|c|, 0, 0)``.

    Examples
    --------
    A tele 12 mm below the wide and 1.5 mm behind it: the rectified x axis tilts by
    atan(1.5/12) = 7.1° out of the image plane, and the centre lands on +x.

    >>> R = canonical_rotation([0.0, 0.012, -0.0015])
    >>> ((R @ [0.0, 0.012, -0.0015]).round(6) + 0.0).tolist()
    [0.012093, 0.0, 0.0]
    >>> round(float(np.degrees(np.arccos(R[2, 2]))), 2)   # wide axis to rectified z
    7.13
    """
    c = _baseline(center)
    x = c / np.linalg.norm(c)
    z = np.array([0.0, 0.0, 1.0]) - x[2] * x
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    return np.stack([x, y, z])


def _baseline(center: Any) -> Array:
    c = as_matrix(np.ravel(np.asarray(center, dtype=np.float64)), (3,), "tele centre")
    norm = float(np.linalg.norm(c))
    if norm == 0.0 or float(np.linalg.norm(c[:2])) < MIN_IN_PLANE_FRACTION * norm:
        raise PhysicsError(
            f"the tele centre {np.round(c * 1e3, 3).tolist()} mm lies mostly along the optical "
            "axis; a wide/tele pair needs its baseline in the image plane (check T_tele_wide: "
            "t is p_tele = R·p_wide + t, in metres)"
        )
    return c


def rotate_lens(lens: LensModel, k: int) -> LensModel:
    """The lens model seen through a quarter-turned image (exact).

    With Q the 2×2 block of :func:`quarter_turn`, ``rotate_lens(lens, k).distort(Q u) =
    Q · lens.distort(u)``: radial terms are unchanged and the tangential vector (p2, p1) turns
    with Q, as does a distortion centre (``radial-odd-centred``).

    Examples
    --------
    >>> from phonestereo.geometry import make_lens
    >>> rotate_lens(make_lens("opencv5", [-0.1, 0.0, 1e-3, 2e-3, 0.0]), 1).coefficients
    (-0.1, 0.0, -0.002, 0.001, 0.0)
    """
    if k % 4 == 0:
        return lens
    i1, i2 = lens.tangential_columns  # the only model-specific knowledge needed
    coeffs = list(lens.coefficients)
    p2, p1 = quarter_turn(k)[:2, :2] @ [coeffs[i2], coeffs[i1]]
    coeffs[i1], coeffs[i2] = float(p1), float(p2)
    centre = getattr(lens, "centre_columns", None)  # a distortion centre turns with the image
    if centre is not None:
        j1, j2 = centre
        cx, cy = quarter_turn(k)[:2, :2] @ [coeffs[j1], coeffs[j2]]
        coeffs[j1], coeffs[j2] = float(cx), float(cy)
    return lens.with_coefficients(coeffs)


def quarter_turn_camera(camera: Camera, k: int) -> Camera:
    """The camera of the image turned by k·90° (pixel-exact, lens included).

    ``quarter_turn_camera(cam, k).project(quarter_turn(k) @ p)`` is the pixel of
    ``cam.project(p)`` in the turned image; for odd k width and height swap and so do fx, fy.

    Raises
    ------
    InputError
        A camera with non-zero skew (phone cameras have none; eq. 2).

    Examples
    --------
    >>> cam = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
    >>> t = quarter_turn_camera(cam, 1)
    >>> t.size, (t.cx, t.cy)
    ((1500, 2000), (749.5, 999.5))
    """
    k = int(k) % 4
    if k == 0:
        return camera
    if camera.skew != 0.0:
        raise InputError(
            "a quarter-turned rectification needs a zero-skew camera (K[0, 1] = 0, eq. 2); "
            f"this camera has skew {camera.skew}"
        )
    w, h = camera.size
    q = quarter_turn(k)[:2, :2]
    offset = {1: (0.0, w - 1.0), 2: (w - 1.0, h - 1.0), 3: (h - 1.0, 0.0)}[k]
    cx, cy = q @ [camera.cx, camera.cy] + offset
    fx, fy = (camera.fy, camera.fx) if k % 2 else (camera.fx, camera.fy)
    size = (h, w) if k % 2 else (w, h)
    return Camera(size, fx, fy, float(cx), float(cy), rotate_lens(camera.lens, k))
